"""Validation stage (issue 7): each check on small synthetic trajectories of a tiny humanoid.

The tiny humanoid (motok_robot.sim.testing) keeps these tests independent of models/mjcf;
tests at the end run the shipped robots when they load.
"""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.sim import synthetic as S
from motok_robot.sim.config import ValidationConfig
from motok_robot.feasibility.dynamics import finite_difference, moving_average, zmp_from_centroidal
from motok_robot.feasibility.geometry import convex_hull, signed_distance
from motok_robot.sim.kinematic import replay
from motok_robot.robots.index import body_pairs_in_collision, index_robot
from motok_robot.sim.report import METRIC_KEYS, frame_ranges, validate_report_dict
from motok_robot.sim.testing import JOINTS, tiny_humanoid
from motok_robot.sim.trajectory import RobotTrajectory, load_robot_npz, save_robot_npz
from motok_robot.sim.validate import validate_file, validate_trajectory

FPS = 20.0


@pytest.fixture(scope="module")
def tiny():
    return index_robot(tiny_humanoid())


def run(index, qpos, physics=True, config=None, name="clip.npz"):
    trajectory = RobotTrajectory(qpos, FPS, index.joint_names, index.name, source=name)
    return validate_trajectory(trajectory, index, config=config, physics=physics)


def failed(result) -> set:
    return set(result.report["failed_checks"])


# ---- building blocks ---------------------------------------------------------------------

def test_config_overrides_parse_and_reject_unknown_keys():
    cfg = ValidationConfig().with_overrides(["max_velocity_ratio=0.8", "zmp_model=cart_table",
                                             "max_self_collision_frames=3"])
    assert cfg.max_velocity_ratio == 0.8 and cfg.zmp_model == "cart_table" and cfg.max_self_collision_frames == 3
    with pytest.raises(InputError, match="no_such_key"):
        ValidationConfig().with_overrides(["no_such_key=1"])
    with pytest.raises(InputError, match="max_velocity_ratio=fast"):
        ValidationConfig().with_overrides(["max_velocity_ratio=fast"])
    with pytest.raises(InputError, match="zmp_model"):
        ValidationConfig().with_overrides(["zmp_model=magic"])
    with pytest.raises(InputError, match="key=value"):
        ValidationConfig().with_overrides(["max_velocity_ratio"])


def test_physics_steps_at_the_robot_models_own_timestep_unless_set(tiny):
    from motok_robot.feasibility.config import FeasibilityConfig
    from motok_robot.feasibility.physics import ServoPhysics
    from motok_robot.sim.rollout import servo_model

    own = tiny.model.opt.timestep
    assert servo_model(tiny, ValidationConfig())[0].opt.timestep == own
    assert ServoPhysics(tiny, timestep_s=FeasibilityConfig().timestep_s).dt == own
    assert servo_model(tiny, ValidationConfig(physics_timestep_s=own / 2))[0].opt.timestep == own / 2
    assert tiny.model.opt.timestep == own  # the robot's own model is left alone


def test_convex_hull_and_signed_distance():
    square = convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [1, 0.5]]))
    assert len(square) == 4
    assert signed_distance(np.array([0.5, 0.5]), square) == pytest.approx(0.5)
    assert signed_distance(np.array([0.9, 0.5]), square) == pytest.approx(0.1)
    assert signed_distance(np.array([1.3, 0.5]), square) == pytest.approx(-0.3)
    assert signed_distance(np.array([2.0, 2.0]), square) == pytest.approx(-np.sqrt(2))
    segment = convex_hull(np.array([[0, 0], [1, 0], [0.5, 0]]))
    assert len(segment) == 2 and signed_distance(np.array([0.5, 0.2]), segment) == pytest.approx(-0.2)
    assert np.isnan(signed_distance(np.array([0.0, 0.0]), np.zeros((0, 2))))


def test_cart_table_zmp_matches_the_analytic_formula():
    t = np.linspace(0, 2, 41)
    com = np.stack([0.05 * np.sin(3 * t), np.zeros_like(t), np.full_like(t, 0.3)], axis=1)
    acc = np.stack([-0.45 * np.sin(3 * t), np.zeros_like(t), np.zeros_like(t)], axis=1)
    zmp = zmp_from_centroidal(com, acc, None, mass=3.0)
    np.testing.assert_allclose(zmp[:, 0], com[:, 0] - 0.3 / 9.81 * acc[:, 0], atol=1e-12)
    # a rate of angular momentum about +y moves the ZMP backwards by L'_y / F_z
    zmp2 = zmp_from_centroidal(com, acc, np.tile([0.0, 0.5, 0.0], (len(t), 1)), mass=3.0)
    np.testing.assert_allclose(zmp2[:, 0] - zmp[:, 0], -0.5 / (3.0 * 9.81), atol=1e-12)
    free_fall = zmp_from_centroidal(com[:1], np.array([[0.0, 0.0, -9.81]]), None, mass=3.0)
    assert np.isnan(free_fall).all()


@pytest.mark.parametrize("window", [3, 4, 5])
def test_smoothing_keeps_a_constant_rate_and_averages_inside(window):
    """The ZMP's CoM smoothing must not invent an acceleration at the clip ends: a series that
    changes at a constant rate has zero second difference after smoothing, first frames included."""
    t = np.arange(30) / FPS
    line = np.stack([0.2 * t, -0.1 * t, np.full_like(t, 0.3)], axis=1)
    acc = finite_difference(finite_difference(moving_average(line, window), FPS), FPS)
    np.testing.assert_allclose(acc, 0.0, atol=1e-9)
    x = np.random.default_rng(0).normal(size=(12, 2))
    pad = window // 2
    inside = np.mean([x[k:len(x) - window + 1 + k] for k in range(window)], axis=0)
    np.testing.assert_allclose(moving_average(x, window)[pad:pad + len(inside)], inside, atol=1e-12)
    assert moving_average(x[:window - 1], window).shape == (window - 1, 2)  # shorter than the window: as is


def test_zmp_of_a_robot_gliding_at_constant_speed_stays_under_its_com(tiny):
    """A standing pose translated at a constant 0.2 m/s has no acceleration: its ZMP is the CoM
    projection on every frame, the first and last ones too."""
    qpos = S.standing(tiny, 1.0, FPS).copy()
    qpos[:, 0] += 0.2 * np.arange(len(qpos)) / FPS
    kin = replay(tiny, qpos, FPS, ValidationConfig())
    np.testing.assert_allclose(kin.zmp, kin.com[:, :2], atol=1e-6)


def test_inverse_dynamics_ground_reaction_carries_the_weight(tiny):
    kin = replay(tiny, S.standing(tiny, 0.5, FPS), FPS, ValidationConfig())
    weight = tiny.total_mass * 9.81
    np.testing.assert_allclose(kin.contact_force[:, :, 2].sum(axis=1), weight, rtol=1e-3)
    assert kin.unsupported_force.max() < 1e-3 * weight
    # symmetric pose: each foot carries half
    np.testing.assert_allclose(kin.contact_force[:, 0, 2], kin.contact_force[:, 1, 2], rtol=1e-3)


def test_inverse_dynamics_torques_hold_the_robot_in_physics(tiny):
    """The ID torque of the stance knee in single support equals what the servos apply in
    physics once the robot has settled at that pose (statically determinate case)."""
    # the middle of the first single support of the walk: pelvis over the left foot, right foot up
    hold = S.walk(tiny, steps=1, step_period_s=2.4, fps=FPS)
    frame = int(round((0.5 * 2.4 + 0.5 * 1.2) * FPS))  # middle of the single support
    pose = hold[frame]
    kin = replay(tiny, np.tile(pose, (5, 1)), FPS, ValidationConfig())
    assert kin.contact[2].tolist() == [True, False]
    model = tiny.model
    data = mujoco.MjData(model)
    data.qpos[:] = pose
    for a in range(model.nu):
        data.ctrl[a] = pose[tiny.qpos_adr[tiny.actuator_joint[a]]]
    for _ in range(int(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    knee = JOINTS.index("left_knee")
    applied = data.actuator_force[list(tiny.actuator_joint).index(knee)]
    assert abs(kin.torque[2, knee]) > 0.3
    assert kin.torque[2, knee] == pytest.approx(applied, abs=0.1 * abs(kin.torque[2, knee]) + 0.02)


def test_self_collision_between_crossed_legs_is_found(tiny):
    qpos = tiny.nominal_qpos.copy()
    qpos[tiny.qpos_adr[JOINTS.index("left_hip_roll")]] = -0.5
    qpos[tiny.qpos_adr[JOINTS.index("right_hip_roll")]] = 0.5
    data = mujoco.MjData(tiny.collision_model)
    data.qpos[:] = qpos
    pairs = body_pairs_in_collision(tiny, data, 0.002)
    names = {frozenset((tiny.model.body(a).name, tiny.model.body(b).name)) for a, b, _ in pairs}
    assert frozenset(("left_shank", "right_shank")) in names
    data.qpos[:] = tiny.nominal_qpos
    assert body_pairs_in_collision(tiny, data, 0.002) == []
    clip = S.standing(tiny, 1.0, FPS)
    clip[8:12] = qpos
    result = run(tiny, clip, physics=False)
    assert failed(result) >= {"self_collision"}
    assert result.report["checks"]["self_collision"]["frames"] == [8, 9, 10, 11]


def test_frame_ranges_text():
    assert frame_ranges([1, 2, 3, 7, 9, 10]) == "1-3, 7, 9-10"
    assert frame_ranges(list(range(0, 20, 2)), limit=2) == "0, 2, ..."


# ---- clean motions pass ------------------------------------------------------------------

def test_standing_still_passes_every_check_with_schema(tiny, tmp_path):
    result = run(tiny, S.standing(tiny, 1.5, FPS))
    report = result.report
    assert report["passed"] and report["failed_checks"] == [], result.summary()
    validate_report_dict(report)
    assert set(METRIC_KEYS) <= set(report["metrics"])
    assert report["metrics"]["fell"] is False and report["metrics"]["max_penetration_m"] < 1e-6
    assert report["metrics"]["balance_margin_min_m"] > 0.03
    assert report["metrics"]["tracking_rmse_rad"] < 0.02
    assert {"fall", "tracking", "base_drift", "center_of_pressure"} <= set(report["checks"])
    assert result.summary().startswith("PASS clip.npz on tiny_humanoid")


def test_procedural_walk_passes_kinematic_and_physics(tiny):
    qpos = S.walk(tiny, steps=2, step_period_s=2.4, fps=FPS)
    kin_contact = replay(tiny, qpos, FPS, ValidationConfig()).contact
    assert (~kin_contact).any(axis=0).all(), "each foot must leave the floor once"
    result = run(tiny, qpos)
    assert result.passed, result.summary()
    assert np.ptp(result.rollout.qpos[:, 0]) > 0.05  # it walked forward in physics


# ---- each synthetic fault is caught by its check and named in the summary --------------

def test_sliding_foot_is_caught_by_skating(tiny):
    result = run(tiny, S.sliding_foot(tiny, 2.0, FPS, side=1), physics=False)
    assert {"foot_skate_ratio", "foot_skate_distance"} <= failed(result)
    assert "penetration" not in failed(result) and "joint_limits" not in failed(result)
    check = result.report["checks"]["foot_skate_distance"]
    assert check["details"]["foot"] == "right" and check["value"] > 0.05
    frames = result.report["checks"]["foot_skate_ratio"]["frames"]
    assert min(frames) >= 8 and max(frames) <= 32  # the slide happens in the middle half
    assert "FAILED foot_skate_ratio" in result.summary() and "right foot" in result.summary()


def test_sunk_foot_is_caught_by_penetration(tiny):
    result = run(tiny, S.sunk_feet(tiny, 1.0, FPS, depth_m=0.02), physics=False)
    assert failed(result) == {"penetration"}
    assert result.report["metrics"]["max_penetration_m"] == pytest.approx(0.02, abs=1e-6)
    assert "FAILED penetration: 0.02" in result.summary()


def test_floating_robot_is_caught(tiny):
    qpos = S.standing(tiny, 1.0, FPS)
    qpos[:, 2] += 0.06
    result = run(tiny, qpos, physics=False)
    assert "floating" in failed(result)
    assert result.report["metrics"]["max_float_m"] == pytest.approx(0.06, abs=1e-6)


def test_leaning_com_outside_support_is_caught_by_static_balance(tiny):
    result = run(tiny, S.leaning(tiny, 2.0, FPS), physics=False)
    assert {"static_balance", "zmp"} <= failed(result)
    assert result.report["metrics"]["balance_margin_min_m"] < -0.01
    assert "FAILED static_balance" in result.summary()
    assert "foot_skate_ratio" not in failed(result)


def test_joint_beyond_limit_is_caught(tiny):
    qpos, joint = S.over_limit(tiny, 2.0, FPS, beyond_rad=0.15)
    result = run(tiny, qpos, physics=False)
    assert failed(result) == {"joint_limits"}
    check = result.report["checks"]["joint_limits"]
    assert check["details"]["worst_joint"] == tiny.joint_names[joint]
    assert check["details"]["worst_excess_rad"] == pytest.approx(0.15, abs=0.01)
    assert f"joint {tiny.joint_names[joint]}" in result.summary()


def test_too_fast_for_the_servo_is_caught_by_velocity(tiny):
    qpos, joint = S.too_fast(tiny, 2.0, FPS, speed_ratio=2.0)
    result = run(tiny, qpos, physics=False)
    assert "joint_velocity" in failed(result)
    assert result.report["metrics"]["max_velocity_ratio"] == pytest.approx(2.0, rel=0.1)
    assert result.report["checks"]["joint_velocity"]["details"]["worst_joint"] == tiny.joint_names[joint]


def test_torque_beyond_the_actuator_limit_is_caught():
    weak = index_robot(tiny_humanoid(torque_limit=0.3))
    result = run(weak, S.standing(weak, 0.5, FPS), physics=False)
    assert failed(result) == {"torque"}
    assert result.report["checks"]["torque"]["details"]["worst_joint"].endswith("knee")


def test_jerky_joint_is_caught_by_acceleration(tiny):
    qpos = S.standing(tiny, 1.0, FPS)
    adr = tiny.qpos_adr[JOINTS.index("left_elbow")]
    qpos[10, adr] -= 0.6  # one-frame glitch
    result = run(tiny, qpos, physics=False)
    assert "joint_acceleration" in failed(result)
    assert 10 in result.report["checks"]["joint_acceleration"]["frames"]


def test_fall_in_the_rollout_is_caught(tiny):
    result = run(tiny, S.lift_foot_without_shift(tiny, 2.0, FPS))
    assert "fall" in failed(result)
    metrics = result.report["metrics"]
    assert metrics["fell"] is True and 0.4 < metrics["fall_time_s"] < 2.0
    assert "FAILED fall" in result.summary() and f"at {metrics['fall_time_s']:.2f} s" in result.summary()
    frames = result.report["checks"]["fall"]["frames"]
    assert frames and frames[0] == int(np.ceil(metrics["fall_time_s"] * FPS))


def test_a_robot_that_stands_through_a_kick_fails_foot_lift_while_the_mean_pose_passes(tiny):
    """The reference lifts the right foot for a short moment (a kick); the robot stands.  The mean
    pose error over the clip stays small, the foot-lift check names the foot that did not rise."""
    stand = S.standing(tiny, 3.0, FPS)
    lifted = S.lift_foot_without_shift(tiny, 3.0, FPS)  # lifted from 40 % of the clip on
    kick = stand.copy()
    kick[30:36] = lifted[-1]  # 0.3 s up, then back
    trajectory = RobotTrajectory(stand, FPS, tiny.joint_names, tiny.name, source="kick.npz", reference_qpos=kick)
    result = validate_trajectory(trajectory, tiny)
    check = result.report["checks"]["fidelity_foot_lift"]
    assert "fidelity_foot_lift" in failed(result) and "fidelity_pose" not in failed(result)
    leg_lift = 0.15 * tiny.nominal_qpos[2]
    assert check["value"] == pytest.approx(leg_lift, rel=0.25)
    assert check["details"]["right_reference_m"] > 0.7 * leg_lift and check["details"]["right_executed_m"] < 0.005
    assert check["frames"] and 30 <= check["frames"][0] < 36
    # the same clip done as asked passes the check
    done = validate_trajectory(RobotTrajectory(kick, FPS, tiny.joint_names, tiny.name, source="kick.npz"), tiny)
    assert done.report["checks"]["fidelity_foot_lift"]["value"] < 0.005


def test_feet_lifted_higher_or_at_other_times_than_the_reference_pass_foot_lift(tiny):
    """Only a lift the rollout fell short of counts: a re-planned walk steps higher and at its own times."""
    from motok_robot.sim.fidelity import fidelity_measures

    walk = S.walk(tiny, steps=2, step_period_s=2.4, fps=FPS)
    valid = np.ones(walk.shape[0], dtype=bool)
    late = np.concatenate([walk[:1].repeat(10, axis=0), walk[:-10]])  # the same steps, 0.5 s later
    assert fidelity_measures(tiny, late, walk, valid)["foot_lift_shortfall_m"] < 1e-3
    high = walk.copy()
    high[:, 2] += 0.01 * np.sin(np.linspace(0, np.pi, walk.shape[0]))  # the whole robot 1 cm higher mid-clip
    assert fidelity_measures(tiny, high, walk, valid)["foot_lift_shortfall_m"] < 1e-3
    low = fidelity_measures(tiny, walk[:1].repeat(walk.shape[0], axis=0), walk, valid)  # never stepped
    assert low["reference_lift_m"].max() > 0.01
    assert low["foot_lift_shortfall_m"] == pytest.approx(low["reference_lift_m"].max(), abs=1e-9)


def test_no_physics_leaves_physics_metrics_null(tiny):
    result = run(tiny, S.standing(tiny, 0.5, FPS), physics=False)
    assert result.report["metrics"]["fell"] is None and "fall" not in result.report["checks"]


# ---- files, mismatches, outputs ------------------------------------------------------------

def _write(path, index, qpos, **override):
    data = {"qpos": qpos, "fps": FPS, "joint_names": np.array(index.joint_names), "robot": index.name}
    data.update(override)
    np.savez(path, **data)
    return path


def test_mismatched_robot_npz_errors_name_the_field(tiny, tmp_path):
    qpos = S.standing(tiny, 0.5, FPS)
    with pytest.raises(InputError, match=r"field 'qpos' has 24 columns .* nq=25"):
        validate_file(_write(tmp_path / "nq.npz", tiny, qpos[:, :-1]), tiny)
    names = list(tiny.joint_names)
    names[3] = "left_knee_typo"
    with pytest.raises(InputError, match=r"field 'joint_names' .*left_knee_typo"):
        validate_file(_write(tmp_path / "names.npz", tiny, qpos, joint_names=np.array(names)), tiny)
    swapped = list(tiny.joint_names)
    swapped[0], swapped[1] = swapped[1], swapped[0]
    with pytest.raises(InputError, match=r"order differs at index 0"):
        validate_file(_write(tmp_path / "order.npz", tiny, qpos, joint_names=np.array(swapped)), tiny)
    with pytest.raises(InputError, match=r"field 'robot' is 'op3_like'"):
        validate_file(_write(tmp_path / "robot.npz", tiny, qpos, robot="op3_like"), tiny)
    bad = qpos.copy()
    bad[3, 9] = np.nan
    with pytest.raises(InputError, match=r"not finite at frame 3, column 9"):
        validate_file(_write(tmp_path / "nan.npz", tiny, bad), tiny)
    np.savez(tmp_path / "nofps.npz", qpos=qpos)
    with pytest.raises(InputError, match=r"field 'fps' is missing"):
        load_robot_npz(tmp_path / "nofps.npz", tiny)
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(InputError, match="not a readable .npz"):
        load_robot_npz(tmp_path / "junk.npz")
    with pytest.raises(FileNotFoundError):
        load_robot_npz(tmp_path / "missing.npz")


def test_report_json_and_plots_are_written(tiny, tmp_path):
    path = tmp_path / "lean.npz"
    save_robot_npz(path, RobotTrajectory(S.leaning(tiny, 1.0, FPS), FPS, tiny.joint_names, tiny.name))
    result = validate_file(path, tiny, out_dir=tmp_path / "out", physics=True, plots=True)
    on_disk = json.loads((tmp_path / "out" / "report.json").read_text())
    validate_report_dict(on_disk)
    assert on_disk["passed"] is False and "static_balance" in on_disk["failed_checks"]
    assert on_disk["checks"]["static_balance"]["threshold"] == 0.0
    assert on_disk["checks"]["static_balance"]["comparison"] == ">="
    for name in ("balance_topview", "feet", "joints", "torques"):
        png = tmp_path / "out" / f"{name}.png"
        assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    assert len(on_disk["outputs"]["plots"]) == 4
    import hashlib

    assert on_disk["input"]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert result.report["metrics"] == on_disk["metrics"] or on_disk["metrics"]["passed"] is False


def test_skating_outside_planned_contacts_is_diagnosed_as_low_clearance(tiny):
    qpos = S.sliding_foot(tiny, 2.0, FPS, side=1)
    planned = np.ones((len(qpos), 2), dtype=bool)
    trajectory = RobotTrajectory(qpos, FPS, tiny.joint_names, tiny.name, contacts=planned, source="slide.npz")
    details = validate_trajectory(trajectory, tiny, physics=False).report["checks"]["foot_skate_ratio"]["details"]
    assert details["skate_frames_in_planned_contact"][1] > 0 and "diagnosis" not in details
    planned[:, 1] = False  # retargeting said the right foot was swinging: it skims the floor
    trajectory.contacts = planned
    result = validate_trajectory(trajectory, tiny, physics=False)
    details = result.report["checks"]["foot_skate_ratio"]["details"]
    assert details["skate_frames_outside_planned_contact"][1] > 0
    assert "clearance" in details["diagnosis"] and "clearance" in result.summary()


def test_deep_squat_is_not_a_fall_because_falls_are_judged_against_the_reference(tiny):
    result = run(tiny, S.squat(tiny, 3.0, FPS, depth=0.4))
    assert result.passed, result.summary()
    start = result.rollout.root_height[0]
    assert result.rollout.root_height.min() < 0.6 * start  # an absolute height rule would call it a fall


def test_motor_actuated_robot_tracks_through_a_pd_servo_law():
    motors = index_robot(tiny_humanoid(actuator="motor"))
    assert not motors.actuator_is_position.any()
    stand = run(motors, S.standing(motors, 1.5, FPS))
    assert stand.passed, stand.summary()
    assert stand.report["metrics"]["tracking_rmse_rad"] < 0.02
    fall = run(motors, S.lift_foot_without_shift(motors, 2.0, FPS))
    assert "fall" in failed(fall)


def test_planted_foot_next_to_a_fast_swing_does_not_skate():
    from motok_robot.sim.kinematic import contact_skating

    fps = 20.0
    t = np.arange(10)
    sole = np.zeros((10, 2, 2))
    contact = np.ones((10, 2), bool)
    # left foot: planted for frames 0-4, then swings away fast (0.1 m per frame)
    contact[5:, 0] = False
    sole[5:, 0, 0] = 0.1 * (t[5:] - 4)
    # right foot: in contact throughout but sliding 1 cm per frame (0.2 m/s)
    sole[:, 1, 0] = 0.01 * t
    skating, distance = contact_skating(sole, contact, fps, speed_threshold=0.05)
    assert not skating[:, 0].any()  # frame 4 borders the swing but the foot did not move
    assert distance[0] == 0.0
    assert skating[:, 1].all()
    assert distance[1] == pytest.approx(0.09)


def test_a_motion_played_much_slower_than_its_source_fails_time_warp(tiny, tmp_path):
    qpos = S.standing(tiny, 1.0, FPS)
    config = ValidationConfig()
    for factor, passes in ((1.0, True), (config.max_time_warp, True), (config.max_time_warp * 1.5, False)):
        trajectory = RobotTrajectory(qpos, FPS, tiny.joint_names, tiny.name, source="slow.npz", retime_factor=factor)
        path = tmp_path / f"slow_{factor}.npz"
        save_robot_npz(path, trajectory)
        report = validate_file(path, tiny, physics=False, plots=False).report
        assert report["checks"]["time_warp"]["passed"] is passes
        assert report["metrics"]["time_warp"] == pytest.approx(factor)
        assert ("time_warp" in report["failed_checks"]) is (not passes)


@pytest.mark.parametrize("bad", [0.0, -2.0, float("nan"), float("inf")])
def test_a_retime_factor_that_is_not_a_positive_number_is_named(tiny, tmp_path, bad):
    path = tmp_path / "bad.npz"
    save_robot_npz(path, RobotTrajectory(S.standing(tiny, 1.0, FPS), FPS, tiny.joint_names, tiny.name))
    data = dict(np.load(path))
    data["retime_factor"] = np.float64(bad)
    np.savez(path, **data)
    with pytest.raises(InputError, match="field 'retime_factor' must be a positive number"):
        load_robot_npz(path, tiny)
