"""Controlled decoding: MoTok tokens + constraints -> raw features, constraints enforced.

``decode_with_control`` runs the tokenizer's DDIM decoder with the hooks of
:mod:`motok_robot.control.guidance` and then, for in-betweening, makes the given prefix and
suffix frames exact (:func:`exact_seams`): the free middle part absorbs the heading and root
position residual as a linear ramp, so the seams stay continuous.
"""

from __future__ import annotations

import torch

from motok_robot.control.config import ControlConfig
from motok_robot.control.constraints import Constraints
from motok_robot.control.guidance import make_guidance, overwrite_known, with_root
from motok_robot.motion.features_torch import joints_from_features, root_from_features


#: features describing the pose relative to the root (height, ric, rotations, velocities, contacts)
POSE_DIMS = slice(3, 263)


def blend_seams(x: torch.Tensor, prefix: int, suffix: int, frames: int) -> torch.Tensor:
    """Cross-fade the pose of the free frames next to a seam from the kept frame's pose.

    ``x [B, T, 263]`` raw features whose first ``prefix`` and last ``suffix`` frames are kept. The
    free frame at distance ``d`` (1 .. ``frames``) from a seam gets ``(1 - d / (frames + 1))`` of
    the kept frame's pose (:data:`POSE_DIMS`; the root path is handled separately), so the pose
    does not jump where the kept frames meet the generated ones.
    """
    T = x.shape[1]
    free = T - prefix - suffix
    if frames < 1 or free < 1:
        return x
    x = x.clone()
    n = min(frames, free)
    weight = 1.0 - torch.arange(1, n + 1, device=x.device, dtype=x.dtype) / (frames + 1)  # [n], kept pose share
    if prefix > 0:
        sl = slice(prefix, prefix + n)
        x[:, sl, POSE_DIMS] = weight[:, None] * x[:, prefix - 1 : prefix, POSE_DIMS] + (1 - weight[:, None]) * x[:, sl, POSE_DIMS]
    if suffix > 0:
        start = T - suffix
        sl = slice(start - n, start)
        w = weight.flip(0)[:, None]
        x[:, sl, POSE_DIMS] = w * x[:, start : start + 1, POSE_DIMS] + (1 - w) * x[:, sl, POSE_DIMS]
    return x


def exact_seams(features: torch.Tensor, constraints: Constraints, blend: int = 10) -> torch.Tensor:
    """Copy prefix / suffix features in and move the suffix to its target place and heading.

    ``features [B, T, 263]`` raw. The pose of the ``blend`` free frames next to each seam is
    cross-faded from the kept frames (:func:`blend_seams`). The suffix target is where the given suffix joints are
    (``constraints.joint_targets``): the heading residual at the first suffix frame is spread
    over the root angular velocity of the free frames, then the root position residual as a
    linear ramp over the same frames.
    """
    c = constraints
    if c.prefix_features is None and c.suffix_features is None:
        return features
    dtype, device = features.dtype, features.device
    prefix = None if c.prefix_features is None else torch.as_tensor(c.prefix_features, device=device, dtype=dtype)
    suffix = None if c.suffix_features is None else torch.as_tensor(c.suffix_features, device=device, dtype=dtype)
    x = overwrite_known(features, prefix, suffix, None)
    x = blend_seams(x, 0 if prefix is None else len(prefix), 0 if suffix is None else len(suffix), blend)
    if suffix is None:
        return x
    T = x.shape[1]
    start = T - len(suffix)  # first suffix frame
    free_from = len(prefix) if prefix is not None else 1
    n_free = start - free_from
    if n_free < 1:
        return x
    target = torch.as_tensor(c.joint_targets[start], device=device, dtype=dtype)  # [22, 3]
    # heading of the target suffix frame, from its hips (as the features' facing)
    def heading(j: torch.Tensor) -> torch.Tensor:
        across = (j[..., 2, :] - j[..., 1, :]) + (j[..., 17, :] - j[..., 16, :])  # right - left hips/shoulders
        forward = torch.stack([-across[..., 1], across[..., 0]], dim=-1)  # rotate (x, y) by +90 deg about z
        return torch.atan2(forward[..., 1], forward[..., 0])

    joints = joints_from_features(x)
    dyaw = heading(target) - heading(joints[:, start])
    dyaw = torch.atan2(torch.sin(dyaw), torch.cos(dyaw))  # [B]
    # yaw = -a, a_t = 2 * sum_{k < t} x[k, 0]: add -dyaw / 2 spread over frames free_from-1 .. start-2
    x = x.clone()
    x[:, free_from - 1 : start - 1, 0] += (-dyaw / 2.0 / n_free)[:, None]
    root, yaw = root_from_features(x)
    joints = joints_from_features(x)
    dpos = target[0] - joints[:, start, 0]  # [B, 3]
    dpos[:, 2] = 0.0  # pelvis height is part of the features
    ramp = torch.clamp((torch.arange(T, device=device, dtype=dtype) - (free_from - 1)) / n_free, 0.0, 1.0)
    root = root + ramp[None, :, None] * dpos[:, None, :]
    return with_root(x, root, yaw)


def decode_with_control(
    tokenizer,
    tokens: torch.Tensor,
    length: int,
    constraints: Constraints | None,
    config: ControlConfig | None = None,
    steps: int | None = None,
    seed: int = 0,
) -> torch.Tensor:
    """Decode ``tokens [B, N]`` to raw features ``[B, length, 263]`` under ``constraints``."""
    config = config or ControlConfig()
    if constraints is None:
        return tokenizer.decode(tokens, length=length, steps=steps, seed=seed)
    if constraints.frames != length:
        from motok_robot.errors import InputError

        raise InputError(f"constraints are for {constraints.frames} frames but the clip has {length}")
    guidance = make_guidance(constraints, config, device=tokenizer.device)
    features = tokenizer.decode(tokens, length=length, steps=steps, seed=seed, guidance=guidance)
    if config.exact_seams and "none" not in config.mechanisms:
        features = exact_seams(features, constraints, config.seam_blend_frames)
    return features
