"""BVH parser, forward kinematics, skeleton maps and malformed-file errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_data_fixtures import BANDAI_NAMES, canonical_bvh_text, identity_map

from motok_robot.data import bvh
from motok_robot.data.clip import load_joint_map
from motok_robot.errors import InputError
from motok_robot.motion import skeleton

# Unusual channel orders, a position channel on a non-root joint, an End Site.
SMALL = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Xrotation Zrotation Yrotation
    JOINT Neck
    {
      OFFSET 0 10 0
      CHANNELS 4 Xposition Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 5 0
      }
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.05
1 2 3 90 0 0   0 90 0   2 0 0 0
0 0 0 0 0 0    0 0 0    2 0 0 0
0 0 0 0 0 0    90 90 0  2 0 0 0
"""


def test_fk_matches_hand_computed_positions(tmp_path):
    f = tmp_path / "small.bvh"
    f.write_text(SMALL)
    m = bvh.read_bvh(f)
    assert m.skeleton.names == ["Hips", "Chest", "Neck", "Neck_end"]
    assert m.skeleton.joints[2].channels == ["Xposition", "Zrotation", "Xrotation", "Yrotation"]
    assert m.fps == pytest.approx(20.0)
    pos = bvh.forward_kinematics(m)
    # frame 0: root at (1,2,3) turned 90 deg about y; chest turned 90 deg about z;
    # Neck's Xposition 2 replaces its offset's x: local translation (2, 10, 0).
    np.testing.assert_allclose(pos["Hips"][0], [1, 2, 3], atol=1e-9)
    np.testing.assert_allclose(pos["Chest"][0], [1, 12, 3], atol=1e-9)
    np.testing.assert_allclose(pos["Neck"][0], [1, 14, 13], atol=1e-9)
    np.testing.assert_allclose(pos["Neck_end"][0], [1, 14, 18], atol=1e-9)
    # frame 1: rest
    np.testing.assert_allclose(pos["Neck"][1], [2, 20, 0], atol=1e-9)
    np.testing.assert_allclose(pos["Neck_end"][1], [2, 25, 0], atol=1e-9)
    # frame 2: chest "Xrotation Zrotation Yrotation" = Rx(90) @ Rz(90) (order matters)
    np.testing.assert_allclose(pos["Neck"][2], [-10, 10, 2], atol=1e-9)
    np.testing.assert_allclose(pos["Neck_end"][2], [-15, 10, 2], atol=1e-9)


def _bad(tmp_path, text, name="bad.bvh"):
    f = tmp_path / name
    f.write_text(text)
    return f


def test_truncated_motion_names_file_and_counts(tmp_path):
    f = _bad(tmp_path, SMALL.replace("Frames: 3", "Frames: 5"))
    with pytest.raises(InputError, match=r"bad\.bvh: truncated motion: header says 5 frames, file has 3"):
        bvh.read_bvh(f)


def test_wrong_channel_count_names_frame(tmp_path):
    f = _bad(tmp_path, SMALL.replace("0 0 0 0 0 0    0 0 0    2 0 0 0", "0 0 0 0 0 0    0 0 0    2 0 0 0 7"))
    with pytest.raises(InputError, match=r"frame 1 has 14 values, the hierarchy declares 13 channels"):
        bvh.read_bvh(f)
    f = _bad(tmp_path, SMALL.replace("CHANNELS 3 Xrotation Zrotation Yrotation", "CHANNELS 3 Xrotation Wrotation Yrotation"))
    with pytest.raises(InputError, match=r"joint 'Chest': CHANNELS 3"):
        bvh.read_bvh(f)


def test_nan_value_names_frame_joint_channel(tmp_path):
    f = _bad(tmp_path, SMALL.replace("0 0 0 0 0 0    90 90 0", "0 0 0 0 0 0    90 nan 0"))
    with pytest.raises(InputError, match=r"frame 2: joint 'Chest' channel Zrotation is nan"):
        bvh.read_bvh(f)


def test_zero_frames_and_missing_motion(tmp_path):
    head = SMALL.split("MOTION")[0]
    with pytest.raises(InputError, match="zero frames"):
        bvh.read_bvh(_bad(tmp_path, head + "MOTION\nFrames: 0\nFrame Time: 0.05\n"))
    with pytest.raises(InputError, match="no MOTION section"):
        bvh.read_bvh(_bad(tmp_path, head))
    with pytest.raises(InputError, match="unclosed"):
        bvh.read_bvh(_bad(tmp_path, head.rsplit("}", 1)[0] + "MOTION\nFrames: 1\nFrame Time: 0.05\n0\n"))


def test_unknown_joint_in_map_is_named(tmp_path):
    f = _bad(tmp_path, canonical_bvh_text(frames=4), "walk.bvh")
    spec = {"joints": {n: n for n in skeleton.JOINT_NAMES}, "units_to_m": 0.01, "up_axis": "y"}
    spec["joints"]["head"] = "Skull"
    with pytest.raises(InputError, match=r"walk\.bvh: joint map names source joint 'Skull' \(for head\)"):
        bvh.load_clip(f, spec)
    # a map file naming a joint that is not canonical
    mf = tmp_path / "map.json"
    mf.write_text(json.dumps({"joints": {**{n: n for n in skeleton.JOINT_NAMES}, "tail": "Tail"}}))
    with pytest.raises(InputError, match=r"unknown canonical joint\(s\) \['tail'\]"):
        load_joint_map(mf)


def test_user_map_file_converts_units_axes_and_rate(tmp_path):
    f = tmp_path / "walk.bvh"
    f.write_text(canonical_bvh_text(frames=31, fps=30.0, speed=1.0))
    clip = bvh.load_clip(f, str(identity_map(tmp_path / "map.json")), source="bvh")
    assert clip.joints.dtype == np.float32
    assert clip.joints.shape == (21, 22, 3)  # 1 s at 30 fps -> 1 s at 20 fps
    # 1 m/s along the body's forward (+z in the file) becomes +x here, z up, metres
    np.testing.assert_allclose(clip.joints[-1, 0] - clip.joints[0, 0], [1.0, 0.0, 0.0], atol=1e-5)
    assert clip.joints[0, skeleton.JOINT_INDEX["head"], 2] > clip.joints[0, 0, 2] > clip.joints[0, 7, 2]
    assert clip.joints[0, skeleton.JOINT_INDEX["left_hip"], 1] > 0  # left = +y when facing +x


def test_forward_field_turns_body_to_face_x(tmp_path):
    f = tmp_path / "walk.bvh"
    f.write_text(canonical_bvh_text(frames=21, fps=20.0, speed=1.0))
    spec = load_joint_map(identity_map(tmp_path / "map.json", forward="z"))
    clip = bvh.load_clip(f, spec)
    np.testing.assert_allclose(clip.joints[-1, 0] - clip.joints[0, 0], [1.0, 0.0, 0.0], atol=1e-5)


def test_bandai_map_derives_spine3(tmp_path):
    f = tmp_path / "dataset-2_walk_normal_001.bvh"
    f.write_text(canonical_bvh_text(frames=10, names=BANDAI_NAMES | {"spine3": "x"}, skip=("spine3",)))
    clip = bvh.load_clip(f, "bandai")
    assert clip.derived_joints == ["spine3"]
    rest = skeleton.rest_pose()
    J = skeleton.JOINT_INDEX
    for name in ("pelvis", "left_knee", "right_wrist", "head"):
        np.testing.assert_allclose(clip.joints[0, J[name]], rest[J[name]], atol=1e-5)
    expect = 0.7 * rest[J["spine2"]] + 0.3 * rest[J["neck"]]
    np.testing.assert_allclose(clip.joints[0, J["spine3"]], expect, atol=1e-5)


def test_acrnn_map_uses_end_site_for_toes():
    assert bvh.ACRNN_MAP["left_foot"] == "lFoot_end"
    assert set(bvh.ACRNN_MAP) == set(skeleton.JOINT_NAMES)
    assert set(bvh.BANDAI_MAP) == set(skeleton.JOINT_NAMES)
