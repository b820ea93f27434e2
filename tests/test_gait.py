"""Walking with the robot's own steps: footsteps along the reference's path, the ZMP-planned CoM,
the stage's walk option, and validation's tracking of what the servos were commanded.

Every test uses the shipped op3_like model and synthetic motions.
"""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.feasibility.config import FeasibilityConfig, GaitConfig
from motok_robot.feasibility.footsteps import RobotFeet, plan_steps, walk_timing
from motok_robot.feasibility.gait import com_path, generate_gait, zmp_reference
from motok_robot.feasibility.stage import make_feasible, walks, write_feasible
from motok_robot.feasibility.zmp_shift import cart_table_zmp
from motok_robot.robots import load
from motok_robot.robots.index import index_robot
from motok_robot.sim import synthetic as S
from motok_robot.sim.validate import validate_file

FPS = 20.0


@pytest.fixture(scope="module")
def op3():
    return index_robot(load("op3_like"))


def _gliding(index, seconds: float, speed: float, rest_s: float = 0.0) -> np.ndarray:
    """The nominal pose with its base moved forward at ``speed`` (m/s), then still for ``rest_s``:
    a path, not a motion."""
    T = int(round(seconds * FPS)) + 1
    qpos = np.tile(index.nominal_qpos, (T + int(round(rest_s * FPS)), 1))
    qpos[:, 0] += speed * np.minimum(np.arange(len(qpos)), T - 1) / FPS
    return qpos


def test_the_com_path_puts_its_cart_table_zmp_on_the_reference():
    dt, height = 0.01, 0.25
    zmp = np.zeros((300, 2))
    zmp[100:200, 1] = 0.04  # the ZMP steps onto a foot 4 cm to the side for 1 s
    path = com_path(zmp, height, dt, zmp[0], zmp[-1], jerk_weight=1e-7)
    assert np.allclose(path[[0, -1]], 0.0, atol=1e-6)  # at rest where it starts and ends
    com = np.c_[path, np.full(len(path), height)]
    achieved = cart_table_zmp(com, 1.0 / dt)
    steady = np.r_[20:80, 130:180, 230:280]
    assert np.abs(achieved[steady] - zmp[steady]).max() < 0.003
    assert 0.01 < path[150, 1] < 0.045  # the CoM sways toward the foot, not past it


def test_footsteps_follow_the_path_within_the_step_limits(op3):
    feet = RobotFeet(op3)
    qpos = _gliding(op3, 4.0, 0.1, rest_s=1.0)  # the stage's lead-out: time for the last steps
    schedule = plan_steps(op3, qpos, FPS, first_step_frame=12, advance_per_leg=0.27, clearance_per_leg=0.15, feet=feet)
    assert schedule.steps >= 6
    advance = 0.27 * feet.leg_length
    by_foot = [[f for f in schedule.footholds if f.foot == k] for k in range(2)]
    for k in range(2):
        xs = np.array([f.pos[0] for f in by_foot[k]])
        assert np.all(np.diff(xs) > 0) and np.diff(xs).max() <= 2 * advance + 1e-6  # forward, within the limit
        assert abs(by_foot[k][-1].pos[0] - qpos[-1, 0]) < 0.02  # the last steps bring it where the path ends
    # never both feet in the air; both down before the first step; feet lifted at mid-swing
    assert schedule.contacts.any(axis=1).all() and schedule.contacts[:12].all()
    swing = ~schedule.contacts
    lifted = schedule.foot_pos[..., 2] - feet.height[None, :]
    assert lifted[swing].max() > 0.9 * 0.15 * feet.leg_length
    assert np.all(schedule.foot_pos[..., 2] >= feet.height[None, :] - 1e-9)  # never below the floor
    # the ZMP reference stays on a planned foot
    zmp = zmp_reference(schedule)
    near = np.min(np.linalg.norm(zmp[:, None] - np.array([f.centre for f in schedule.footholds])[None], axis=2), axis=1)
    single = schedule.contacts.sum(axis=1) == 1
    assert near[single].max() < 1e-9


def test_a_swing_rises_as_high_as_the_reference_foot_did_within_the_bounds(op3):
    feet = RobotFeet(op3)
    leg = feet.leg_length
    qpos = _gliding(op3, 4.0, 0.1, rest_s=1.0)
    reference_lift = np.zeros((len(qpos), 2))
    reference_lift[:, 1] = 0.25 * leg  # the right foot high all along, the left on the floor
    peaks = {}
    for highest in (None, 0.3, 0.2):
        schedule = plan_steps(op3, qpos, FPS, first_step_frame=12, clearance_per_leg=0.15, feet=feet,
                              reference_lift=reference_lift, max_clearance_per_leg=highest)
        lifted = (schedule.foot_pos[..., 2] - feet.height[None, :]) / leg
        peaks[highest] = lifted[~schedule.contacts[:, 0], 0].max(), lifted[~schedule.contacts[:, 1], 1].max()
    assert peaks[None] == pytest.approx((0.15, 0.15), abs=0.01)  # no upper bound given: the usual swing
    assert peaks[0.3] == pytest.approx((0.15, 0.25), abs=0.01)  # as high as the reference's right foot
    assert peaks[0.2] == pytest.approx((0.15, 0.2), abs=0.01)  # but no higher than the bound


def test_an_inner_foot_steps_in_as_far_as_a_wide_stance_allows_and_no_closer(op3):
    """Walking sideways (to the right) on a stance wider than the closest the feet may pass: the
    inner (left) foot lands as close to the stance foot as the path asks, further than a quarter
    step, but never closer than that gap."""
    from motok_robot.feasibility.footsteps import MIN_GAP_PER_LEG

    feet = RobotFeet(op3)
    advance = 0.27 * feet.leg_length
    qpos = _gliding(op3, 4.0, 0.0, rest_s=1.0)
    T = int(round(4.0 * FPS)) + 1
    qpos[:, 1] -= 0.5 * advance / 0.5 * np.minimum(np.arange(len(qpos)), T - 1) / FPS  # half a step per step, rightwards
    wide = feet.offset.copy()
    wide[:, 0] = 0.0
    wide[:, 1] += np.array([1.0, -1.0]) * 0.3 * feet.leg_length
    schedule = plan_steps(op3, qpos, FPS, first_step_frame=12, feet=feet, offsets=wide)
    closest = feet.offset[0, 1] - feet.offset[1, 1] + MIN_GAP_PER_LEG * feet.leg_length
    gaps = []  # the left foot's landing, across from the right foot it lands beside
    right = None
    for f in schedule.footholds:
        if f.foot == 1:
            right = np.asarray(f.pos[:2])
        elif right is not None:
            gaps.append(float(np.asarray(f.pos[:2])[1] - right[1]))
    gaps = np.array(gaps[1:-1])  # the walk, not the first and last steps
    width = wide[0, 1] - wide[1, 1]
    assert gaps.min() < width - 0.25 * advance - 0.002  # it stepped in more than a quarter step
    assert gaps.min() >= closest - 1e-6  # and never closer than the feet may pass


def test_the_trailing_foot_carries_nothing_from_the_other_feet_landing_until_it_lifts(op3):
    qpos = _gliding(op3, 4.0, 0.1, rest_s=1.0)
    schedule = plan_steps(op3, qpos, FPS, first_step_frame=12, double_support=0.2)
    contacts, loaded = schedule.contacts, schedule.loaded
    assert not (loaded & ~contacts).any()  # only a foot on the floor carries weight
    single = contacts.sum(axis=1) == 1
    assert np.array_equal(loaded[single], contacts[single])
    assert loaded[:12].all()  # standing before the first step: both feet
    landings = [t for t in range(13, len(contacts)) if (contacts[t] & ~contacts[t - 1]).any()]
    assert len(landings) >= 5
    for t in landings:
        landed = int(np.nonzero(contacts[t] & ~contacts[t - 1])[0][0])
        u = t
        while u < len(contacts) and contacts[u].all():  # the double support after the landing
            u += 1
        if u < len(contacts):  # another step follows (else both feet stand at the end, loaded)
            assert all(loaded[v].tolist() == [landed == 0, landed == 1] for v in range(t, u)), t
    # the ZMP reference is on the landed foot after the transfer share of each double support
    zmp = zmp_reference(schedule, transfer_share=0.5)
    centre = {(f.foot, f.start): f.centre for f in schedule.footholds}
    for t in landings[:-1]:
        landed = int(np.nonzero(contacts[t] & ~contacts[t - 1])[0][0])
        assert np.allclose(zmp[t + 1], centre[(landed, t)])  # 2 frames of double support: on it at the second
        assert not np.allclose(zmp_reference(schedule)[t + 1], centre[(landed, t)])  # share 1: still between


def test_the_inverse_dynamics_gives_an_unloaded_foot_no_share_of_the_weight(op3):
    from motok_robot.feasibility.dynamics import required_torque

    qpos = np.tile(op3.nominal_qpos, (5, 1))
    _, _, both = required_torque(op3, qpos, FPS)
    loaded = np.ones((5, 2), dtype=bool)
    loaded[:, 1] = False  # the right foot down, planned to carry nothing
    _, _, left_only = required_torque(op3, qpos, FPS, loaded=loaded)
    knee = [j for j, n in enumerate(op3.joint_names) if "knee" in n]
    right_knee = [j for j in knee if op3.joint_names[j].startswith("r")][0]
    left_knee = [j for j in knee if op3.joint_names[j].startswith("l")][0]
    # the right knee holds only its shank and foot, the left knee the whole robot above it
    assert abs(left_only[2, right_knee]) < 0.3 * abs(both[2, right_knee])
    assert abs(left_only[2, left_knee]) > 1.5 * abs(both[2, left_knee])
    with pytest.raises(ValueError, match="loaded"):
        required_torque(op3, qpos, FPS, loaded=loaded[:3])


def test_the_time_warp_slows_what_the_robot_cannot_step(op3):
    feet = RobotFeet(op3)
    robot_speed = 0.27 * feet.leg_length / 0.5
    gait = GaitConfig(max_advance_per_leg=0.27)
    warp = {k: walk_timing(_gliding(op3, 4.0, k * robot_speed), FPS, feet, gait).time_warp for k in (0.5, 2.0, 5.0)}
    assert warp[0.5] == 1.0
    assert warp[2.0] == pytest.approx(2.0, rel=0.05)
    assert warp[5.0] == 3.0  # capped


def test_a_sideways_path_is_slowed_by_the_sideways_steps_the_robot_can_take(op3):
    """Sideways the feet cover (1/2 + 1/4) / 2 of a step length per step (the trailing foot may
    not cross the leading one): a generated kick that drifted sideways was planned 2.7x too fast
    and ended 0.2-0.3 m beside its path."""
    feet = RobotFeet(op3)
    robot_speed = 0.27 * feet.leg_length / 0.5
    side = _gliding(op3, 4.0, 0.5 * robot_speed)
    side[:, 1], side[:, 0] = side[:, 0] - side[0, 0] + side[0, 1], side[0, 0]  # the same speed along +y
    gait = GaitConfig(max_advance_per_leg=0.27, sideways_timing=True)
    assert walk_timing(side, FPS, feet, gait).time_warp == pytest.approx(0.5 / 0.375, rel=0.05)
    assert walk_timing(_gliding(op3, 4.0, 0.5 * robot_speed), FPS, feet, gait).time_warp == 1.0
    assert walk_timing(side, FPS, feet, GaitConfig(max_advance_per_leg=0.27)).time_warp == 1.0  # off: speed only


def test_a_path_too_fast_even_at_the_largest_time_warp_is_walked_with_longer_then_quicker_steps(op3):
    feet = RobotFeet(op3)
    robot_speed = 0.27 * feet.leg_length / 0.5
    gait = GaitConfig(max_advance_per_leg=0.4, min_step_period_s=0.3)
    timing = {k: walk_timing(_gliding(op3, 4.0, k * robot_speed), FPS, feet, gait) for k in (2.0, 3.5, 6.0, 20.0)}
    assert (timing[2.0].advance_per_leg, timing[2.0].step_period_s) == (0.27, 0.5)  # 2x slower is enough
    assert timing[3.5].advance_per_leg == pytest.approx(0.27 * 3.5 / 3.0, rel=0.05)  # just long enough at 3x
    assert timing[3.5].step_period_s == 0.5
    assert timing[6.0].advance_per_leg == 0.4  # as long as they may be, and quicker
    assert timing[6.0].step_period_s == pytest.approx(0.5 * (0.4 / 0.27) * 3.0 / 6.0, rel=0.05)
    assert timing[6.0].time_warp == pytest.approx(3.0)
    assert (timing[20.0].advance_per_leg, timing[20.0].step_period_s) == (0.4, 0.3)  # the robot still falls behind
    assert walk_timing(_gliding(op3, 4.0, 6.0 * robot_speed), FPS, feet,
                       GaitConfig(max_advance_per_leg=0.4)).step_period_s == 0.5  # quicker steps are opt-in


def test_the_whole_body_puts_the_feet_on_the_footholds_within_the_velocity_limits(op3):
    qpos = _gliding(op3, 3.0, 0.06)
    schedule = plan_steps(op3, qpos, FPS, first_step_frame=12)
    walk = generate_gait(op3, qpos, FPS, schedule)
    assert np.median(walk.foot_errors) < 0.002 and walk.com_error_m < 0.005
    speed = np.abs(np.diff(walk.qpos[:, op3.qpos_adr], axis=0)) * FPS / op3.velocity_limit
    assert speed.max() <= 0.9 + 1e-6
    arms = [j for j, n in enumerate(op3.joint_names) if "sho" in n or "el" in n or "head" in n]
    assert np.array_equal(walk.qpos[:, op3.qpos_adr[arms]], qpos[:, op3.qpos_adr[arms]])  # upper body kept


def test_a_walk_starting_on_a_straight_knee_still_puts_that_foot_on_the_floor():
    """A reference that starts with the right leg straight and swung forward (the first frame of
    a real Bandai walk on the OP3): from there the leg solve holds the knee at its limit and
    left the foot 6 mm into the floor, which kicked the robot over in physics; the first frame
    now starts again from the robot's own stance."""
    index = index_robot(load("op3"))
    qpos = _gliding(index, 3.0, 0.06)
    for joint, angle in (("r_hip_pitch", 0.693), ("r_knee", 0.0), ("r_ank_pitch", 0.462)):
        qpos[:, index.qpos_adr[index.joint_names.index(joint)]] = angle
    schedule = plan_steps(index, qpos, FPS, first_step_frame=12)
    walk = generate_gait(index, qpos, FPS, schedule)
    assert walk.foot_errors[:12].max() < 1e-3


def test_the_walks_joints_stay_below_the_speed_their_damping_allows(op3):
    from motok_robot.feasibility.stage import damping_speed_limit

    limit = damping_speed_limit(op3, 0.75)
    damping = op3.kin_model.dof_damping[op3.dof_adr]
    assert np.allclose(limit[damping > 0], 0.75 * op3.torque_limit[damping > 0] / damping[damping > 0])
    qpos = _gliding(op3, 3.0, 0.06)
    schedule = plan_steps(op3, qpos, FPS, first_step_frame=12)
    free = generate_gait(op3, qpos, FPS, schedule)
    legs = [j for j, n in enumerate(op3.joint_names) if not ("sho" in n or "el" in n or "head" in n)]
    speed = lambda w: np.abs(np.diff(w.qpos[:, op3.qpos_adr[legs]], axis=0)).max() * FPS  # noqa: E731
    assert speed(free) > 1.0  # the walk moves its legs faster than the bound below
    bounded = generate_gait(op3, qpos, FPS, schedule, speed_limit=np.full(op3.nj, 1.0))
    assert speed(bounded) <= 1.0 + 1e-6


def test_a_leg_held_back_by_its_speed_limit_keeps_the_foot_flat(op3):
    """The swing foot asked to rise faster than its knee may bend: it rises as far as the knee
    allows and stays flat where it is (the joint at its bound is held and the others re-solved
    around it), rather than the hip and ankle doing their share of the full lift alone, which
    tipped the foot up 30 deg about its heel and shoved it 57 mm forward along the floor."""
    import mujoco

    from motok_robot.feasibility.zmp_shift import leg_dofs, solve_legs

    legs = leg_dofs(op3)
    data = mujoco.MjData(op3.kin_model)
    start = op3.nominal_qpos.copy()
    data.qpos[:] = start
    mujoco.mj_kinematics(op3.kin_model, data)
    foot = op3.sole_body[1]
    pos, quat = data.xpos[op3.sole_body].copy(), data.xquat[op3.sole_body].copy()
    goal = pos.copy()
    goal[1, 2] += 0.015  # the right foot 15 mm up in one frame, flat
    knee = op3.qpos_adr[op3.joint_names.index("r_knee")]
    max_step = np.full(op3.kin_model.nq, 0.3)
    max_step[knee] = 0.05  # rad per frame: the knee is too slow for that
    q = start.copy()
    solve_legs(op3, q, goal, quat, legs, data, previous=start, max_step=max_step)
    assert abs(q[knee] - start[knee]) == pytest.approx(0.05)
    data.qpos[:] = q
    mujoco.mj_kinematics(op3.kin_model, data)
    moved = data.xpos[foot] - pos[1]
    tilt = np.degrees(2 * np.arccos(min(1.0, abs(float(np.dot(data.xquat[foot], quat[1]))))))
    assert 0.001 < moved[2] < 0.015 and np.hypot(moved[0], moved[1]) < 0.002
    assert tilt < 1.0, f"the foot tipped {tilt:.1f} deg"


def test_the_walks_base_height_leaves_out_the_human_pelvis_bob(op3):
    """A reference whose pelvis bobs 1 cm at a human's step period: the robot's base keeps the
    mean height and a slow change of it, not the bob."""
    qpos = _gliding(op3, 6.0, 0.06)
    t = np.arange(len(qpos)) / FPS
    slow = 0.01 * np.clip((t - 3.0) / 2.0, 0.0, 1.0)  # a 1 cm dip over 2 s, kept
    qpos[:, 2] += 0.005 * np.sin(2 * np.pi * t / 0.55) - slow
    schedule = plan_steps(op3, qpos, FPS, first_step_frame=12)
    kept = generate_gait(op3, qpos, FPS, schedule)
    smooth = generate_gait(op3, qpos, FPS, schedule, height_window_s=1.0)
    inner = slice(int(1.5 * FPS), int(5.5 * FPS))
    bob = lambda z: np.abs(np.diff(z[inner], 2)).max() * FPS ** 2  # noqa: E731  (vertical acceleration)
    assert bob(smooth.qpos[:, 2]) < 0.25 * bob(kept.qpos[:, 2])
    dip = smooth.qpos[int(1.5 * FPS), 2] - smooth.qpos[-1, 2]
    assert 0.007 < dip < 0.013  # the slow change is followed
    assert np.median(smooth.foot_errors) < 0.002


def test_only_a_motion_that_goes_somewhere_is_walked(op3):
    feet, config = RobotFeet(op3), GaitConfig()
    assert walks(op3, S.walk(op3, steps=6, step_period_s=1.0, fps=FPS), feet, config)
    assert not walks(op3, S.standing(op3, 2.0, FPS), feet, config)
    assert not walks(op3, S.lift_foot_without_shift(op3, 3.0, FPS), feet, config)


def test_feet_that_rise_high_are_walked_only_when_the_motion_goes_far(op3):
    """A run lifts its feet as high as a kick; only the run leaves the spot."""
    feet = RobotFeet(op3)
    config = GaitConfig()  # min_run_travel_per_leg 2
    leg = feet.leg_length

    def hopping(distance_per_leg: float) -> np.ndarray:
        qpos = _gliding(op3, 3.0, distance_per_leg * leg / 3.0)
        qpos[20:26, 2] += 0.35 * leg  # both soles 0.35 leg lengths up for 0.3 s
        return qpos

    assert walks(op3, hopping(3.0), feet, config)
    assert not walks(op3, hopping(1.5), feet, config)  # soles travel, but it ends near its start
    assert not walks(op3, hopping(3.0), feet, GaitConfig(min_run_travel_per_leg=1000.0))  # off
    assert walks(op3, _gliding(op3, 3.0, 1.5 * leg / 3.0), feet, config)  # low feet: walked as before


def test_the_stage_walks_a_walk_with_the_robots_steps_and_validation_passes_what_it_should(op3, tmp_path, retargeted):
    qpos = S.walk(op3, steps=6, step_period_s=1.0, fps=FPS, double_support=0.2)
    gait = GaitConfig(enabled=True)
    result = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig(gait=gait))
    record = result.record["gait"]
    assert record["steps"] >= 6 and record["time_warp"] == 1.0
    lead = int(round(record["lead_in_s"] * FPS))
    out = result.trajectory
    # the reference gained the lead-in and lead-out, and the task differs from it in the legs only
    assert out.qpos.shape[0] == qpos.shape[0] + lead + int(round(record["lead_out_s"] * FPS))
    assert np.array_equal(out.reference_qpos[lead:lead + qpos.shape[0]], qpos)
    assert out.task_qpos is not None and not np.allclose(out.task_qpos, out.reference_qpos)
    assert not result.fell
    path = write_feasible(result, tmp_path, op3.name)
    report = validate_file(path, op3, plots=False).report
    # every check, the feet's sliding included: with the trailing foot loaded in the feedforward
    # until it lifts (two frames of double support, the ZMP moving across over all of it) this
    # walk failed foot_skate_ratio (0.127) and foot_skate_distance (0.061 m)
    assert report["passed"], {k: c["value"] for k, c in report["checks"].items() if not c["passed"]}


def test_tracking_is_judged_against_what_the_servos_were_commanded(op3, tmp_path, retargeted):
    walk = S.walk(op3, steps=2, step_period_s=3.2, fps=FPS)
    result = make_feasible(retargeted(op3, walk), op3, FeasibilityConfig())
    path = write_feasible(result, tmp_path / "a", op3.name)
    honest = validate_file(path, op3, plots=False).report["metrics"]["tracking_rmse_rad"]
    # the same execution, claimed to follow a task with the knees bent 0.3 rad more
    data = dict(np.load(path))
    knees = op3.qpos_adr[[j for j, n in enumerate(op3.joint_names) if "knee" in n]]
    data["task_qpos"] = data["task_qpos"].copy()
    data["task_qpos"][:, knees] += 0.3
    np.savez(tmp_path / "claimed.npz", **data)
    claimed = validate_file(tmp_path / "claimed.npz", op3, plots=False).report["metrics"]["tracking_rmse_rad"]
    assert honest < 0.05 and claimed > honest + 0.05
    data["task_qpos"] = data["task_qpos"][:-1]
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(InputError, match="task_qpos"):
        validate_file(tmp_path / "bad.npz", op3, plots=False)


def test_gait_settings_are_bounded():
    with pytest.raises(InputError, match="step_period_s"):
        GaitConfig(step_period_s=0.05)
    with pytest.raises(InputError, match="max_time_warp"):
        GaitConfig(max_time_warp=10)


def test_run_and_feasible_offer_the_own_steps_walk():
    import argparse

    from motok_robot.feasibility.cli import register as register_feasible
    from motok_robot.pipeline.cli import feasibility_config
    from motok_robot.pipeline.cli import register as register_run

    parser = argparse.ArgumentParser()
    commands = parser.add_subparsers()
    register_run(commands, {})
    register_feasible(commands, {})
    settings = feasibility_config(parser.parse_args(["run", "a person walks", "--out", "o", "--feasible", "--feasible-own-steps"]))
    assert settings == {"gait": {"enabled": True}}  # applied over the robot's own settings
    assert feasibility_config(parser.parse_args(["run", "a person walks", "--out", "o", "--feasible"])) == {}
    assert feasibility_config(parser.parse_args(["run", "a person walks", "--out", "o", "--feasible",
                                                 "--feasible-retime", "1.5"])) == {"retime": 1.5}
    with pytest.raises(InputError, match="--feasible-own-steps needs --feasible"):
        feasibility_config(parser.parse_args(["run", "a person walks", "--out", "o", "--feasible-own-steps"]))
    assert parser.parse_args(["feasible", "robot.npz", "--out", "o", "--own-steps"]).own_steps
    from motok_robot.pipeline.cli import pipeline_config

    assert pipeline_config(parser.parse_args(["run", "a person walks", "--out", "o"])).walk_own_steps
    assert not pipeline_config(parser.parse_args(["run", "a person walks", "--out", "o", "--no-own-steps"])).walk_own_steps


def test_run_walks_a_motion_that_travels_with_the_robots_own_steps(op3):
    from types import SimpleNamespace

    from motok_robot.pipeline import PipelineConfig
    from motok_robot.pipeline.stages import walk_config

    entry = {"index": op3}
    walk = SimpleNamespace(qpos=S.walk(op3, steps=6, step_period_s=1.0, fps=FPS))
    config = walk_config(PipelineConfig(), entry, walk)
    assert config is not None and config.gait.enabled
    assert walk_config(PipelineConfig(walk_own_steps=False), entry, walk) is None
    assert walk_config(PipelineConfig(), entry, SimpleNamespace(qpos=S.standing(op3, 2.0, FPS))) is None


@pytest.mark.slow
def test_run_reports_the_feasibility_stages_time_warp(tmp_path):
    """``run --feasible`` records how many times slower the robot plays the motion (about 10 s)."""
    from pathlib import Path

    from motok_robot.pipeline import Pipeline, PipelineConfig

    demo = Path(__file__).resolve().parents[1] / "examples" / "wave_demo.npz"
    pipe = Pipeline(PipelineConfig(plots=False, max_retime=1.0, feasibility=FeasibilityConfig(retime=1.5)))
    result = pipe.run(None, motion=demo, robot="op3_like", out_dir=tmp_path / "wave", render=False)
    assert result.retime_factor == pytest.approx(1.5)
    assert any("time warp 1.50x" in note for note in result.notes)
