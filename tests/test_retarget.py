"""Retargeting: self-retargeting identity, contacts on a synthetic walk, limits, files, errors.

The robot here is a small humanoid written in the test (16 hinge joints, box soles with corner
sites), so these tests do not depend on the robot stage; one CLI test uses op3_like when present.
Windows are short to keep the run time small.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("casadi")

from motok_robot.errors import InputError  # noqa: E402
from motok_robot.motion.skeleton import JOINT_INDEX, JOINT_NAMES, rest_pose  # noqa: E402
from retarget.config import CollisionConfig, ContactConfig, CostWeights, RetargetConfig, SolverConfig  # noqa: E402
from retarget.contacts import contact_phases, detect_contacts  # noqa: E402
from retarget.io import read_input, read_robot_npz, write_robot_npz  # noqa: E402
from retarget.metrics import measure  # noqa: E402
from motok_robot.robots.description import Keypoint  # noqa: E402
from retarget.robot_model import RetargetRobot, SoleSites  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402


def _leg(side: str, y: float) -> str:
    s = side[0]
    return f"""
      <body name="{s}_thigh" pos="0 {y} -0.03">
        <joint name="{s}_hip_yaw" axis="0 0 1" range="-0.6 0.6"/>
        <joint name="{s}_hip_roll" axis="1 0 0" range="-0.5 0.5"/>
        <joint name="{s}_hip_pitch" axis="0 1 0" range="-1.8 0.8"/>
        <site name="{s}_hip"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.11" size="0.015" mass="0.15"/>
        <body name="{s}_shank" pos="0 0 -0.11">
          <joint name="{s}_knee" axis="0 1 0" range="0 2.3"/>
          <site name="{s}_knee"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.11" size="0.015" mass="0.12"/>
          <body name="{s}_foot" pos="0 0 -0.11">
            <joint name="{s}_ank_pitch" axis="0 1 0" range="-1.2 1.2"/>
            <joint name="{s}_ank_roll" axis="1 0 0" range="-0.5 0.5"/>
            <site name="{s}_ankle"/>
            <geom type="box" size="0.06 0.035 0.01" pos="0.02 0 -0.02" mass="0.1"/>
            <site name="{s}_sole" pos="0.02 0 -0.03"/>
            <site name="{s}_toe" pos="0.08 0 -0.03"/>
            <site name="{s}_c0" pos="0.08 0.035 -0.03"/>
            <site name="{s}_c1" pos="0.08 -0.035 -0.03"/>
            <site name="{s}_c2" pos="-0.04 -0.035 -0.03"/>
            <site name="{s}_c3" pos="-0.04 0.035 -0.03"/>
          </body>
        </body>
      </body>"""


def _arm(side: str, y: float, roll_range: str) -> str:
    s = side[0]
    return f"""
        <body name="{s}_upper_arm" pos="0 {y} 0.15">
          <joint name="{s}_sho_pitch" axis="0 1 0" range="-2.5 2.5"/>
          <joint name="{s}_sho_roll" axis="1 0 0" range="{roll_range}"/>
          <site name="{s}_shoulder"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.09" size="0.012" mass="0.1"/>
          <body name="{s}_forearm" pos="0 0 -0.09">
            <joint name="{s}_el" axis="0 1 0" range="-2.2 0"/>
            <site name="{s}_elbow"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.09" size="0.01" mass="0.08"/>
            <site name="{s}_hand" pos="0 0 -0.09"/>
          </body>
        </body>"""


TOY_XML = f"""
<mujoco model="toy">
  <compiler angle="radian"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="pelvis" pos="0 0 0.3">
      <freejoint name="root"/>
      <geom type="box" size="0.03 0.05 0.02" mass="0.6"/>
      <site name="pelvis"/>
      <body name="torso" pos="0 0 0.02">
        <geom type="box" size="0.03 0.06 0.07" pos="0 0 0.08" mass="1.0"/>
        <site name="neck" pos="0 0 0.17"/>
        <site name="head" pos="0 0 0.21"/>
        {_arm("left", 0.08, "-0.3 1.6")}
        {_arm("right", -0.08, "-1.6 0.3")}
      </body>
      {_leg("left", 0.035)}
      {_leg("right", -0.035)}
    </body>
  </worldbody>
</mujoco>
"""

KEYPOINTS = {
    "pelvis": "pelvis", "left_hip": "l_hip", "right_hip": "r_hip", "left_knee": "l_knee", "right_knee": "r_knee",
    "left_ankle": "l_ankle", "right_ankle": "r_ankle", "left_foot": "l_toe", "right_foot": "r_toe",
    "neck": "neck", "head": "head", "left_shoulder": "l_shoulder", "right_shoulder": "r_shoulder",
    "left_elbow": "l_elbow", "right_elbow": "r_elbow", "left_wrist": "l_hand", "right_wrist": "r_hand",
}


def toy_robot() -> RetargetRobot:
    model = mujoco.MjModel.from_xml_string(TOY_XML)
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(1, model.njnt)]
    adr = np.array([model.jnt_qposadr[j] for j in range(1, model.njnt)])
    nominal = model.qpos0.copy()
    pose = {"l_hip_pitch": -0.3, "l_knee": 0.6, "l_ank_pitch": -0.3, "r_hip_pitch": -0.3, "r_knee": 0.6, "r_ank_pitch": -0.3,
            "l_el": -0.3, "r_el": -0.3, "l_sho_roll": 0.1, "r_sho_roll": -0.1}
    for n, v in pose.items():
        nominal[adr[names.index(n)]] = v
    data = mujoco.MjData(model)
    data.qpos[:] = nominal
    mujoco.mj_kinematics(model, data)
    sole = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "l_sole")
    nominal[2] -= data.site_xpos[sole, 2]  # soles on the floor
    return RetargetRobot(
        name="toy", model=model, joint_names=names, qpos_adr=adr,
        joint_range=np.array([model.jnt_range[j] for j in range(1, model.njnt)]),
        velocity_limit=np.full(len(names), 6.0), nominal_qpos=nominal,
        keypoints=[Keypoint(h, s, 1.0) for h, s in KEYPOINTS.items()],
        soles={side: SoleSites(f"{side[0]}_sole", tuple(f"{side[0]}_c{i}" for i in range(4))) for side in ("left", "right")},
        limb_scale={"legs": 0.27, "arms": 0.35, "torso": 0.3, "head": 0.4},
    )


@pytest.fixture(scope="module")
def robot() -> RetargetRobot:
    return toy_robot()


@pytest.fixture(scope="module")
def small(robot) -> Retargeter:
    """One retargeter with short windows, shared (its problems are built once)."""
    return Retargeter(robot, SMALL)


def sites_to_human(robot: RetargetRobot, qpos: np.ndarray) -> np.ndarray:
    """Human joints [T, 22, 3] whose mapped joints are the robot's keypoint sites (others interpolated)."""
    data = mujoco.MjData(robot.model)
    out = np.zeros((len(qpos), 22, 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(robot.model, data)
        for k in robot.keypoints:
            sid = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, k.site)
            out[t, JOINT_INDEX[k.human_joint]] = data.site_xpos[sid]
    J = JOINT_INDEX
    mid_sh = 0.5 * (out[:, J["left_shoulder"]] + out[:, J["right_shoulder"]])
    for name, a in (("spine1", 0.25), ("spine2", 0.5), ("spine3", 0.75)):
        out[:, J[name]] = (1 - a) * out[:, J["pelvis"]] + a * mid_sh
    out[:, J["left_collar"]] = 0.5 * (out[:, J["neck"]] + out[:, J["left_shoulder"]])
    out[:, J["right_collar"]] = 0.5 * (out[:, J["neck"]] + out[:, J["right_shoulder"]])
    return out


def smooth_random_qpos(robot: RetargetRobot, T: int, rng, amplitude: float = 0.35) -> np.ndarray:
    """Random smooth joint trajectories inside the ranges, base floating 0.15 m above the standing height."""
    t = np.arange(T) / 20.0
    q = np.tile(robot.nominal_qpos, (T, 1))
    lo, hi = robot.joint_range[:, 0] + 0.05, robot.joint_range[:, 1] - 0.05
    for i, a in enumerate(robot.qpos_adr):
        f1, f2 = rng.uniform(0.2, 0.6, size=2)
        p1, p2 = rng.uniform(0, 2 * np.pi, size=2)
        v = robot.nominal_qpos[a] + amplitude * (0.6 * np.sin(2 * np.pi * f1 * t + p1) + 0.4 * np.sin(2 * np.pi * f2 * t + p2))
        q[:, a] = np.clip(v, lo[i], hi[i])
    yaw = 0.3 * np.sin(2 * np.pi * 0.15 * t) + 0.2
    pitch = 0.1 * np.sin(2 * np.pi * 0.2 * t)
    q[:, 0] = 0.2 * t
    q[:, 1] = 0.05 * np.sin(2 * np.pi * 0.1 * t)
    q[:, 2] = robot.nominal_qpos[2] + 0.15
    from retarget.problem import quat_from_euler_zyx

    q[:, 3:7] = quat_from_euler_zyx(np.stack([yaw, pitch, np.zeros(T)], axis=-1))
    return q


def synthetic_walk(T: int = 60, fps: float = 20.0, speed: float = 0.9, period: float = 1.1) -> np.ndarray:
    """A procedural human walk [T, 22, 3] (canonical adult, metres, z up, facing +x): each foot is planted
    for 60 % of the gait cycle and swings (0.08 m lift) for 40 %; knees by two-link IK."""
    rest = rest_pose()
    J = JOINT_INDEX
    t = np.arange(T) / fps
    pelvis_h = rest[J["pelvis"], 2] - 0.04
    out = np.zeros((T, 22, 3))
    stride = speed * period
    for side, phase0 in (("left", 0.0), ("right", 0.5)):
        ank0 = rest[J[f"{side}_ankle"]]
        toe_off = rest[J[f"{side}_foot"]] - ank0
        ph = ((t / period) + phase0) % 1.0
        cycle = np.floor((t / period) + phase0)
        # stance 0..0.6 planted at x = cycle * stride; swing 0.6..1 moves to the next step
        s = np.clip((ph - 0.6) / 0.4, 0, 1)
        blend = 0.5 - 0.5 * np.cos(np.pi * s)
        x = (cycle + blend) * stride - phase0 * stride
        z = ank0[2] + 0.08 * np.sin(np.pi * s)
        out[:, J[f"{side}_ankle"]] = np.stack([x, np.full(T, ank0[1]), z], axis=-1)
        out[:, J[f"{side}_foot"]] = out[:, J[f"{side}_ankle"]] + toe_off
    pelvis = np.stack([speed * t + 0.25 * stride, np.zeros(T), np.full(T, pelvis_h)], axis=-1)
    for j in range(22):
        name = JOINT_NAMES[j]
        if any(k in name for k in ("ankle", "foot", "knee")):
            continue
        out[:, j] = pelvis + (rest[j] - rest[J["pelvis"]])
    for side in ("left", "right"):
        sh = out[:, J[f"{side}_shoulder"]]
        out[:, J[f"{side}_elbow"]] = sh + [0.0, 0.0, -0.26]
        out[:, J[f"{side}_wrist"]] = sh + [0.05, 0.0, -0.5]
        hip, ank = out[:, J[f"{side}_hip"]], out[:, J[f"{side}_ankle"]]
        l1 = np.linalg.norm(rest[J[f"{side}_knee"]] - rest[J[f"{side}_hip"]])
        l2 = np.linalg.norm(rest[J[f"{side}_ankle"]] - rest[J[f"{side}_knee"]])
        d_vec = ank - hip
        d = np.minimum(np.linalg.norm(d_vec, axis=-1), 0.999 * (l1 + l2))
        u = d_vec / np.linalg.norm(d_vec, axis=-1, keepdims=True)
        f = np.array([1.0, 0, 0]) - (u @ np.array([1.0, 0, 0]))[:, None] * u
        f /= np.linalg.norm(f, axis=-1, keepdims=True)
        cos_a = np.clip((l1**2 + d**2 - l2**2) / (2 * l1 * d), -1, 1)
        out[:, J[f"{side}_knee"]] = hip + l1 * (cos_a[:, None] * u + np.sqrt(1 - cos_a**2)[:, None] * f)
    return out


SMALL = RetargetConfig(window=20, overlap=5)


def test_contacts_on_synthetic_walk_alternate():
    joints = synthetic_walk(T=80)
    c = detect_contacts(joints, 20.0)
    for s in range(2):
        phases = contact_phases(c[:, s])
        assert len(phases) >= 2
        # a detected contact is really a planted foot of the generator (ankle still)
        ank = joints[:, JOINT_INDEX[("left_ankle", "right_ankle")[s]]]
        for a, b in phases:
            assert np.abs(ank[a:b, :2] - ank[a, :2]).max() < 1e-9
    assert (c[:, 0] | c[:, 1]).all()  # walking: always at least one foot down


def test_contact_hysteresis_and_min_length():
    T = 40
    j = np.tile(rest_pose(), (T, 1, 1))
    la, lf = JOINT_INDEX["left_ankle"], JOINT_INDEX["left_foot"]
    # left foot lifted for frames 10..11 only (shorter than min_swing_frames=2? no: exactly 2 -> kept) and
    # a one-frame flicker at 25 (filled)
    j[10:12, [la, lf], 2] += 0.3
    j[25, [la, lf], 2] += 0.3
    cfg = ContactConfig(min_swing_frames=2, min_contact_frames=3, floor_height=0.0)
    c = detect_contacts(j, 20.0, cfg)
    assert not c[10:12, 0].any()
    assert c[25, 0]  # one-frame gap filled
    assert c[:, 1].all()


def _sliding_feet_clip(T: int = 30) -> np.ndarray:
    """Rest pose; left foot planted for frames 0-9, then both feet slide along the floor (near it
    but too fast to count as planted) with the right foot 1 cm lower in frames 10-19 and the left
    lower in 20-24, then both feet 30 cm up (a flight) in frames 25-29."""
    j = np.tile(rest_pose(), (T, 1, 1))
    feet = {s: [JOINT_INDEX[f"{s}_ankle"], JOINT_INDEX[f"{s}_foot"]] for s in ("left", "right")}
    j[:10, feet["right"], 2] += 0.3  # right swings while left stands
    for t in range(10, 25):
        for s in ("left", "right"):
            j[t, feet[s], 0] += 0.06 * (t - 9)  # 1.2 m/s: sliding
        lower = "right" if t < 20 else "left"
        j[t, feet["left" if lower == "right" else "right"], 2] += 0.01
    j[25:, :, 2] += 0.3
    return j


def test_fill_support_plants_the_lower_foot_where_none_is_planted():
    from retarget.contacts import fill_support

    j = _sliding_feet_clip()
    base = ContactConfig(floor_height=0.0)
    raw = detect_contacts(j, 20.0, base)
    assert raw[:9, 0].all() and not raw[10:].any()  # sliding and flying frames have no contact
    off = fill_support(raw, j, replace(base, support="off"))
    np.testing.assert_array_equal(off, raw)
    near = fill_support(raw, j, replace(base, support="near"))
    assert near[:10, 0].all() and not near[:10, 1].any()  # frame 9 extends the left foot's phase
    assert near[10:20, 1].all() and not near[10:20, 0].any()  # the lower (right) foot carries 10-19
    assert near[20:25, 0].all() and not near[20:25, 1].any()  # then the left
    assert not near[25:].any()  # a flight stays a flight
    always = fill_support(raw, j, replace(base, support="always"))
    assert always[25:].any(axis=1).all() and (always[25:].sum(axis=1) == 1).all()
    assert (always[:25] == near[:25]).all()
    with pytest.raises(InputError, match="contact support must be one of"):
        fill_support(raw, j, replace(base, support="sometimes"))


def test_fill_support_does_not_flicker_between_feet():
    """A foot that is lower for fewer than ``min_contact_frames`` frames does not get its own phase."""
    from retarget.contacts import fill_support

    j = _sliding_feet_clip()
    lf = [JOINT_INDEX["left_ankle"], JOINT_INDEX["left_foot"]]
    j[14, lf, 2] -= 0.02  # left briefly lower than right at frame 14
    cfg = ContactConfig(floor_height=0.0, min_contact_frames=3)
    filled = fill_support(detect_contacts(j, 20.0, cfg), j, cfg)
    assert filled[10:20, 1].all() and not filled[10:20, 0].any()


def test_double_support_delays_the_lift_off_of_the_old_foot():
    from retarget.contacts import ensure_double_support

    def mask(left: str, right: str) -> np.ndarray:
        return np.array([[a == "x", b == "x"] for a, b in zip(left, right)])

    #                left           right
    c = mask("xxxxx.......xxxx", "....xxxxxx......")
    out = ensure_double_support(c, 3, min_swing=2)
    # right touches down at 4 while left is planted: left stays until frame 6 (4 + 3 - 1)
    assert out[:, 0].tolist() == mask("xxxxxxx.....xxxx", "x" * 16)[:, 0].tolist()
    # left touches down at 12 but right lifted at 10 (no hand-over): right unchanged
    np.testing.assert_array_equal(out[:, 1], c[:, 1])
    # a short swing keeps min_swing frames: left's next contact at 8 allows planting up to 5 only
    c2 = mask("xxxxx...xxxx", "....xxxxxxxx")
    assert ensure_double_support(c2, 5, min_swing=2)[:, 0].tolist() == mask("xxxxxx..xxxx", "x" * 12)[:, 0].tolist()
    np.testing.assert_array_equal(ensure_double_support(c, 0), c)


def test_retargeting_plants_a_foot_where_the_human_slides(robot):
    """With ``support="near"`` (the default) the robot keeps a sole on the floor in the frames where
    both human feet slide; with ``"off"`` it lifts both (the validator's ``floating`` failure)."""
    from retarget.metrics import sole_points

    j = _sliding_feet_clip()[:25]  # no flight
    lowest = {}
    for mode in ("off", "near"):
        cfg = replace(SMALL, contacts=ContactConfig(floor_height=0.0, support=mode), collision=CollisionConfig(enabled=False))
        rt = Retargeter(robot, cfg)
        res = rt.run(j, 20.0, progress=False)
        assert res.success, res.solver_status()
        assert res.contacts[12:22].any(axis=1).all() == (mode == "near")
        _, corners = sole_points(rt.kin, res.x)
        lowest[mode] = corners[..., 2].min(axis=(1, 2))
    assert lowest["off"][12:22].min() > 0.005  # both soles up: floating
    assert np.abs(lowest["near"][12:22]).max() < 1e-3  # a sole on the floor


def test_scaled_contact_config_scales_only_the_body_size_thresholds():
    from dataclasses import fields

    from retarget.solve import scaled_contact_config

    child = rest_pose()[None] * 0.5  # half the canonical adult's size
    base = ContactConfig(min_contact_frames=5, min_swing_frames=4, floor_percentile=7.0, floor_height=0.01)
    scaled = scaled_contact_config(child, base)
    scaled_names = {"toe_height", "ankle_height", "enter_speed", "exit_speed"}
    for f in fields(ContactConfig):
        if f.name in scaled_names:
            assert getattr(scaled, f.name) == pytest.approx(0.5 * getattr(base, f.name))
        else:  # every other setting (also ones added later) passes through unchanged
            assert getattr(scaled, f.name) == getattr(base, f.name), f.name


def test_self_retarget_recovers_robot_motion(robot):
    rng = np.random.default_rng(3)
    T = 40
    qpos = smooth_random_qpos(robot, T, rng)
    human = sites_to_human(robot, qpos)
    cfg = replace(
        SMALL, scale=False,
        weights=CostWeights(heading=0.0, foot_yaw=0.0, nominal=1e-6, base_tilt=0.0, velocity=1e-5, acceleration=1e-5),
        contacts=ContactConfig(floor_height=0.0),
        solver=SolverConfig(tol=1e-8),
        min_foot_gap=None,  # the random robot motion brings the feet closer than the default gap
        collision=CollisionConfig(enabled=False),  # ... and its limbs closer than the collision margin
    )
    rt = Retargeter(robot, cfg)
    res = rt.run(human, 20.0, progress=False)
    assert res.success, res.solver_status()
    assert not res.contacts.any()
    assert res.keypoint_error.max() < 1e-3, res.keypoint_error.max()
    # the joints come back too (the keypoints determine them up to the 1 mm tolerance)
    assert np.abs(res.qpos[:, robot.qpos_adr] - qpos[:, robot.qpos_adr]).max() < 0.05


def test_synthetic_walk_contacts_hold_and_limits_respected(robot, small):
    human = synthetic_walk(T=60)
    rt = small
    res = rt.run(human, 20.0, progress=False)
    assert res.success, res.solver_status()
    assert res.contacts[:, 0].any() and res.contacts[:, 1].any()
    m = measure(rt.kin, res.x, res.contacts, res.keypoint_error, res.fps)
    assert m.contact_phases >= 4
    assert m.sole_drift_max <= 5e-3, m
    assert m.sole_min_height >= -1e-3, m
    assert m.joint_range_excess <= 1e-6, m
    assert m.velocity_ratio_max <= 1.0 + 1e-6, m
    # the result is a real tracking, not a standing robot: the pelvis follows the (scaled) walk
    adv = res.qpos[-1, 0] - res.qpos[0, 0]
    tgt = res.targets.joints[-1, 0, 0] - res.targets.joints[0, 0, 0]
    assert abs(adv - tgt) < 0.2 * abs(tgt)


def test_fast_motion_is_clamped_to_limits(robot):
    """A motion that asks for more than the joint ranges and velocity limits gets neither."""
    rng = np.random.default_rng(5)
    T = 30
    qpos = smooth_random_qpos(robot, T, rng, amplitude=1.5)
    qpos[:, robot.qpos_adr] += rng.normal(scale=0.5, size=(T, len(robot.qpos_adr)))  # jitter: > 6 rad/s
    human = sites_to_human(robot, qpos)
    cfg = replace(SMALL, scale=False, contacts=ContactConfig(floor_height=0.0))
    rt = Retargeter(robot, cfg)
    res = rt.run(human, 20.0, progress=False)
    m = measure(rt.kin, res.x, res.contacts, res.keypoint_error, res.fps)
    assert m.joint_range_excess <= 1e-6
    assert m.velocity_ratio_max <= 1.0 + 1e-6
    assert m.sole_min_height >= -1e-3


def test_per_frame_baseline_is_rougher_than_trajectory(robot, small):
    human = synthetic_walk(T=40)
    traj = small
    per_frame = Retargeter(robot, replace(SMALL, mode="per-frame"))
    a = traj.run(human, 20.0, progress=False)
    b = per_frame.run(human, 20.0, progress=False)
    assert len(b.windows) == 40 and all(w.stop - w.start == 1 for w in b.windows)
    ma = measure(traj.kin, a.x, a.contacts, a.keypoint_error, 20.0)
    mb = measure(per_frame.kin, b.x, b.contacts, b.keypoint_error, 20.0)
    assert b.success
    assert mb.sole_drift_max <= 5e-3 and mb.sole_min_height >= -1e-3
    assert ma.joint_acceleration_mean < mb.joint_acceleration_mean


def test_window_plan_covers_clip_with_overlap(robot):
    rt = Retargeter(robot, RetargetConfig(window=20, overlap=5))
    plan = rt.windows(47)
    assert plan[0] == (0, 20, 15) and plan[1] == (15, 35, 30) and plan[-1] == (27, 47, 47)
    assert Retargeter(robot, RetargetConfig(window=20, overlap=5)).windows(12) == [(0, 12, 12)]
    with pytest.raises(InputError, match="overlap"):
        Retargeter(robot, RetargetConfig(window=10, overlap=9))


def test_non_converged_window_names_the_violated_constraint(robot):
    human = synthetic_walk(T=20)
    cfg = replace(SMALL, solver=SolverConfig(max_iter=1))
    res = Retargeter(robot, cfg).run(human, 20.0, progress=False)
    assert not res.success
    w = res.failed_windows()[0]
    assert w.status == "Maximum_Iterations_Exceeded"
    assert w.violated is not None and w.violated.startswith("frame ")
    assert any(k in w.violated for k in ("sole", "velocity", "bound"))


def test_a_first_window_that_fails_from_the_presolve_is_solved_again_from_the_plain_start(robot, monkeypatch):
    """The presolve's chain can start the first window where IPOPT finds no way back to
    feasibility (a Bandai walk on the OP3 with its one-way elbows: every window of the clip then
    failed); the first window is then solved again from the nominal pose on the human root."""
    import dataclasses

    from retarget import problem as problem_module

    human = synthetic_walk(T=40)
    cfg = replace(SMALL, presolve_frames=5, collision=CollisionConfig(enabled=False))
    plain = Retargeter(robot, replace(cfg, presolve_frames=0)).run(human, 20.0, progress=False)
    starts = []
    original = problem_module.WindowProblem.solve

    def solve(self, x0, *args, **kwargs):
        sol = original(self, x0, *args, **kwargs)
        if self.W == cfg.window:
            starts.append(np.array(x0))
            if len(starts) == 1:  # the first full window, started from the presolve: make it fail
                return dataclasses.replace(sol, success=False, status="Infeasible_Problem_Detected")
        return sol

    monkeypatch.setattr(problem_module.WindowProblem, "solve", solve)
    res = Retargeter(robot, cfg).run(human, 20.0, progress=False)
    assert res.success
    assert len(starts) == len(res.windows) + 1  # the first window twice
    assert not np.allclose(starts[0], starts[1])  # the second time not from the presolve's guess
    np.testing.assert_allclose(res.qpos, plain.qpos, atol=1e-6)  # but as if there was no presolve


def test_a_first_window_far_from_its_targets_is_solved_again_and_the_lower_objective_kept(robot, monkeypatch):
    """IPOPT can also succeed from the presolve's guess into a bad local minimum (a generated kick
    on both OP3 models: the base pinned at its lowest bound, keypoints 27 cm from their targets):
    a first window with a keypoint farther than ``presolve_retry_per_leg`` leg lengths from its
    target is solved again from the plain start, and the solution with the lower objective kept."""
    import dataclasses

    from retarget import problem as problem_module

    human = synthetic_walk(T=40)
    cfg = replace(SMALL, presolve_frames=5, collision=CollisionConfig(enabled=False))
    plain = Retargeter(robot, replace(cfg, presolve_frames=0)).run(human, 20.0, progress=False)
    drop = 0.7 * Retargeter(robot, cfg).kin.leg_length  # beyond the retry bound of half a leg length
    original = problem_module.WindowProblem.solve
    objectives = []

    def solve(self, x0, *args, **kwargs):
        sol = original(self, x0, *args, **kwargs)
        if self.W == cfg.window and not objectives:  # the first full window from the presolve: a
            # "successful" solution with the base dropped and a higher objective
            x = np.array(sol.x)
            x[:, 2] -= drop
            sol = dataclasses.replace(sol, x=x, objective=sol.objective + 1e3)
        if self.W == cfg.window:
            objectives.append(sol.objective)
        return sol

    monkeypatch.setattr(problem_module.WindowProblem, "solve", solve)
    res = Retargeter(robot, cfg).run(human, 20.0, progress=False)
    assert len(objectives) == len(res.windows) + 1  # the first window twice
    np.testing.assert_allclose(res.qpos, plain.qpos, atol=1e-6)  # the plain start's solution kept
    objectives.clear()
    kept = Retargeter(robot, replace(cfg, presolve_retry_per_leg=10.0)).run(human, 20.0, progress=False)
    assert len(objectives) == len(kept.windows)  # within the bound: solved once, as it came
    assert kept.qpos[0, 2] == pytest.approx(plain.qpos[0, 2] - drop, abs=1e-3)


def test_bad_input_errors_name_the_problem(robot, small, tmp_path):
    rt = small
    j = synthetic_walk(T=10)
    j[4, JOINT_INDEX["left_knee"], 1] = np.nan
    with pytest.raises(InputError, match=r"frame 4.*left_knee"):
        rt.run(j, 20.0, progress=False)
    with pytest.raises(InputError, match="21 joints per frame, expected 22"):
        rt.run(np.zeros((10, 21, 3)), 20.0, progress=False)
    bad = tmp_path / "motion.npz"
    bad.write_bytes(b"this is not a zip file")
    with pytest.raises(InputError, match="motion.npz"):
        read_input(bad)
    with pytest.raises(InputError, match="not found"):
        read_input(tmp_path / "missing.npz")
    np.savez(tmp_path / "nojoints.npz", fps=20)
    with pytest.raises(InputError, match="no 'joints'"):
        read_input(tmp_path / "nojoints.npz")
    with pytest.raises(InputError, match="unknown input type"):
        read_input(tmp_path / "clip.xyz") if (tmp_path / "clip.xyz").write_text("x") else None
    (tmp_path / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0\n")
    with pytest.raises(InputError, match="broken.bvh"):
        read_input(tmp_path / "broken.bvh")


def test_unknown_robot_is_named():
    from retarget.robot_model import load_robot

    with pytest.raises(InputError, match="no_such_robot"):
        load_robot("no_such_robot")


def test_robot_npz_round_trip(robot, small, tmp_path):
    human = synthetic_walk(T=20)
    res = small.run(human, 20.0, progress=False)
    path = write_robot_npz(tmp_path / "robot.npz", res)
    back = read_robot_npz(path)
    assert back.qpos.shape == (20, robot.nq) and back.qpos.dtype == np.float64
    assert np.allclose(np.linalg.norm(back.qpos[:, 3:7], axis=1), 1.0)
    assert back.joint_names == robot.joint_names and back.robot == "toy" and back.fps == 20.0
    assert back.contacts.shape == (20, 2) and back.contacts.dtype == bool
    assert back.keypoint_error.shape == (20, len(robot.keypoints))
    assert back.keypoint_names == [k.human_joint for k in robot.keypoints]
    assert back.source.dtype == np.float32 and np.allclose(back.source, human, atol=1e-6)
    assert back.solver_status[0]["status"] and "violated" in back.solver_status[0]
    with np.load(path) as raw:  # plain arrays, readable without this package
        assert json.loads(str(raw["solver_status"]))[0]["start"] == 0


def test_plot_writes_png(robot, small, tmp_path):
    from retarget.plots import plot_result

    res = small.run(synthetic_walk(T=20), 20.0, progress=False)
    path = plot_result(tmp_path / "r.png", small.kin, res, baseline=res)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10000


def test_quaternion_output_matches_solver_orientation(robot, small):
    """qpos quaternions put the robot where the solver variables say (MuJoCo FK on the output)."""
    human = synthetic_walk(T=20)
    rt = small
    res = rt.run(human, 20.0, progress=False)
    data = mujoco.MjData(robot.model)
    sid = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, "l_hand")
    kp = np.array(rt.kin.frame.map(20)(res.x.T)[0]).reshape(3, -1, 20, order="F")
    k = [kk.site for kk in robot.keypoints].index("l_hand")
    for t in (0, 10, 19):
        data.qpos[:] = res.qpos[t]
        mujoco.mj_kinematics(robot.model, data)
        assert np.allclose(data.site_xpos[sid], kp[:, k, t], atol=1e-9)


def test_retarget_imports_no_torch():
    code = "import sys, retarget.solve, retarget.io, retarget.cli, retarget.metrics; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_cli_retarget_op3_like(tmp_path):
    robots = pytest.importorskip("motok_robot.robots")
    try:
        if "op3_like" not in robots.list_robots():
            pytest.skip("op3_like not present")
        robots.load("op3_like")
    except Exception as exc:
        pytest.skip(f"op3_like cannot be loaded: {exc}")
    from motok_robot.cli import main

    motion = tmp_path / "motion.npz"
    np.savez(motion, joints=synthetic_walk(T=30).astype(np.float32), fps=20)
    out = tmp_path / "robot.npz"
    rc = main(["retarget", str(motion), "--robot", "op3_like", "--out", str(out), "--window", "20", "--overlap", "5"])
    assert rc == 0 and out.exists()
    back = read_robot_npz(out)
    assert back.robot == "op3_like" and back.qpos.shape[0] == 30
    assert main(["retarget", str(motion), "--robot", "no_such_robot", "--out", str(tmp_path / "x.npz")]) == 2


def test_cli_fails_on_non_converged_window_unless_allowed(tmp_path, monkeypatch, capsys):
    robots = pytest.importorskip("motok_robot.robots")
    try:
        robots.load("op3_like")
    except Exception as exc:
        pytest.skip(f"op3_like cannot be loaded: {exc}")
    import retarget.config as config_module
    from motok_robot.cli import main

    starved = replace(RetargetConfig(), solver=SolverConfig(max_iter=1))
    monkeypatch.setattr(config_module, "RetargetConfig", lambda: starved)
    motion = tmp_path / "motion.npz"
    np.savez(motion, joints=synthetic_walk(T=20).astype(np.float32), fps=20)
    out = tmp_path / "robot.npz"
    args = ["retarget", str(motion), "--robot", "op3_like", "--out", str(out), "--window", "20", "--overlap", "5"]
    assert main(args) == 2 and not out.exists()
    err = capsys.readouterr().err
    assert "did not converge" in err and "Maximum_Iterations_Exceeded" in err and "violated: frame" in err
    assert main(args + ["--allow-partial"]) == 0 and out.exists()
    assert read_robot_npz(out).solver_status[0]["success"] is False


def test_soft_com_term_pulls_com_over_support(robot, small):
    human = synthetic_walk(T=40)
    with_com = Retargeter(robot, replace(SMALL, weights=replace(SMALL.weights, com=1000.0)))

    def com_offset(rt, res):
        out = rt.kin.frame.map(len(res.x))(res.x.T)
        com = np.array(out[4]).T[:, :2]
        soles = np.array(out[1]).reshape(3, 2, -1, order="F").transpose(2, 1, 0)[..., :2]
        m = res.contacts.astype(float)
        keep = m.sum(1) > 0
        centre = (m[:, :, None] * soles).sum(1)[keep] / m.sum(1)[keep, None]
        return np.linalg.norm(com[keep] - centre, axis=1).mean()

    a = small.run(human, 20.0, progress=False)
    b = with_com.run(human, 20.0, progress=False)
    assert b.success
    assert com_offset(with_com, b) < 0.8 * com_offset(small, a)


def test_bvh_mocap_input_is_imported_and_retargeted(robot, small, tmp_path):
    fixtures = pytest.importorskip("test_data_fixtures")  # the data stage's BVH writer
    path = tmp_path / "walk.bvh"
    names = {k: v for k, v in fixtures.BANDAI_NAMES.items()}
    path.write_text(fixtures.canonical_bvh_text(frames=45, fps=30.0, names=names, skip=("spine3",)))
    motion = read_input(path, skeleton="bandai")
    assert motion.joints.shape == (30, 22, 3) and motion.fps == 20.0
    res = small.run(motion.joints, motion.fps, progress=False)
    assert res.success and res.qpos.shape == (30, robot.nq)


def _spin_on_the_left_foot(T: int = 40, turn_deg: float = 150.0, frames: int = 12) -> np.ndarray:
    """The human rest pose with the right foot lifted 0.15 m, turning ``turn_deg`` about the
    vertical through the left ankle over ``frames`` frames (from frame 10): the stance foot
    pivots in place, as in a spinning kick."""
    J = JOINT_INDEX
    rest = rest_pose()
    for name in ("right_ankle", "right_foot"):
        rest[J[name], 2] += 0.15
    rest[J["right_knee"]] += [0.08, 0.0, 0.08]
    axis = rest[J["left_ankle"]].copy()
    yaw = np.radians(turn_deg) * np.clip((np.arange(T) - 10) / frames, 0.0, 1.0)
    out = np.zeros((T, 22, 3))
    rel = rest - [axis[0], axis[1], 0.0]
    for t in range(T):
        c, s = np.cos(yaw[t]), np.sin(yaw[t])
        out[t] = np.c_[axis[0] + c * rel[:, 0] - s * rel[:, 1], axis[1] + s * rel[:, 0] + c * rel[:, 1], rel[:, 2]]
    return out


def _sole_yaws(robot: RetargetRobot, qpos: np.ndarray) -> np.ndarray:
    """[T, 2] unwrapped yaw (deg) of each sole's corner 0 -> 1 edge."""
    data = mujoco.MjData(robot.model)
    ids = [[mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, robot.soles[side].corner_sites[i]) for i in (0, 1)]
           for side in ("left", "right")]
    out = np.zeros((len(qpos), 2))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(robot.model, data)
        for k, (a, b) in enumerate(ids):
            e = data.site_xpos[b] - data.site_xpos[a]
            out[t, k] = np.arctan2(e[1], e[0])
    return np.degrees(np.unwrap(out, axis=0))


def _base_yaw(qpos: np.ndarray) -> np.ndarray:
    """[T] unwrapped yaw (deg) of the base quaternions of ``qpos`` [T, nq]."""
    q = qpos[:, 3:7]
    return np.degrees(np.unwrap(np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]), 1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))))


def test_a_planted_foot_pivots_only_where_the_human_foot_turns_fast_and_far():
    from retarget.solve import pivot_allowance

    fps = 20.0
    # planted throughout: still, a 150-degree turn at 600 deg/s, still, 10 degrees at 40 deg/s
    angle = np.radians(np.r_[np.zeros(5), np.linspace(0, 150, 6), np.full(5, 150.0), 150 + np.linspace(0, 10, 6)])
    foot_dir = np.stack([np.cos(angle), np.sin(angle)], axis=-1)[:, None].repeat(2, axis=1)
    planted = np.ones((len(angle), 2), dtype=bool)
    pivot = pivot_allowance(foot_dir, fps, planted, speed_deg=120.0, min_turn_deg=120.0, margin=1.5)
    assert pivot.shape == (len(angle), 2)
    np.testing.assert_allclose(np.degrees(pivot[6:11, 0]), 1.5 * 30.0, atol=1e-6)
    assert not pivot[:6].any() and not pivot[11:].any()
    # the same fast turn split over two contact phases of 75 degrees each (a walk's heel strike
    # and toe-off swing the foot's direction quickly, but not far): held
    split = planted.copy()
    split[8] = False
    assert not pivot_allowance(foot_dir, fps, split, speed_deg=120.0, min_turn_deg=120.0, margin=1.5).any()


def test_a_stance_foot_pivots_with_a_spinning_human_and_never_flips(robot):
    human = _spin_on_the_left_foot()
    held = Retargeter(robot, replace(SMALL, contacts=replace(SMALL.contacts, pivot_speed_deg=1e6))).run(
        human, 20.0, progress=False)
    res = Retargeter(robot, SMALL).run(human, 20.0, progress=False)
    assert res.success, res.solver_status()
    assert res.contacts[:, 0].all()  # the left foot stays planted throughout
    # the pivoting sole turns with the human (150 degrees) about its sole site
    yaws = _sole_yaws(robot, res.qpos)[:, 0]
    assert yaws[-1] - yaws[0] > 120, yaws[-1] - yaws[0]
    # held, the sole cannot follow: the solve fails on the flip it would need (half a turn round
    # keeps the sole's edge parallel, which the yaw-slip row alone allowed), and says so (the
    # human turns 12.5 degrees a frame, too slowly for the bound on the base's turn to apply)
    assert not held.success
    assert any("sole yaw flip" in (w.violated or "") for w in held.windows)
    data = mujoco.MjData(robot.model)
    site = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, robot.soles["left"].site)
    centre = []
    for q in res.qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(robot.model, data)
        centre.append(data.site_xpos[site, :2].copy())
    assert np.linalg.norm(np.asarray(centre) - centre[0], axis=1).max() < 1e-3  # it turns about its sole site
    # neither the sole nor the base turns more than 45 degrees between two frames (a sole
    # flipped half a turn round also keeps its edge parallel)
    assert np.abs(np.diff(yaws)).max() < 45
    base_yaw = _base_yaw(res.qpos)
    assert np.abs(np.diff(base_yaw)).max() < 45
    assert abs(base_yaw[-1] - base_yaw[0] - 150) < 25  # the robot faces where the human ends up facing


def test_the_base_turns_no_faster_than_its_bound_between_frames(robot):
    human = _spin_on_the_left_foot()  # 150 degrees in 12 frames: 12.5 degrees a frame at 20 fps
    # 8 degrees a frame; the human's 12.5 is more than half that, so the windows of the spin get the row
    slow = replace(SMALL, solver=replace(SMALL.solver, max_base_turn_speed_deg=160.0))
    bounded = Retargeter(robot, slow)
    res = bounded.run(human, 20.0, progress=False)
    assert res.success, res.solver_status()
    with_row = [p for (_, _, turn), p in bounded._problems.items() if turn]
    assert with_row and all("base yaw turn" in p._names for p in with_row)
    assert np.abs(np.diff(_base_yaw(res.qpos))).max() <= 8.0 + 0.05
    unbounded = Retargeter(robot, SMALL)
    free = unbounded.run(human, 20.0, progress=False)  # 36 degrees a frame: no row here
    assert not any(turn for _, _, turn in unbounded._problems)  # the problems of the walks, unchanged
    assert np.abs(np.diff(_base_yaw(free.qpos))).max() > 9.0
    assert abs(_base_yaw(res.qpos)[-1] - _base_yaw(free.qpos)[-1]) < 10  # both end facing where the human does
