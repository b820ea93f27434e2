"""Torch feature decoders: agreement with numpy, batching, gradients, foot-contact helper."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.errors import InputError  # noqa: E402
from motok_robot.motion import features as F  # noqa: E402
from motok_robot.motion import features_torch as FT  # noqa: E402
from motok_robot.motion import synthetic  # noqa: E402

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def batch():
    clips = [synthetic.walking_clip(61, turn_rate=0.8), synthetic.random_poses(61, seed=2), synthetic.standing_clip(61)]
    return np.stack([F.features_from_joints(c) for c in clips])  # [3, 60, 263] float32


def test_torch_matches_numpy_float32(batch):
    out = FT.joints_from_features(torch.from_numpy(batch))
    assert out.shape == (3, 60, 22, 3) and out.dtype == torch.float32
    np.testing.assert_allclose(out.numpy(), F.joints_from_features(batch.astype(np.float64)), atol=1e-5)
    root, yaw = FT.root_from_features(torch.from_numpy(batch))
    root_np, yaw_np = F.root_from_features(batch)
    np.testing.assert_allclose(root.numpy(), root_np, atol=1e-5)
    np.testing.assert_allclose(yaw.numpy(), yaw_np, atol=1e-5)
    np.testing.assert_allclose(root.numpy(), out[..., 0, :].numpy(), atol=1e-6)


def test_torch_round_trip_and_extra_batch_dims(batch):
    clip = synthetic.walking_clip(61, turn_rate=0.8)
    norm = F.normalise_joints(clip)[:-1]
    out = FT.joints_from_features(torch.from_numpy(batch)[None, :1].double())  # [1, 1, 60, 263]
    assert out.shape == (1, 1, 60, 22, 3)
    assert np.abs(out[0, 0].numpy() - norm).max() < 1e-5


def test_gradients_flow_to_root_and_ric_features(batch):
    x = torch.from_numpy(batch[:1, :8]).double().requires_grad_(True)
    assert torch.autograd.gradcheck(FT.joints_from_features, (x,), eps=1e-6, atol=1e-5)
    FT.joints_from_features(x)[..., -1, :, :].sum().backward()
    g = x.grad[0]
    assert g[:-1, 0].abs().sum() > 0  # yaw velocities of earlier frames move the last pose
    assert g[:-1, 1:3].abs().sum() > 0
    assert g[-1, 4:67].abs().sum() > 0
    assert g[:, 67:].abs().sum() == 0  # rotations, velocities and contacts are not used


def test_foot_contact_velocity_masks_by_contact():
    joints = torch.zeros(2, 4, 22, 3)
    joints[:, :, 10, 0] = torch.arange(4.0) * 0.1  # left foot moves 10 cm per frame
    contacts = torch.zeros(2, 4, 4)
    contacts[0, :, 1] = 1.0  # batch 0 claims the left foot is planted
    vel = FT.foot_contact_velocity(joints, contacts)
    assert vel.shape == (2, 3, 4, 3)
    np.testing.assert_allclose(vel[0, :, 1, 0].numpy(), 0.1, rtol=1e-6)
    assert vel[1].abs().sum() == 0
    assert vel[0, :, [0, 2, 3]].abs().sum() == 0
    with pytest.raises(InputError, match="contacts"):
        FT.foot_contact_velocity(joints, contacts[..., :3])


def test_cont6d_torch_matches_numpy():
    from motok_robot.motion import rotations as R

    d6 = np.random.default_rng(0).normal(size=(10, 6))
    np.testing.assert_allclose(FT.matrix_from_cont6d(torch.from_numpy(d6)).numpy(), R.matrix_from_cont6d(d6), atol=1e-12)
    m = R.matrix_from_cont6d(d6)
    np.testing.assert_allclose(FT.matrix_to_cont6d(torch.from_numpy(m)).numpy(), R.matrix_to_cont6d(m))


def test_shape_errors():
    with pytest.raises(InputError, match="263"):
        FT.joints_from_features(torch.zeros(5, 262))
    with pytest.raises(InputError, match="Tensor"):
        FT.joints_from_features(np.zeros((5, 263)))
