"""Torch versions of the feature decoders (batched, differentiable).

The same mathematics as :mod:`motok_robot.motion.features` (HumanML3D's ``recover_from_ric``),
for tensors of any leading batch shape on any device and dtype, with gradients flowing to
every input feature that the result depends on (root yaw velocity, root planar velocity,
root height, ric positions). Outputs are in the project's world frame: metres, **z up**,
facing +x at frame 0. The numpy functions agree with these to float32 rounding (tested to
1e-5 m).

This is the only module of :mod:`motok_robot.motion` that imports torch; do not import it
from ``motok_robot.motion.__init__``.
"""

from __future__ import annotations

import torch

from motok_robot.errors import InputError
from motok_robot.motion.features import CONTACT_JOINTS, FEATURE_DIM


def _check(features: torch.Tensor, name: str = "features") -> None:
    if not isinstance(features, torch.Tensor):
        raise InputError(f"{name} must be a torch.Tensor of shape [..., T, {FEATURE_DIM}]; got {type(features).__name__}")
    if features.ndim < 2 or features.shape[-1] != FEATURE_DIM:
        raise InputError(f"{name} must have shape [..., T, {FEATURE_DIM}] (frames, HumanML3D features); got shape {list(features.shape)}")
    if features.shape[-2] < 1:
        raise InputError(f"{name} has 0 frames")


def _zup_from_yup(x: torch.Tensor) -> torch.Tensor:
    return torch.stack([x[..., 2], x[..., 0], x[..., 1]], dim=-1)


def _root_yup(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(root [..., T, 3] y-up, a [..., T])`` with ``a`` the angle of the root-facing rotation
    about +y (minus the heading)."""
    half = features[..., 0]
    zeros = torch.zeros_like(half[..., :1])
    a = 2.0 * torch.cat([zeros, torch.cumsum(half[..., :-1], dim=-1)], dim=-1)
    c, s = torch.cos(a), torch.sin(a)
    vx = torch.cat([zeros, features[..., :-1, 1]], dim=-1)
    vz = torch.cat([zeros, features[..., :-1, 2]], dim=-1)
    wx = c * vx - s * vz
    wz = s * vx + c * vz
    root = torch.stack([torch.cumsum(wx, dim=-1), features[..., 3], torch.cumsum(wz, dim=-1)], dim=-1)
    return root, a


def root_from_features(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Root trajectory of ``features[..., T, 263]``.

    Returns:
        ``(root_positions [..., T, 3], yaw [..., T])``: pelvis positions in metres (z up, the
        root's ground point at the origin at frame 0) and heading in rad about +z (0 = facing
        +x, positive = turned towards +y).
    """
    _check(features)
    root, a = _root_yup(features)
    return _zup_from_yup(root), -a


def joints_from_features(features: torch.Tensor) -> torch.Tensor:
    """Joint positions ``[..., T, 22, 3]`` (metres, z up) from ``features[..., T, 263]``.

    Batched over any leading dimensions and differentiable. The 6D rotations, joint
    velocities and foot contacts are not used (HumanML3D's ``recover_from_ric``).
    """
    _check(features)
    root, a = _root_yup(features)
    c, s = torch.cos(a)[..., None], torch.sin(a)[..., None]
    ric = features[..., 4:67].reshape(features.shape[:-1] + (21, 3))
    x = c * ric[..., 0] - s * ric[..., 2] + root[..., 0:1]
    z = s * ric[..., 0] + c * ric[..., 2] + root[..., 2:3]
    body = torch.stack([x, ric[..., 1], z], dim=-1)
    joints = torch.cat([root[..., None, :], body], dim=-2)
    return _zup_from_yup(joints)


def foot_contact_velocity(joints: torch.Tensor, contacts: torch.Tensor, threshold: float = 0.5) -> torch.Tensor:
    """Velocities of the four contact joints where a contact is on (MDM's foot-contact loss).

    Args:
        joints: ``[..., T, 22, 3]`` metres (e.g. :func:`joints_from_features` of a prediction).
        contacts: ``[..., T, 4]`` contact values in feature order (left_ankle, left_foot,
            right_ankle, right_foot), e.g. ``features[..., 259:263]``; a contact is on when
            the value exceeds ``threshold``. Frame t's contact gates the step t -> t + 1.
        threshold: contact threshold.

    Returns:
        ``[..., T-1, 4, 3]`` m/frame, zero where the contact is off. MDM's loss is the mean
        of its square.
    """
    if joints.ndim < 3 or joints.shape[-2:] != (22, 3):
        raise InputError(f"joints must have shape [..., T, 22, 3]; got shape {list(joints.shape)}")
    if contacts.shape[-1] != 4 or contacts.shape[:-1] != joints.shape[:-2]:
        raise InputError(
            f"contacts must have shape [..., T, 4] matching joints {list(joints.shape[:-2])}; got shape {list(contacts.shape)}"
        )
    feet = joints[..., list(CONTACT_JOINTS), :]
    velocity = feet[..., 1:, :, :] - feet[..., :-1, :, :]
    mask = (contacts[..., :-1, :] > threshold).to(velocity.dtype)
    return velocity * mask[..., None]


def matrix_from_cont6d(d6: torch.Tensor) -> torch.Tensor:
    """6D ``[..., 6]`` (first two matrix columns) -> rotation matrices ``[..., 3, 3]`` (Gram-Schmidt)."""
    a1, a2 = d6[..., :3], d6[..., 3:6]
    b1 = torch.nn.functional.normalize(a1, dim=-1)
    b2 = torch.nn.functional.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-1)


def matrix_to_cont6d(m: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``[..., 3, 3]`` -> 6D ``[..., 6]`` = ``[R[:, 0], R[:, 1]]``."""
    return torch.cat([m[..., :, 0], m[..., :, 1]], dim=-1)
