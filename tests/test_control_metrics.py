"""Control metrics (GMD / OmniControl protocol), the physics term, trajectory formats and clip length."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.control.constraints import Constraints, Obstacle, add_trajectory  # noqa: E402
from motok_robot.control.losses import foot_loss  # noqa: E402
from motok_robot.control.metrics import (  # noqa: E402
    bone_length_change,
    clip_metrics,
    control_table,
    keyframe_errors,
    obstacle_penetration,
)
from motok_robot.control.options import frames_from_args  # noqa: E402
from motok_robot.errors import InputError  # noqa: E402
from motok_robot.motion.synthetic import walking_clip  # noqa: E402

T = 30


@pytest.fixture(scope="module")
def walk() -> np.ndarray:
    return walking_clip(frames=T).astype(np.float64)


def test_keyframe_errors_use_only_constrained_coordinates(walk):
    c = Constraints(T)
    c.set_joint(5, 0, walk[5, 0, :2] + [0.3, 0.4])  # planar root: the height does not count
    c.set_joint(10, 21, walk[10, 21] + [0.0, 0.0, 0.1])
    errors = keyframe_errors(walk, c)
    np.testing.assert_allclose(errors, [0.5, 0.1], atol=1e-9)
    m = clip_metrics(walk, c)
    assert m["max_error_m"] == pytest.approx(0.5) and m["keyframes"] == 2 and m["keyframes_far"] == 0


def test_control_table_fractions():
    base = {"foot_skating_ratio": 0.1, "penetration_mean_mm": 1.0, "floating_mean_mm": 2.0, "bone_change_m": 0.0}
    clips = [
        dict(base, keyframes=4, max_error_m=0.6, mean_error_m=0.3, keyframes_far=1, obstacle_depth_m=0.0),
        dict(base, keyframes=4, max_error_m=0.3, mean_error_m=0.1, keyframes_far=0, obstacle_depth_m=0.02),
        dict(base, keyframes=2, max_error_m=0.1, mean_error_m=0.05, keyframes_far=0, obstacle_depth_m=0.0005),
    ]
    row = control_table(clips)
    assert row["traj_fail_50cm"] == pytest.approx(1 / 3) and row["traj_fail_20cm"] == pytest.approx(2 / 3)
    assert row["location_fail_50cm"] == pytest.approx(1 / 10)
    assert row["avg_error_m"] == pytest.approx(0.15) and row["avg_error_cm"] == pytest.approx(15.0)
    assert row["max_error_cm"] == pytest.approx(60.0)
    assert row["obstacle_hit_fraction"] == pytest.approx(1 / 3) and row["obstacle_depth_max_cm"] == pytest.approx(2.0)
    with pytest.raises(InputError):
        control_table([])


def test_obstacle_penetration_and_bone_length_change(walk):
    c = Constraints(T)
    c.obstacles.append(Obstacle("circle", tuple(walk[15, 0, :2]), radius=0.05))
    assert obstacle_penetration(walk, c) == pytest.approx(0.05, abs=1e-6)  # the pelvis passes its centre
    assert obstacle_penetration(walk, Constraints(T)) == 0.0
    assert bone_length_change(walk) < 1e-6
    stretched = walk.copy()
    stretched[:, 10, :] += [0.0, 0.0, -0.1]  # left foot moved: one bone changes in every frame...
    stretched[:15, 10, :] = walk[:15, 10, :]  # ...in half of the frames
    assert bone_length_change(stretched) > 1e-3


def test_foot_term_does_not_reward_lifting_the_feet(walk):
    """The contact label carries no gradient: the slide term cannot be lowered by raising a foot."""
    j = torch.as_tensor(walk, dtype=torch.float32)[None].clone()
    j[:, :, 10, 2] = 0.02  # left foot on the ground...
    j[:, :, 10, 0] = torch.linspace(0, 1, T)  # ...and sliding
    j.requires_grad_(True)
    foot_loss(j).sum().backward()
    assert j.grad[0, :, 10, 2].min() >= 0  # descent never lifts the foot (the floor term pulls it down)
    assert j.grad[0, 1:-1, 10, 0].abs().max() > 0  # the slide is penalised


def test_dense_trajectory_formats(tmp_path):
    rows = np.stack([np.linspace(0, 1, 10), np.zeros(10)], 1)
    rows[4] = np.nan
    csv = tmp_path / "path.csv"
    np.savetxt(csv, rows, delimiter=",")
    npy = tmp_path / "path.npy"
    np.save(npy, np.concatenate([rows, np.full((10, 1), 0.9)], 1))
    for path, height in ((csv, False), (npy, True)):
        c = add_trajectory(Constraints(12), path)
        assert c.joint_mask[:, 0].tolist() == [True] * 4 + [False] + [True] * 5 + [False] * 2
        assert c.root_height_mask[0] == height
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros((5, 2, 2)))
    with pytest.raises(InputError, match=r"shape \[T, 2\] or \[T, 3\]"):
        add_trajectory(Constraints(12), bad)
    half = tmp_path / "half.csv"
    half.write_text("0,0\nnan,1\n")
    with pytest.raises(InputError, match="row 1: x and y must both be given"):
        add_trajectory(Constraints(12), half)
    with pytest.raises(InputError, match="12 trajectory rows but the clip has 8"):
        np.savetxt(csv, np.zeros((12, 2)), delimiter=",")
        add_trajectory(Constraints(8), csv)


def test_clip_length_from_the_files(tmp_path):
    def args(**kw):
        base = dict(seconds=None, edit=None, trajectory=None, keyframes=None, prefix=None, suffix=None)
        base.update(kw)
        return argparse.Namespace(**base)

    traj = tmp_path / "t.csv"
    traj.write_text("frame,x,y\n0,0,0\n79,2,0\n")
    keys = tmp_path / "k.json"
    keys.write_text(json.dumps({"keyframes": [{"frame": 150, "joint": "head", "position": [0, 0, 1.6]}]}))
    motion = tmp_path / "m.npz"
    np.savez(motion, joints=np.zeros((50, 22, 3)), features=np.zeros((50, 263)))
    assert frames_from_args(args(seconds=2.5)) == 50
    assert frames_from_args(args(trajectory=str(traj))) == 80
    assert frames_from_args(args(keyframes=str(keys))) == 151
    assert frames_from_args(args()) == 120
    assert frames_from_args(args(edit=str(motion))) == 50
    assert frames_from_args(args(prefix=str(motion), suffix=str(motion))) == 120  # 50 + 50 + 20 < 6 s


def test_bone_term_is_zero_for_a_rigid_skeleton_and_pulls_a_stretched_limb_back(walk):
    from motok_robot.control.losses import bone_loss

    rigid = torch.as_tensor(walk, dtype=torch.float32)[None]
    assert float(bone_loss(rigid)[0]) < 1e-10
    stretched = rigid.clone()
    stretched[:, 20:, 21, 2] -= 0.2  # the right wrist drops 20 cm away from the elbow in the last frames
    stretched.requires_grad_(True)
    loss = bone_loss(stretched)
    loss.sum().backward()
    assert float(loss.detach()[0]) > 1e-4
    assert float(stretched.grad[0, 25, 21, 2]) < 0  # descent moves the wrist back up


def test_seams_are_cross_faded_and_kept_frames_exact():
    from motok_robot.control.decode import blend_seams

    T, P, S = 40, 8, 8
    x = torch.zeros(1, T, 263)
    x[:, :P, 4:] = 1.0  # kept prefix pose
    x[:, T - S :, 4:] = -1.0  # kept suffix pose; the generated middle is 0
    out = blend_seams(x, P, S, frames=10)
    torch.testing.assert_close(out[:, :P], x[:, :P])
    torch.testing.assert_close(out[:, T - S :], x[:, T - S :])
    pose = out[0, :, 10]
    steps = (pose[1:] - pose[:-1]).abs()
    assert steps.max() <= 1.0 / 11 + 1e-6  # a jump of 1 spread over 11 steps, not one
    torch.testing.assert_close(out[:, :, :3], x[:, :, :3])  # the root path is not touched


def test_sparse_root_imputation_is_exact_without_jumps(walk):
    from motok_robot.control.guidance import impute_root
    from motok_robot.control.losses import ConstraintTensors
    from motok_robot.motion.features import features_from_joints
    from motok_robot.motion.features_torch import root_from_features

    x = torch.as_tensor(features_from_joints(walk), dtype=torch.float32)[None]  # [1, T-1, 263]
    root, _ = root_from_features(x)
    c = Constraints(x.shape[1])
    c.set_joint(10, 0, (root[0, 10, :2] + torch.tensor([0.0, 1.0])).tolist())  # one metre to the left
    c.set_joint(20, 0, root[0, 20, :2].tolist())
    out, _ = root_from_features(impute_root(x, ConstraintTensors.from_constraints(c)))
    torch.testing.assert_close(out[0, [10, 20], :2], torch.as_tensor(c.joint_targets[[10, 20], 0, :2]), atol=1e-5, rtol=0)
    extra = (out - root)[0, :, 1]  # the detour, spread linearly over the free frames
    assert (extra[1:] - extra[:-1]).abs().max() <= 1.0 / 10 + 1e-5


def test_floating_feet_are_pulled_to_the_floor_but_jumps_are_left_alone(walk):
    from motok_robot.control.losses import foot_loss

    j = torch.as_tensor(walk[:1], dtype=torch.float32).repeat(10, 1, 1)[None]  # standing still
    j[..., 2] -= j[..., 2].min() - 0.005  # on the floor
    grounded = float(foot_loss(j)[0])
    floating, jumping = j.clone(), j.clone()
    floating[..., 2] += 0.05
    jumping[..., 2] += 0.5
    assert float(foot_loss(floating)[0]) > grounded + 1e-4
    assert float(foot_loss(jumping)[0]) < grounded + 1e-6
