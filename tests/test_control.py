"""Control stage: constraint files, imputation exactness, each mechanism vs none, in-betweening seams."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.control.config import ControlConfig  # noqa: E402
from motok_robot.control.constraints import (  # noqa: E402
    Constraints,
    add_keyframes,
    add_obstacles,
    add_prefix,
    add_suffix,
    add_trajectory,
)
from motok_robot.control.decode import decode_with_control, exact_seams  # noqa: E402
from motok_robot.control.guidance import impute_root, with_root  # noqa: E402
from motok_robot.control.losses import ConstraintTensors, control_loss, obstacle_distance  # noqa: E402
from motok_robot.errors import InputError  # noqa: E402
from motok_robot.motion.features import features_from_joints  # noqa: E402
from motok_robot.motion.features_torch import joints_from_features, root_from_features  # noqa: E402
from motok_robot.motion.synthetic import walking_clip  # noqa: E402
from motok_robot.tokenizer import MoTok, TokenizerConfig  # noqa: E402

T = 40


@pytest.fixture(scope="module")
def walk_features() -> np.ndarray:
    return features_from_joints(walking_clip(frames=T + 1))  # [T, 263]


@pytest.fixture(scope="module")
def tiny_tokenizer(walk_features):
    torch.manual_seed(0)
    torch.set_num_threads(1)
    cfg = TokenizerConfig(width=32, depth=1, codebook_size=16, code_dim=16, denoiser_width=32, denoiser_blocks=2, diffusion_steps=100, sample_steps=6)
    mean = walk_features.mean(0)
    std = walk_features.std(0) + 1e-2
    return MoTok(cfg, mean, std).eval()


def constraint_loss_of(features: torch.Tensor, c: Constraints) -> float:
    return float(control_loss(joints_from_features(features), ConstraintTensors.from_constraints(c)).mean())


# ----------------------------------------------------------------------------- files


def test_trajectory_csv_and_npz(tmp_path):
    csv_file = tmp_path / "traj.csv"
    csv_file.write_text("frame,x,y\n0,0,0\n10,0.5,0.1\n39,1.5,0.2\n")
    c = add_trajectory(Constraints(T), csv_file)
    assert c.joint_mask[:, 0].sum() == 3 and not c.root_height_mask.any()
    np.testing.assert_allclose(c.joint_targets[10, 0, :2], [0.5, 0.1])
    npz = tmp_path / "traj.npz"
    np.savez(npz, root=np.zeros((T, 3)))
    c = add_trajectory(Constraints(T), npz)
    assert c.joint_mask[:, 0].all() and c.root_height_mask.all()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("frame,x,y\n0,0,nan\n", "line 2: field 'y' is NaN"),
        ("frame,x,y\n50,0,0\n", "frame 50 is out of range"),
        ("frame,a,b\n0,0,0\n", "CSV header"),
        ("frame,x,y\n1.5,0,0\n", "'frame' must be an integer"),
    ],
)
def test_bad_trajectory_csv_names_the_field(tmp_path, content, message):
    path = tmp_path / "t.csv"
    path.write_text(content)
    with pytest.raises(InputError, match=message):
        add_trajectory(Constraints(T), path)


def test_bad_trajectory_npz_shape(tmp_path):
    path = tmp_path / "t.npz"
    np.savez(path, root=np.zeros((T, 4)))
    with pytest.raises(InputError, match=r"'root' must have shape \[T, 2\] or \[T, 3\]"):
        add_trajectory(Constraints(T), path)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ({"frame": 3, "joint": "left_pinky", "position": [0, 0, 1]}, "unknown joint 'left_pinky'"),
        ({"frame": 99, "joint": "head", "position": [0, 0, 1]}, "frame 99 is out of range"),
        ({"frame": 3, "joint": "head", "position": [0, "x", 1]}, "field 'position' must be a number"),
        ({"frame": 3, "joint": "head", "position": [0, 1]}, "needs 3 values"),
        ({"joint": "head", "position": [0, 0, 1]}, "needs a 'frame' or a 'time'"),
    ],
)
def test_bad_keyframes_name_the_field(tmp_path, item, message):
    path = tmp_path / "k.json"
    path.write_text(json.dumps({"keyframes": [item]}))
    with pytest.raises(InputError, match=message):
        add_keyframes(Constraints(T), path)


def test_keyframes_time_and_obstacles(tmp_path):
    path = tmp_path / "k.json"
    path.write_text(json.dumps({"keyframes": [{"time": 1.0, "joint": "right_wrist", "position": [0.3, -0.2, 1.5]}]}))
    c = add_keyframes(Constraints(T), path)
    assert c.joint_mask[20, 21]
    obs = tmp_path / "o.json"
    obs.write_text(json.dumps({"obstacles": [{"type": "circle", "center": [1, 0], "radius": 0.2}, {"type": "box", "center": [0, 2], "size": [1, 0.5], "yaw": 0.0}]}))
    c = add_obstacles(c, obs)
    ct = ConstraintTensors.from_constraints(c)
    d = obstacle_distance(torch.tensor([[1.0, 0.0], [1.5, 0.0], [0.0, 2.0], [0.0, 2.5]]), ct)
    torch.testing.assert_close(d, torch.tensor([-0.2, 0.3, -0.25, 0.25]))
    obs.write_text(json.dumps({"obstacles": [{"type": "triangle", "center": [1, 0]}]}))
    with pytest.raises(InputError, match="'type' must be 'circle' or 'box'"):
        add_obstacles(Constraints(T), obs)


def test_unknown_mechanism():
    with pytest.raises(InputError, match="unknown mechanism"):
        ControlConfig(mechanisms="motok,magic")


# ----------------------------------------------------------------------------- imputation


def test_with_root_inverts_root_from_features(walk_features):
    x = torch.as_tensor(walk_features)[None]
    root, yaw = root_from_features(x)
    torch.testing.assert_close(with_root(x, root, yaw), x, atol=1e-5, rtol=0)
    # a moved trajectory is recovered exactly (frame 0 stays at the origin by construction)
    moved = root.clone()
    moved[:, 1:, :2] += torch.linspace(0, 0.5, T - 1)[None, :, None]
    out_root, out_yaw = root_from_features(with_root(x, moved, yaw))
    torch.testing.assert_close(out_root, moved, atol=1e-5, rtol=0)
    torch.testing.assert_close(out_yaw, yaw)


def test_imputation_keeps_imposed_values_exactly(walk_features):
    c = Constraints(T)
    rng = np.random.default_rng(0)
    for f in range(1, T, 3):
        c.set_joint(f, 0, [0.05 * f, 0.3 * np.sin(f / 5), 0.9 + 0.01 * rng.normal()])
    x = torch.as_tensor(walk_features)[None]
    out = impute_root(x, ConstraintTensors.from_constraints(c))
    root, _ = root_from_features(out)
    frames = np.flatnonzero(c.joint_mask[:, 0])
    torch.testing.assert_close(root[0, frames], torch.as_tensor(c.joint_targets[frames, 0]), atol=1e-5, rtol=0)


# ----------------------------------------------------------------------------- mechanisms


def root_constraints() -> Constraints:
    c = Constraints(T)
    for f in range(T):
        c.set_joint(f, 0, [0.04 * f, 0.2 * np.sin(f / 8.0)])
    return c


def keyframe_constraints() -> Constraints:
    c = Constraints(T)
    for f, joint, pos in [(10, 21, [0.3, -0.3, 1.6]), (20, 20, [0.5, 0.4, 1.5]), (30, 15, [0.8, 0.0, 1.4]), (35, 0, [1.0, 0.2])]:
        c.set_joint(f, joint, pos)
    return c


@pytest.mark.parametrize("mechanism", ["motok", "gmd", "inpaint"])
@pytest.mark.parametrize("make", [root_constraints, keyframe_constraints], ids=["root", "keyframes"])
def test_each_mechanism_lowers_the_constraint_loss(tiny_tokenizer, mechanism, make):
    if mechanism == "inpaint" and make is keyframe_constraints:
        pytest.skip("MDM inpainting acts on the root trajectory and on whole frames/joints, not on sparse joint keyframes")
    c = make()
    tokens = torch.randint(0, 16, (2, T // 4), generator=torch.Generator().manual_seed(0))
    free = decode_with_control(tiny_tokenizer, tokens, T, c, ControlConfig(mechanisms=("none",)), seed=1)
    cfg = ControlConfig(mechanisms=(mechanism,), refine_final_iters=60)
    guided = decode_with_control(tiny_tokenizer, tokens, T, c, cfg, seed=1)
    before, after = constraint_loss_of(free, c), constraint_loss_of(guided, c)
    assert after < 0.8 * before, (mechanism, before, after)


def test_refinement_meets_root_trajectory_closely(tiny_tokenizer):
    c = root_constraints()
    tokens = torch.randint(0, 16, (1, T // 4), generator=torch.Generator().manual_seed(3))
    out = decode_with_control(tiny_tokenizer, tokens, T, c, ControlConfig(mechanisms=("motok", "gmd")), seed=0)
    root = joints_from_features(out)[0, :, 0, :2].numpy()
    err = np.linalg.norm(root - c.joint_targets[:, 0, :2], axis=-1)
    assert err[1:].mean() < 0.02, err.mean()


# ----------------------------------------------------------------------------- in-betweening


def test_exact_seams_keep_prefix_and_suffix_and_stay_continuous(tmp_path, walk_features):
    joints_full = joints_from_features(torch.as_tensor(walk_features)).numpy()
    motion = tmp_path / "m.npz"
    np.savez(motion, joints=joints_full, features=walk_features)
    c = Constraints(T)
    add_prefix(c, motion, frames=8)
    add_suffix(c, motion, frames=8)
    # a "generated" middle that knows nothing of the suffix: the walk, slowed down and turned
    x = torch.as_tensor(walk_features)[None].clone()
    x[:, 8:32, 1:3] *= 0.5
    x[:, 8:32, 0] += 0.01
    out = exact_seams(x, c)
    joints = joints_from_features(out)[0].numpy()
    np.testing.assert_allclose(joints[:8], joints_full[:8], atol=1e-5)
    np.testing.assert_allclose(joints[-8:], joints_full[-8:], atol=2e-3)
    speed = np.linalg.norm(np.diff(joints, axis=0), axis=-1).max(axis=1)
    data_speed = np.linalg.norm(np.diff(joints_full, axis=0), axis=-1).max(axis=1)
    assert speed.max() <= np.percentile(data_speed, 99) * 1.5
