"""The third-party robots shipped in models/mjcf (Menagerie op3, g1, t1; ToddlerBot): they load, their descriptions
match their models, they stand on flat soles, and a short motion retargets onto them and validates."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.motion import skeleton as sk
from motok_robot.robots import DEFAULT_ROBOT, list_robots, load, models_dir

REAL = ("op3", "g1", "t1", "toddlerbot")
# robots whose published model places an IMU (ToddlerBot's MJCF does not: the torso frame stands in)
WITH_IMU = ("op3", "g1", "t1")

# ROBOTIS-OP3 framework IDs (right odd, left even, head last)
OP3_IDS = {
    "r_sho_pitch": 1, "l_sho_pitch": 2, "r_sho_roll": 3, "l_sho_roll": 4, "r_el": 5, "l_el": 6,
    "r_hip_yaw": 7, "l_hip_yaw": 8, "r_hip_roll": 9, "l_hip_roll": 10, "r_hip_pitch": 11, "l_hip_pitch": 12,
    "r_knee": 13, "l_knee": 14, "r_ank_pitch": 15, "l_ank_pitch": 16, "r_ank_roll": 17, "l_ank_roll": 18,
    "head_pan": 19, "head_tilt": 20,
}


@pytest.fixture(scope="module", params=REAL)
def robot(request):
    return load(request.param)


@pytest.fixture(scope="module")
def op3():
    return load("op3")


def _pose(robot, qpos):
    d = mujoco.MjData(robot.model)
    d.qpos[:] = qpos
    mujoco.mj_forward(robot.model, d)
    return d


def test_listed_and_the_op3_is_the_default():
    assert set(REAL) <= set(list_robots())
    assert DEFAULT_ROBOT == "op3"


def test_loads_with_a_complete_description(robot):
    assert robot.nj == robot.model.nu and robot.model.nq == 7 + robot.nj
    assert len(robot.keypoints) == 18
    for sole in robot.soles.values():
        assert len(sole.corner_sites) == 4
    if robot.name in WITH_IMU:
        assert robot.model.site("imu").bodyid >= 1
    assert np.all(robot.velocity_limit > 0) and np.all(robot.torque_limit > 0)
    # the meshes stay in the robot's own folder next to its MJCF
    assert (models_dir() / robot.name / "LICENSE").is_file()
    assert (models_dir() / robot.name / "README.md").is_file()


@pytest.mark.parametrize("name", REAL)
def test_robots_show(name, capsys):
    assert main(["robots", "show", name]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{name}:") and "keypoints" in out


def test_op3_mass_and_identified_servo_model(op3):
    m = op3.model
    assert 3.1 <= op3.total_mass() <= 3.2
    assert op3.nj == 20 and m.nu == 20
    for a in range(m.nu):
        assert m.actuator_gainprm[a, 0] == pytest.approx(21.1)
        assert m.actuator_biasprm[a, 1] == pytest.approx(-21.1)
        assert m.actuator_forcelimited[a] and tuple(m.actuator_forcerange[a]) == (-5.0, 5.0)
        assert tuple(m.actuator_ctrlrange[a]) == pytest.approx((-3.141592, 3.141592))
    dofs = op3.dof_adr
    np.testing.assert_allclose(m.dof_damping[dofs], 1.084)
    np.testing.assert_allclose(m.dof_armature[dofs], 0.045)
    np.testing.assert_allclose(m.dof_frictionloss[dofs], 0.03)
    # the XM430-W350's stall torque clamps the joints (the identified forcerange of 5 N m is above it)
    np.testing.assert_allclose(op3.torque_limit, 4.1)


def test_op3_elbows_bend_one_way_when_retargeted_only(op3):
    from retarget.robot_model import RetargetRobot

    solver_range = RetargetRobot.from_robot(op3).joint_range
    for joint, (lo, hi) in (("l_el", (-2.4, 0.0)), ("r_el", (0.0, 2.4))):
        i = op3.joint_index(joint)
        np.testing.assert_allclose(op3.retarget_range[i], (lo, hi))
        np.testing.assert_allclose(solver_range[i], (lo, hi))
        np.testing.assert_allclose(op3.joint_range[i], (-2.4, 2.4))  # the servos keep the MJCF's range
    others = [i for i, n in enumerate(op3.joint_names) if n not in ("l_el", "r_el")]
    np.testing.assert_array_equal(op3.retarget_range[others], op3.joint_range[others])


def test_op3_servo_map_and_bus(op3):
    assert {s.joint: s.id for s in op3.servos} == OP3_IDS
    assert all(s.model == "XM430-W350" and s.ticks_per_rev == 4096 for s in op3.servos)
    assert (op3.bus.protocol, op3.bus.baud, op3.bus.control_hz) == (2.0, 2_000_000, 125.0)
    for s in op3.servos:
        lo, hi = op3.joint_range[op3.joint_index(s.joint)]
        slo, shi = s.angle_range
        assert 0 <= s.min_ticks < s.max_ticks <= 4095
        # the joint range rounded outwards to whole ticks: never more than one tick wider
        assert lo - s.rad_per_tick < slo <= lo + 1e-12 and hi - 1e-12 <= shi < hi + s.rad_per_tick, s.joint
        assert s.zero_offset_ticks == 2048 and s.sign == 1


def test_robots_without_dynamixels_have_no_servo_map():
    for name in ("g1", "t1", "toddlerbot"):
        r = load(name)
        assert r.servos == [] and r.bus is None
        assert np.all(np.isfinite(r.velocity_limit))


def test_toddlerbot_is_a_serial_chain_with_its_couplings_folded_in():
    r = load("toddlerbot")
    m = r.model
    # one actuated hinge per degree of freedom: no gear equalities, linkage constraints or waist tendons
    assert m.neq == 0 and m.ntendon == 0 and r.nj == 30
    assert abs(r.total_mass() - 3.4536) < 1e-3  # the published 3.454 kg, gear and rod bodies kept

    def act(name):
        a = m.actuator(name).id
        return m.actuator_gainprm[a, 0], m.actuator_forcerange[a, 1]

    # published: kp 10 / 14 / 4 and +-10 N m at the servo; geared joints through their ratio c
    assert act("left_knee") == pytest.approx((14.0, 10.0))
    assert act("left_wrist_roll") == pytest.approx((4.0, 10.0))
    assert act("left_hip_yaw") == pytest.approx((10.0 / 0.8571428571**2, 10.0 / 0.8571428571), rel=1e-5)
    assert act("neck_yaw") == pytest.approx((10.0 / 0.9090909091**2, 10.0 / 0.9090909091), rel=1e-5)
    assert act("waist_yaw") == pytest.approx((10.0 / (2 * 0.20833333**2), 10.0 / 0.20833333), rel=1e-5)
    assert act("waist_roll") == pytest.approx((10.0 / (2 * 0.29166667**2), 10.0 / 0.29166667), rel=1e-5)
    # the nominal pose is the published "home" keyframe: knees bent 0.38 rad, soles flat
    q = r.nominal_joints()
    assert q[r.joint_index("left_knee")] == pytest.approx(-0.380812)
    assert q[r.joint_index("right_knee")] == pytest.approx(0.380812)


def test_mass_and_height_in_documented_ranges(robot):
    lo, hi = robot.description.mass_range
    assert lo <= robot.total_mass() <= hi
    lo, hi = robot.description.height_range
    assert lo <= robot.height() <= hi


def test_standing_nominal_pose_has_both_soles_flat_on_the_floor(robot):
    q = robot.standing_qpos(robot.nominal_joints())
    assert abs(robot.lowest_sole_height(q)) < 1e-3
    d = _pose(robot, q)
    for side, sole in robot.soles.items():
        z = [d.site(s).xpos[2] for s in (sole.site, *sole.corner_sites)]
        np.testing.assert_allclose(z, 0.0, atol=1e-3, err_msg=side)
    # the only contacts are soles on the floor
    floor = robot.model.geom("floor").id
    feet = {robot.model.body(s.body).id for s in robot.soles.values()}
    assert d.ncon >= 2
    for c in d.contact[: d.ncon]:
        other = c.geom2 if c.geom1 == floor else c.geom1
        assert floor in (c.geom1, c.geom2) and robot.model.geom_bodyid[other] in feet
    assert q[2] < robot.standing_qpos(np.zeros(robot.nj))[2] - 0.005  # slightly crouched


def test_sole_corners_span_the_documented_half_size(robot):
    d = _pose(robot, robot.qpos_from_joints(np.zeros(robot.nj)))
    for sole in robot.soles.values():
        fl, fr, rr, rl = (d.site(s).xpos for s in sole.corner_sites)
        assert np.linalg.norm(fl - rl) == pytest.approx(2 * sole.half_size[0], abs=1e-6)
        assert np.linalg.norm(fl - fr) == pytest.approx(2 * sole.half_size[1], abs=1e-6)
        np.testing.assert_allclose((fl + fr + rr + rl) / 4, d.site(sole.site).xpos, atol=1e-6)
        assert fl[0] > rl[0] and fl[1] > fr[1]  # front-left is in front and to the left


def test_limb_scale_matches_the_model(robot):
    d = _pose(robot, robot.qpos_from_joints(np.zeros(robot.nj)))
    site = {k.human_joint: d.site(k.site).xpos.copy() for k in robot.keypoints}
    rest = sk.rest_pose()
    human = {n: rest[sk.JOINT_INDEX[n]] for n in sk.JOINT_NAMES}

    def length(p, chain):
        return sum(np.linalg.norm(p[b] - p[a]) for a, b in zip(chain, chain[1:]))

    chains = {"legs": ("left_hip", "left_knee", "left_ankle"), "arms": ("left_shoulder", "left_elbow", "left_wrist"),
              "torso": ("pelvis", "neck"), "head": ("neck", "head")}
    for limb, chain in chains.items():
        assert robot.limb_scale[limb] == pytest.approx(length(site, chain) / length(human, chain), rel=0.01), limb


def test_keypoints_are_left_right_symmetric(robot):
    d = _pose(robot, robot.nominal_qpos())
    pos = {k.human_joint: d.site(k.site).xpos.copy() for k in robot.keypoints}
    for name, p in pos.items():
        if name.startswith("left_"):
            np.testing.assert_allclose(p * [1, -1, 1], pos["right_" + name[5:]], atol=1e-4, err_msg=name)


def test_retarget_kinematics_match_mujoco(robot):
    from retarget.kinematics import kinematics_function

    m = robot.model
    fk = kinematics_function(m)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    for _ in range(3):
        q = robot.nominal_qpos()
        q[robot.qpos_adr] += rng.normal(scale=0.3, size=robot.nj)
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        site_pos = np.array(fk(q)[0])
        assert np.abs(site_pos - d.site_xpos.T).max() < 1e-9


def _standing_clip(T: int = 20) -> np.ndarray:
    """A human standing with slightly bent knees, arms held out to the sides, hands rising forwards."""
    rest = sk.rest_pose()
    J = sk.JOINT_INDEX
    frame = rest.copy()
    frame[[J[n] for n in sk.JOINT_NAMES if "ankle" not in n and "foot" not in n], 2] -= 0.02
    clip = np.repeat(frame[None], T, axis=0)
    s = np.sin(np.linspace(0.0, math.pi, T))
    for side, out in (("left", 1.0), ("right", -1.0)):
        sh = clip[:, J[f"{side}_shoulder"]]
        clip[:, J[f"{side}_elbow"]] = sh + [0.0, 0.18 * out, -0.2]
        clip[:, J[f"{side}_wrist"]] = sh + [0.0, 0.36 * out, -0.38] + s[:, None] * [0.15, 0.0, 0.1]
    return clip


@pytest.mark.parametrize("name", REAL)
def test_short_motion_retargets_and_validates(name, tmp_path):
    motion = tmp_path / "motion.npz"
    np.savez(motion, joints=_standing_clip().astype(np.float32), fps=20)
    out = tmp_path / "robot.npz"
    # self-collision avoidance off to keep it fast (the clip keeps the arms clear); validation still checks it.
    # ToddlerBot's feet are wide for its legs: the scaled human stance brings its ankle boxes together
    # (2 cm overlap without avoidance), so it keeps the avoidance on
    avoid = [] if name == "toddlerbot" else ["--no-self-collision"]
    assert main(["retarget", str(motion), "--robot", name, "--out", str(out), "--window", "20", "--overlap", "5",
                 *avoid]) == 0
    assert main(["validate", str(out), "--out", str(tmp_path / "val"), "--no-render", "--no-plots"]) == 0
