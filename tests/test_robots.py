"""Robot models (models/mjcf) and their descriptions: compile, maps, ranges, standing, bad files."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.motion import skeleton as sk
from motok_robot.robots import DEFAULT_ROBOT, MODELS_ENV, list_robots, load, models_dir

ROBOTS = ("op3_like", "humanoid25")
OP3_TOML = models_dir() / "op3_like.toml"


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    return load(request.param)


@pytest.fixture(scope="module")
def op3():
    return load("op3_like")


def names(model, obj, count):
    return {mujoco.mj_id2name(model, obj, i) for i in range(count)}


def test_both_robots_are_listed():
    assert set(ROBOTS) <= set(list_robots())
    assert DEFAULT_ROBOT == "op3" and load(DEFAULT_ROBOT).servos  # the system-identified ROBOTIS OP3 (issue 44)


def test_compiles_and_steps_without_warnings(robot):
    messages = []
    mujoco.set_mju_user_warning(messages.append)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            model = mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
        data = mujoco.MjData(model)
        data.qpos[:] = robot.nominal_qpos()
        data.ctrl[:] = robot.ctrl_from_qpos(data.qpos)
        for _ in range(200):
            mujoco.mj_step(model, data)
    finally:
        mujoco.set_mju_user_warning(None)
    assert messages == []
    assert data.warning.number.sum() == 0, {mujoco.mjtWarning(i).name: n for i, n in enumerate(data.warning.number) if n}
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert 0.002 <= model.opt.timestep <= 0.005


def test_contract_arrays(robot):
    m = robot.model
    nj = robot.nj
    assert m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE and m.nq == 7 + nj and m.nv == 6 + nj
    assert robot.qpos_adr.tolist() == list(range(7, 7 + nj))  # qpos order, free joint excluded
    assert robot.dof_adr.tolist() == list(range(6, 6 + nj))
    assert robot.joint_range.shape == (nj, 2) and np.all(robot.joint_range[:, 0] < robot.joint_range[:, 1])
    assert robot.velocity_limit.shape == (nj,) and np.all(robot.velocity_limit > 0)
    assert robot.torque_limit.shape == (nj,) and np.all(robot.torque_limit > 0)
    assert sorted(robot.actuator_joint.tolist()) == list(range(nj))  # one actuator per joint
    for i, name in enumerate(robot.joint_names):
        np.testing.assert_allclose(robot.joint_range[i], m.joint(name).range)


def test_every_mapped_site_body_and_joint_exists(robot):
    m = robot.model
    sites = names(m, mujoco.mjtObj.mjOBJ_SITE, m.nsite)
    bodies = names(m, mujoco.mjtObj.mjOBJ_BODY, m.nbody)
    joints = set(robot.joint_names)
    assert {k.human_joint for k in robot.keypoints} <= set(sk.JOINT_NAMES)
    for k in robot.keypoints:
        assert k.site in sites, k
    # the retargeting keypoints the issue asks for are all there
    required = {"pelvis", "neck", "head"} | {f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle", "foot", "shoulder", "elbow", "wrist")}
    assert required <= {k.human_joint for k in robot.keypoints}
    assert set(robot.soles) == {"left", "right"}
    for sole in robot.soles.values():
        assert sole.body in bodies
        assert {sole.site, *sole.corner_sites} <= sites
    assert robot.torso_body in bodies
    assert set(robot.description.nominal_pose) <= joints
    assert {s.joint for s in robot.servos} <= joints
    assert set(robot.limb_scale) == {"legs", "arms", "torso", "head"}


def test_servo_robot_has_one_servo_per_actuated_joint(op3):
    assert op3.nj == 20
    joints = [s.joint for s in op3.servos]
    assert sorted(joints) == sorted(op3.joint_names)  # exactly one entry per joint
    assert sorted(s.id for s in op3.servos) == list(range(1, 21))
    assert {s.model for s in op3.servos} == {"XM430-W350"}
    assert all(s.ticks_per_rev == 4096 and s.velocity_limit == pytest.approx(4.8) for s in op3.servos)
    np.testing.assert_allclose(op3.torque_limit, 4.1)
    np.testing.assert_allclose(op3.velocity_limit, 4.8)
    assert op3.bus.protocol == 2.0 and op3.bus.baud == 2_000_000 and op3.bus.control_hz == 125
    # 125 Hz control is a whole number of physics steps
    steps = 1.0 / (op3.bus.control_hz * op3.model.opt.timestep)
    assert steps == pytest.approx(round(steps))


def test_servo_ticks_agree_with_mjcf_joint_ranges(op3):
    for s in op3.servos:
        lo, hi = op3.joint_range[op3.joint_index(s.joint)]
        tick_lo, tick_hi = sorted((s.ticks_from_angle(lo), s.ticks_from_angle(hi)))
        # the servo limits are the joint range, rounded outwards to whole ticks
        assert s.min_ticks <= tick_lo + 1e-6 and tick_lo - s.min_ticks < 1.0, s
        assert s.max_ticks >= tick_hi - 1e-6 and s.max_ticks - tick_hi < 1.0, s
        assert 0 <= s.min_ticks < s.max_ticks <= 4095
        # conversion round trip
        assert s.angle_from_ticks(s.ticks_from_angle(0.3)) == pytest.approx(0.3)
        assert s.angle_from_ticks(s.zero_offset_ticks) == 0.0


def test_mirrored_servos_turn_the_other_way(op3):
    for s in op3.servos:
        if s.joint.startswith("l_"):
            twin = op3.description.servo_for("r_" + s.joint[2:])
            assert twin is not None and twin.id == s.id - 1  # OP numbering: right is odd, left even
            pitch = any(k in s.joint for k in ("pitch", "_el", "knee"))
            assert twin.sign == (-s.sign if pitch else s.sign), s.joint


def test_mass_and_height_in_documented_ranges(robot):
    lo, hi = robot.description.mass_range
    assert lo <= robot.total_mass() <= hi
    lo, hi = robot.description.height_range
    assert lo <= robot.height() <= hi


def test_issue_sizes():
    op3, h25 = load("op3_like"), load("humanoid25")
    assert 3.2 <= op3.total_mass() <= 3.5 and 0.48 <= op3.height() <= 0.53
    m = op3.model
    d = mujoco.MjData(m)
    d.qpos[:] = op3.qpos_from_joints(np.zeros(op3.nj))
    mujoco.mj_kinematics(m, d)
    dist = lambda a, b: float(np.linalg.norm(d.site(a).xpos - d.site(b).xpos))  # noqa: E731
    assert dist("l_hip", "l_knee") == pytest.approx(0.110, abs=0.005)
    assert dist("l_knee", "l_ankle") == pytest.approx(0.110, abs=0.005)
    assert dist("l_shoulder", "l_elbow") == pytest.approx(0.090, abs=0.005)
    assert op3.soles["left"].half_size == pytest.approx((0.06, 0.035))
    assert 1.6 <= h25.height() <= 1.8 and 23 <= h25.nj <= 27 and h25.servos == []
    assert {"waist_yaw", "waist_pitch"} <= set(h25.joint_names)


def test_limb_scale_hints_match_the_model(robot):
    """limb_scale = robot limb length / canonical human limb length, measured at the zero pose."""
    m = robot.model
    d = mujoco.MjData(m)
    d.qpos[:] = robot.qpos_from_joints(np.zeros(robot.nj))
    mujoco.mj_kinematics(m, d)
    site = {k.human_joint: d.site(k.site).xpos.copy() for k in robot.keypoints}
    rest = sk.rest_pose()
    human = {n: rest[sk.JOINT_INDEX[n]] for n in sk.JOINT_NAMES}

    def length(p, chain):
        return sum(np.linalg.norm(p[b] - p[a]) for a, b in zip(chain, chain[1:]))

    chains = {
        "legs": ("left_hip", "left_knee", "left_ankle"),
        "arms": ("left_shoulder", "left_elbow", "left_wrist"),
        "torso": ("pelvis", "neck"),
        "head": ("neck", "head"),
    }
    for limb, chain in chains.items():
        measured = length(site, chain) / length(human, chain)
        assert robot.limb_scale[limb] == pytest.approx(measured, rel=0.03), limb


def test_keypoints_are_left_right_symmetric(robot):
    m = robot.model
    d = mujoco.MjData(m)
    d.qpos[:] = robot.nominal_qpos()
    mujoco.mj_kinematics(m, d)
    pos = {k.human_joint: d.site(k.site).xpos.copy() for k in robot.keypoints}
    for name, p in pos.items():
        if name.startswith("left_"):
            q = pos["right_" + name[5:]]
            np.testing.assert_allclose(p * [1, -1, 1], q, atol=1e-9, err_msg=name)


def test_nominal_qpos_puts_flat_soles_on_the_floor(robot):
    q = robot.nominal_qpos()
    assert q.shape == (robot.nq,)
    np.testing.assert_allclose(q[3:7], [1, 0, 0, 0])
    m = robot.model
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    corners = [d.site(s).xpos[2] for sole in robot.soles.values() for s in sole.corner_sites]
    np.testing.assert_allclose(corners, 0.0, atol=1e-9)  # flat and resting, not floating
    for sole in robot.soles.values():
        assert d.site(sole.site).xpos[2] == pytest.approx(0.0, abs=1e-9)
    lo, hi = robot.joint_range.T
    j = q[robot.qpos_adr]
    assert np.all((lo <= j) & (j <= hi))
    knees = [robot.joint_index(n) for n in ("l_knee", "r_knee")]
    assert np.all(j[knees] > 0.2)  # knees slightly bent
    # the only contacts in the nominal pose are soles on the floor
    floor = m.geom("floor").id
    foot_bodies = {m.body(s.body).id for s in robot.soles.values()}
    for c in d.contact[: d.ncon]:
        assert floor in (c.geom1, c.geom2)
        other = c.geom2 if c.geom1 == floor else c.geom1
        assert m.geom_bodyid[other] in foot_bodies


def _self_contacts(robot, joints: dict[str, float]) -> set[tuple[str, str]]:
    m = robot.model
    d = mujoco.MjData(m)
    q = robot.nominal_qpos()
    for n, v in joints.items():
        q[robot.qpos_adr[robot.joint_index(n)]] = v
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    pairs = set()
    for c in d.contact[: d.ncon]:
        b1, b2 = m.body(m.geom_bodyid[c.geom1]).name, m.body(m.geom_bodyid[c.geom2]).name
        if "world" not in (b1, b2):
            pairs.add(tuple(sorted((b1, b2))))
    return pairs


def test_self_collisions_are_detectable(robot):
    # arm raised forward: free; arm swung across the chest: touches the torso; legs crossed: touch
    assert _self_contacts(robot, {"l_sho_pitch": -1.57}) == set()
    arm = _self_contacts(robot, {"l_sho_pitch": -1.5, "l_sho_roll": -1.0})
    assert any(robot.torso_body in p for p in arm), arm
    legs = _self_contacts(robot, {"l_hip_roll": -0.4, "r_hip_roll": 0.4})
    assert any(a.startswith("l_") and b.startswith("r_") for a, b in legs), legs


def test_head_clears_the_torso_over_its_whole_range(robot):
    """The neck joint ranges are what the links allow: no head/torso contact anywhere in them."""
    m = robot.model
    d = mujoco.MjData(m)
    pan, tilt = ("head_pan", "head_tilt") if "head_pan" in robot.joint_names else ("neck_yaw", "neck_pitch")
    head = [g for g in range(m.ngeom) if m.body(m.geom_bodyid[g]).name == "head" and m.geom_contype[g]]
    trunk = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body(robot.torso_body).id and m.geom_contype[g]]
    closest = np.inf
    for a in np.linspace(*robot.joint_range[robot.joint_index(pan)], 5):
        for b in np.linspace(*robot.joint_range[robot.joint_index(tilt)], 9):
            q = robot.nominal_qpos()
            q[robot.qpos_adr[robot.joint_index(pan)]] = a
            q[robot.qpos_adr[robot.joint_index(tilt)]] = b
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            for g1 in head:
                for g2 in trunk:
                    closest = min(closest, mujoco.mj_geomDistance(m, d, g1, g2, 0.05, None))
    assert 0.0 < closest < 0.05  # clear, but not by a wide margin (the range is not too timid)


def test_stands_for_10_seconds_under_its_own_actuators(robot):
    m = robot.model
    d = mujoco.MjData(m)
    d.qpos[:] = robot.nominal_qpos()
    d.ctrl[:] = robot.ctrl_from_qpos(d.qpos)
    mujoco.mj_forward(m, d)
    torso = m.body(robot.torso_body).id
    z0 = d.xpos[torso, 2]
    steps = int(round(10.0 / m.opt.timestep))
    heights = np.empty(steps)
    for i in range(steps):
        mujoco.mj_step(m, d)
        heights[i] = d.xpos[torso, 2]
    assert np.abs(heights - z0).max() < 0.02
    up = d.xmat[torso].reshape(3, 3)[:, 2]
    assert up[2] > math.cos(math.radians(10))  # still upright
    assert d.warning.number.sum() == 0


# ------------------------------------------------------------------------------------------
# malformed descriptions


def _write_bad(tmp_path: Path, edit) -> Path:
    text = OP3_TOML.read_text()
    text = re.sub(r'^mjcf = ".*"$', f'mjcf = "{(models_dir() / "op3_like.xml").as_posix()}"', text, flags=re.M)
    bad = edit(text)
    assert bad != text, "the edit did not change the file"
    path = tmp_path / "bad_robot.toml"
    path.write_text(bad)
    return path


def _sub(old, new):
    def edit(text):
        assert old in text, old
        return text.replace(old, new, 1)

    return edit


def _drop_bus(text):
    """Remove the whole ``[bus]`` section: the table and its sub-tables (``[bus.imu]``, ...), up to the
    next table that is not part of it; the comment lines just above each removed header go too."""
    out, skipping = [], False
    for line in text.splitlines(keepends=True):
        header = re.match(r"\s*\[([^\]]+)\]", line)
        if header:
            skipping = header.group(1).strip() == "bus" or header.group(1).strip().startswith("bus.")
            if skipping:
                while out and out[-1].lstrip().startswith("#"):
                    out.pop()
        if not skipping:
            out.append(line)
    result = "".join(out)
    assert "[bus" not in result and "[bus]" in text
    return result


def _retarget_ranges(line):
    def edit(text):
        return text + f"\n[retarget_ranges]\n{line}\n"

    return edit


def test_the_copy_itself_loads(tmp_path):
    path = _write_bad(tmp_path, _sub('summary = "', 'summary = "copy of '))
    assert load(path).nj == 20


@pytest.mark.parametrize(
    "edit, pattern",
    [
        (_sub('left_knee = { site = "l_knee"', 'left_knee = { site = "l_kneecap"'), r"\[keypoints\.left_knee\] unknown site 'l_kneecap'"),
        (_sub('"l_sole_fl", "l_sole_fr"', '"l_sole_fl", "l_sole_front"'), r"\[soles\.left\] unknown site 'l_sole_front'"),
        (_sub("r_knee = { id = 13,", "r_knee = { id = 14,"), r"\[servos\.l_knee\] duplicate servo id 14: already used by \[servos\.r_knee\]"),
        (_sub("min_ticks = 2048, max_ticks = 3613", "min_ticks = 2048, max_ticks = 3000"), r"\[servos\.l_knee\] servo ticks 2048\.\.3000 .* does not cover the joint range"),
        (_sub("min_ticks = 1265, max_ticks = 2831 }\nr_ank_roll", "min_ticks = 1265, max_ticks = 4200 }\nr_ank_roll"), r"\[servos\.l_ank_pitch\] max_ticks 4200 outside the servo's 0\.\.4095 ticks"),
        (_sub("head_tilt = { id = 20, sign = 1,", "head_tilt = { id = 20, sign = 2,"), r"\[servos\.head_tilt\] sign must be 1 or -1"),
        (_sub("head_pan = { id = 19, sign = 1, zero_offset_ticks = 2048,", "head_pan = { id = 19, sign = 1,"), r"\[servos\.head_pan\] missing field 'zero_offset_ticks'"),
        (_sub("l_knee = { id = 14,", "l_kneee = { id = 14,"), r"\[servos\.l_kneee\] unknown joint 'l_kneee'"),
        (_sub("head_tilt = { id = 20, sign = 1, zero_offset_ticks = 2048, min_ticks = 1591, max_ticks = 2440 }\n", ""), r"\[servos\] no servo for actuated joint\(s\) head_tilt"),
        (_sub("l_knee = 0.6", "l_knee = 2.9"), r"\[nominal_pose\.l_knee\] 2\.9 rad outside the joint range"),
        (_sub("left_knee = {", "left_kneee = {"), r"\[keypoints\.left_kneee\] 'left_kneee' is not a canonical human joint"),
        (_sub("torso_body = \"torso\"\n", ""), r"missing field 'torso_body'"),
        (_drop_bus, r"servos are listed but there is no \[bus\] table"),
        (_sub("[soles.right]", "[soles.rite]"), r"\[soles\] missing table 'right'"),
        (_sub("half_size = [0.06, 0.035]", "half_size = [0.06]"), r"\[soles\.left\] field 'half_size' must be a list of 2 numbers"),
        (_sub("name = \"op3_like\"", "name = \"op3_like"), r"not valid TOML"),
        (_retarget_ranges("l_elbo = [0.0, 1.0]"), r"\[retarget_ranges\.l_elbo\] unknown joint 'l_elbo'"),
        (_retarget_ranges("l_knee = [-1.0, 1.0]"), r"\[retarget_ranges\.l_knee\] \[-1, 1\] rad reaches outside the joint range"),
        (_retarget_ranges("l_knee = [1.0, 0.5]"), r"\[retarget_ranges\.l_knee\] needs low < high"),
        (_retarget_ranges("l_knee = [1.0, 1.5]"), r"\[retarget_ranges\.l_knee\] .* leaves out the nominal pose's 0\.6 rad"),
        (_retarget_ranges("l_knee = [1.0]"), r"\[retarget_ranges\] field 'l_knee' must be a list of 2 numbers"),
    ],
    ids=[
        "unknown-keypoint-site",
        "unknown-sole-site",
        "duplicate-servo-id",
        "ticks-do-not-cover-range",
        "ticks-outside-servo",
        "bad-sign",
        "missing-servo-field",
        "servo-unknown-joint",
        "joint-without-servo",
        "nominal-outside-range",
        "not-a-human-joint",
        "missing-field",
        "servos-without-bus",
        "missing-sole",
        "bad-half-size",
        "bad-toml",
        "retarget-range-unknown-joint",
        "retarget-range-outside-joint-range",
        "retarget-range-empty",
        "retarget-range-without-nominal",
        "retarget-range-not-a-pair",
    ],
)
def test_malformed_description_names_the_entry(tmp_path, edit, pattern):
    path = _write_bad(tmp_path, edit)
    with pytest.raises(InputError) as info:
        load(path)
    message = str(info.value)
    assert message.startswith("bad_robot.toml: "), message
    assert re.search(pattern, message), message


def test_unknown_robot_lists_the_known_ones():
    with pytest.raises(InputError, match=r"unknown robot 'nao'; known robots: .*humanoid25.*op3_like"):
        load("nao")


def test_broken_mjcf_is_an_input_error(tmp_path):
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><body><geom type='box'/></worldbody></mujoco>")
    (tmp_path / "broken.toml").write_text(OP3_TOML.read_text().replace('mjcf = "op3_like.xml"', 'mjcf = "broken.xml"'))
    with pytest.raises(InputError, match=r"broken\.xml: MuJoCo cannot compile it"):
        load(tmp_path / "broken.toml")


def test_models_folder_override(tmp_path, monkeypatch):
    (tmp_path / "mjcf").mkdir()
    for suffix in (".xml", ".toml"):
        src = models_dir() / f"op3_like{suffix}"
        (tmp_path / "mjcf" / f"mybot{suffix}").write_text(src.read_text().replace('mjcf = "op3_like.xml"', 'mjcf = "mybot.xml"'))
    monkeypatch.setenv(MODELS_ENV, str(tmp_path))
    assert list_robots() == ["mybot"]
    assert load("mybot").nj == 20
    with pytest.raises(InputError, match="known robots: mybot"):
        load("op3_like")
