"""benchmarks/_gmr_quality.py (the measures of bench_gmr.py) and the GMR driver's bone-axis table,
on a tiny MJCF built here: no ../shared, no GMR."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import _gmr_driver as driver  # noqa: E402
import _gmr_quality as Q  # noqa: E402

# a floating torso with two legs (hip hinge about y, knee hinge about y), a box foot on each, and an
# arm hanging beside the torso that can swing (about x) inwards into the left thigh; a floor plane
XML = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="torso" pos="0 0 0.5">
      <freejoint name="root"/>
      <geom name="torso" type="box" size="0.05 0.1 0.05" pos="0 0 0.05"/>
      <body name="left_thigh" pos="0 0.06 0">
        <joint name="left_hip" type="hinge" axis="0 1 0" range="-1 1"/>
        <geom name="left_thigh" type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
        <body name="left_shin" pos="0 0 -0.22">
          <joint name="left_knee" type="hinge" axis="0 1 0" range="0 2"/>
          <geom name="left_shin" type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
          <body name="left_foot" pos="0 0 -0.25">
            <geom name="left_foot" type="box" size="0.05 0.02 0.01" pos="0.02 0 0"/>
          </body>
        </body>
      </body>
      <body name="right_thigh" pos="0 -0.06 0">
        <joint name="right_hip" type="hinge" axis="0 1 0" range="-1 1"/>
        <geom name="right_thigh" type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
        <body name="right_shin" pos="0 0 -0.22">
          <joint name="right_knee" type="hinge" axis="0 1 0" range="0 2"/>
          <geom name="right_shin" type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
          <body name="right_foot" pos="0 0 -0.25">
            <geom name="right_foot" type="box" size="0.05 0.02 0.01" pos="0.02 0 0"/>
          </body>
        </body>
      </body>
      <body name="left_arm" pos="0 0.16 -0.02">
        <joint name="left_shoulder" type="hinge" axis="1 0 0" range="-1.5 1.5"/>
        <geom name="left_arm" type="capsule" fromto="0 0 0 0 0 -0.25" size="0.02"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
# the free base height that puts the foot boxes' bottoms exactly on the floor: torso at 0.5, hips 0,
# knee at -0.22, foot body at -0.47, box half-height 0.01 -> bottom at 0.5 - 0.48 = 0.02 above z=0
STAND_Z = 0.48


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(XML)


def _standing(model, T: int) -> np.ndarray:
    q = np.tile(model.qpos0, (T, 1)).astype(np.float64)
    q[:, 2] = STAND_Z
    return q


def _spec(**kw) -> Q.MeasureSpec:
    return Q.MeasureSpec(feet={"left": "left_foot", "right": "right_foot"}, **kw)


def test_standing_still_is_clean(model):
    q = _standing(model, 10)
    m = Q.measure(model, q, 20.0, _spec())
    assert m["frames"] == 10 and m["seconds"] == pytest.approx(0.5)
    assert m["below_floor_frames"] == 0
    assert m["lowest_point_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["foot_contact_fraction"] == 1.0
    assert m["foot_slip_total_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["joint_limit_frames"] == 0 and m["self_collision_frames"] == 0
    assert m["base_turn_max_deg"] == pytest.approx(0.0, abs=1e-6)


def test_geom_pushed_below_floor_is_counted(model):
    q = _standing(model, 10)
    q[3:5, 2] -= 0.015  # 1.5 cm into the floor: counted
    q[7, 2] -= 0.005  # 5 mm: within the 1 cm tolerance
    m = Q.measure(model, q, 20.0, _spec())
    assert m["below_floor_frames"] == 2
    assert m["lowest_point_m"] == pytest.approx(-0.015, abs=1e-9)


def test_lowest_point_of_each_geom_type():
    xml = """<mujoco><compiler angle="degree"/><asset><mesh name="tet" vertex="0 0 0  0.1 0 0  0 0.1 0  0 0 0.1"/></asset><worldbody>
      <body name="b"><freejoint/>
        <geom name="s" type="sphere" size="0.1" pos="0 0 1"/>
        <geom name="c" type="capsule" size="0.05 0.2" pos="0 0 2" euler="0 90 0"/>
        <geom name="y" type="cylinder" size="0.05 0.2" pos="0 0 3"/>
        <geom name="x" type="box" size="0.1 0.2 0.3" pos="0 0 4" euler="0 0 45"/>
        <geom name="e" type="ellipsoid" size="0.1 0.2 0.3" pos="0 0 5"/>
        <geom name="m" type="mesh" mesh="tet" pos="0 0 6"/>
      </body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    z = Q.LowestPoint(m, range(m.ngeom))(d)
    # MuJoCo re-centres the mesh and moves the geom frame with it: the tetrahedron's lowest vertex
    # (its origin) stays at the body's z = 6
    np.testing.assert_allclose(z, [0.9, 1.95, 2.8, 3.7, 4.7, 6.0], atol=1e-9)


def test_sliding_foot_slip_is_measured(model):
    q = _standing(model, 11)
    q[:, 0] = np.linspace(0.0, 0.10, 11)  # the whole robot slides 10 cm forward, feet on the floor
    m = Q.measure(model, q, 10.0, _spec())
    assert m["foot_slip_total_m"] == pytest.approx(0.20, abs=1e-9)  # both feet, 10 cm each
    assert m["foot_slip_worst_frame_m"] == pytest.approx(0.01, abs=1e-9)
    assert m["foot_slip_speed_m_s"] == pytest.approx(0.10, abs=1e-9)
    # lifted 3 cm the feet are not in contact: no floor-based slip, but the human stance still sees it
    q[:, 2] += 0.03
    stance = np.ones((11, 2), dtype=bool)
    stance[:, 1] = False  # only the left foot is planted in the human motion
    m = Q.measure(model, q, 10.0, _spec(), stance=stance)
    assert m["foot_contact_fraction"] == 0.0 and m["foot_slip_total_m"] == 0.0
    assert m["stance_slip_total_m"] == pytest.approx(0.10, abs=1e-9)
    assert m["stance_foot_height_median_m"] == pytest.approx(0.03, abs=1e-9)


def test_joint_out_of_range_is_counted(model):
    q = _standing(model, 6)
    knee = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "left_knee")]
    hip = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "right_hip")]
    q[1, knee] = -0.05  # 0.05 rad below the knee's lower limit 0
    q[2, hip] = 1.0005  # within the 1e-3 tolerance
    q[4, hip] = 1.2
    m = Q.measure(model, q, 20.0, _spec())
    assert m["joint_limit_frames"] == 2
    assert m["joint_limit_excess_max"] == pytest.approx(0.2, abs=1e-9)


def test_self_collision_frames(model):
    q = _standing(model, 5)
    sh = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "left_shoulder")]
    q[2:4, sh] = -1.2  # hinge about +x: negative swings the hanging arm towards -y, through the left thigh
    m = Q.measure(model, q, 20.0, _spec())
    assert m["self_collision_frames"] == 2
    assert "left_thigh|left_arm" in m["self_collision_pairs"]  # (and the right thigh, which it reaches too)
    assert m["self_collision_deepest_m"] > 0.002
    assert m["designed_pairs_ignored"] == 0
    # pairs that already penetrate in the reference pose are designed contacts, not counted
    xml = XML.replace('<body name="left_arm" pos="0 0.16 -0.02">', '<body name="left_arm" pos="0 0.16 -0.02" euler="-1.2 0 0">')
    bent = mujoco.MjModel.from_xml_string(xml)  # the arm built already swung into both thighs
    m3 = Q.measure(bent, np.tile(bent.qpos0, (3, 1)), 20.0, _spec())
    assert m3["designed_pairs_ignored"] == 2 and m3["self_collision_frames"] == 0


def test_base_turn(model):
    q = _standing(model, 4)
    angles = np.radians([0.0, 10.0, 12.0, 42.0])  # yaw steps 10, 2, 30 degrees
    q[:, 3] = np.cos(angles / 2)
    q[:, 6] = np.sin(angles / 2)
    m = Q.measure(model, q, 20.0, _spec())
    assert m["base_turn_max_deg"] == pytest.approx(30.0, abs=1e-6)
    assert m["base_turn_max_deg_s"] == pytest.approx(600.0, abs=1e-4)
    assert m["base_turn_max_at_frame"] == 3
    np.testing.assert_allclose(Q.quat_angles_deg(q[:, 3:7]), [10.0, 2.0, 30.0], atol=1e-6)


def test_keypoint_error(model):
    # keypoints: hips at the thigh bodies, knees at the knee joint anchors, feet at the foot bodies;
    # the "human" is the robot's own keypoints doubled in size about the hip midpoint and moved away
    kps = [Q.Keypoint(0, "body", "left_thigh"), Q.Keypoint(1, "body", "right_thigh"),
           Q.Keypoint(2, "joint", "left_knee"), Q.Keypoint(3, "joint", "right_knee"),
           Q.Keypoint(4, "body", "left_foot"), Q.Keypoint(5, "body", "right_foot")]
    spec = _spec(keypoints=kps, hips=(0, 1), legs=((0, 2, 4), (1, 3, 5)))
    q = _standing(model, 3)
    d = mujoco.MjData(model)
    pts = []
    for t in range(3):
        d.qpos[:] = q[t]
        mujoco.mj_kinematics(model, d)
        pts.append(Q._points(d, kps, Q._point_ids(model, kps)))
    pts = np.array(pts)
    origin = 0.5 * (pts[:, 0] + pts[:, 1])
    human = 2.0 * (pts - origin[:, None]) + np.array([3.0, 1.0, 0.0])
    assert Q.leg_scale(model, spec, human) == pytest.approx(0.5)
    m = Q.measure(model, q, 20.0, spec, human=human)
    assert m["keypoint_scale"] == pytest.approx(0.5)
    assert m["keypoint_error_mean_m"] == pytest.approx(0.0, abs=1e-9)
    # move the left foot keypoint of the human 10 cm (human units: 20 cm at scale 0.5) forward in frame 1
    human[1, 4, 0] += 0.2
    m = Q.measure(model, q, 20.0, spec, human=human, scale=0.5)
    assert m["keypoint_error_mean_m"] == pytest.approx(0.10 / 18, abs=1e-9)  # one of 6 keypoints x 3 frames
    # a constant offset is removed by the centred error
    human[:, 2, 1] += 0.1
    human[1, 4, 0] -= 0.2
    m = Q.measure(model, q, 20.0, spec, human=human, scale=0.5)
    assert m["keypoint_error_mean_m"] == pytest.approx(0.05 / 6, abs=1e-9)
    assert m["keypoint_error_centred_m"] == pytest.approx(0.0, abs=1e-9)


def test_map_qpos_by_name(model):
    src = np.zeros((2, 7 + 2))
    src[:, 3] = 1.0
    src[:, 7] = [0.3, 0.4]  # "knee_l" -> left_knee
    src[:, 8] = [0.1, 0.2]  # right_hip, flipped
    out, missing = Q.map_qpos(src, ["knee_l", "right_hip"], model, rename={"knee_l": "left_knee"}, flip={"right_hip"})
    adr = {n: model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in ("left_knee", "right_hip")}
    np.testing.assert_allclose(out[:, adr["left_knee"]], [0.3, 0.4])
    np.testing.assert_allclose(out[:, adr["right_hip"]], [-0.1, -0.2])
    assert set(missing) == {"left_hip", "right_knee", "left_shoulder"}
    with pytest.raises(KeyError):
        Q.map_qpos(src, ["nope", "right_hip"], model)


def test_driver_bone_axis_conversions_are_rotations():
    for bone in driver.AXES:
        C = driver.conversion(bone)
        np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(C) == pytest.approx(1.0)
        bandai, lafan = (driver.axes_matrix(a) for a in driver.AXES[bone])
        np.testing.assert_allclose(bandai @ C, lafan, atol=1e-12)  # standing pose: Bandai axes -> LAFAN1 axes
    np.testing.assert_allclose(driver.conversion("Spine2"), np.eye(3))
    assert set(driver.AXES) <= set(driver.RENAME)


def test_benchmark_skips_without_the_gmr_environment(tmp_path, capsys):
    import bench_gmr

    assert bench_gmr.main(["--gmr-python", str(tmp_path / "no_venv" / "bin" / "python"), "--out", str(tmp_path / "x.json")]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith("bench_gmr: skipped:")
    assert not (tmp_path / "x.json").exists()
