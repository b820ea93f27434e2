"""DeepMimic JSON and HumanML3D folder readers."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_data_fixtures import deepmimic_json

from motok_robot.data import deepmimic, humanml3d
from motok_robot.errors import InputError
from motok_robot.motion import features as F
from motok_robot.motion import skeleton
from motok_robot.motion.synthetic import walking_clip

J = skeleton.JOINT_INDEX


def test_deepmimic_rest_offsets_axes_and_rate(tmp_path):
    f = tmp_path / "humanoid3d_walk.txt"
    f.write_text(deepmimic_json(frames=31, dt=1 / 30, speed=1.0, knee=0.0))
    clip = deepmimic.load_clip(f)
    assert clip.joints.shape == (21, 22, 3)  # 1 s at 30 fps -> 21 frames at 20 fps
    j = clip.joints[0]
    # y-up, facing +x, right = +z  ->  z-up, facing +x, left = +y
    np.testing.assert_allclose(j[J["pelvis"]], [0, 0, 0.85], atol=1e-6)
    np.testing.assert_allclose(j[J["left_hip"]], [0, 0.084887, 0.85], atol=1e-6)
    np.testing.assert_allclose(j[J["right_knee"]], [0, -0.084887, 0.85 - 0.421546], atol=1e-6)
    np.testing.assert_allclose(j[J["left_ankle"], 2], 0.85 - 0.421546 - 0.40987, atol=1e-6)
    np.testing.assert_allclose(j[J["spine2"]], [0, 0, 0.85 + 0.236151], atol=1e-6)
    np.testing.assert_allclose(j[J["neck"], 2], 0.85 + 0.236151 + 0.223894, atol=1e-6)
    np.testing.assert_allclose(j[J["right_shoulder"]], [-0.02405, -0.18311, 0.85 + 0.236151 + 0.2435], atol=1e-6)
    assert j[J["left_foot"], 0] > j[J["left_ankle"], 0]  # toes point forward
    np.testing.assert_allclose(clip.joints[-1, 0] - clip.joints[0, 0], [1.0, 0, 0], atol=1e-6)
    assert set(clip.derived_joints) == {"spine1", "spine3", "left_collar", "right_collar", "head", "left_foot", "right_foot"}


def test_deepmimic_knee_and_root_rotation(tmp_path):
    data = json.loads(deepmimic_json(frames=2, knee=-np.pi / 2))
    # root turned 90 deg about y (up): facing +x -> facing -z
    s = np.sqrt(0.5)
    for row in data["Frames"]:
        row[4:8] = [s, 0, s, 0]
    f = tmp_path / "turned.txt"
    f.write_text(json.dumps(data))
    pos = deepmimic.forward_kinematics(deepmimic.read_frames(f))
    # knee flexed 90 deg (negative angle): the shin points backward (-x in the body frame,
    # which the root turn maps to +z)
    shin = pos["right_ankle"][0] - pos["right_knee"][0]
    np.testing.assert_allclose(shin, [0, 0, 0.40987], atol=1e-6)


def test_deepmimic_errors(tmp_path):
    good = json.loads(deepmimic_json(frames=3))
    cases = []
    short = json.loads(json.dumps(good))
    short["Frames"][1] = short["Frames"][1][:40]
    cases.append((json.dumps(short), r"frame 1 has 40 values, expected 44"))
    nan = json.dumps(good).replace("0.85", "NaN", 2)
    cases.append((nan, r"frame 0: value 2 \(root position\) is NaN"))
    cases.append((json.dumps({"Loop": "none", "Frames": []}), r"'Frames' is empty \(zero frames\)"))
    cases.append((json.dumps(good)[:-30], r"not valid JSON"))
    cases.append((json.dumps({"Loop": "none"}), r"no 'Frames' field"))
    for i, (text, pattern) in enumerate(cases):
        f = tmp_path / f"bad{i}.txt"
        f.write_text(text)
        with pytest.raises(InputError, match=rf"bad{i}\.txt: {pattern}"):
            deepmimic.load_clip(f)


def _humanml_folder(root, ids=("000001", "M000001", "000002")):
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "new_joints").mkdir()
    (root / "texts").mkdir()
    for k, cid in enumerate(ids):
        joints = walking_clip(frames=40 + k)
        if cid.startswith("M"):
            joints = skeleton.mirror_joints(joints)
        feats = F.features_from_joints(joints)
        np.save(root / "new_joint_vecs" / f"{cid}.npy", feats)
        np.save(root / "new_joints" / f"{cid}.npy", skeleton.yup_from_zup(F.normalise_joints(joints)))
        (root / "texts" / f"{cid}.txt").write_text(
            "a person walks and turns left#a/DET person/NOUN#0.0#0.0\nthe first second#x#0.0#1.0\n"
        )
    np.save(root / "Mean.npy", np.zeros(263, np.float32))
    np.save(root / "Std.npy", np.ones(263, np.float32))
    (root / "train.txt").write_text("000001\nM000001\n")
    (root / "test.txt").write_text("000002\n")
    return root


def test_humanml3d_reader(tmp_path):
    root = _humanml_folder(tmp_path / "HumanML3D")
    assert humanml3d.list_ids(root) == ["000001", "000002", "M000001"]
    clips = humanml3d.load_clips(root, "M000001")
    whole, part = clips
    assert whole.id == "humanml3d/M000001" and whole.texts == ["a person walks and turns left"]
    assert whole.labels == {"split": "train", "mirror_of": "humanml3d/000001"}
    feats = np.load(root / "new_joint_vecs" / "M000001.npy")
    np.testing.assert_array_equal(whole.features, feats)  # used as they are
    # joints converted to z-up: the pelvis is above the feet along +z
    assert (whole.joints[:, J["pelvis"], 2] > whole.joints[:, J["left_ankle"], 2]).all()
    np.testing.assert_allclose(whole.joints[:-1], F.joints_from_features(feats), atol=1e-5)
    assert part.id == "humanml3d/M000001_0_20" and part.joints.shape[0] == 20
    assert part.features.shape == (19, 263)


def test_humanml3d_bad_files(tmp_path):
    root = _humanml_folder(tmp_path / "H", ids=("000001",))
    np.save(root / "new_joint_vecs" / "000001.npy", np.zeros((10, 200), np.float32))
    with pytest.raises(InputError, match=r"000001\.npy: expected \[T-1, 263\] features"):
        humanml3d.load_clips(root, "000001")
    with pytest.raises(InputError, match="not a HumanML3D folder"):
        humanml3d.list_ids(tmp_path)
