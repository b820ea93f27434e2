"""Constraint enforcement inside the MoTok decoder's DDIM loop (the "fine" path of control).

Each mechanism is a hook for :func:`motok_robot.tokenizer.sampler.ddim_sample` (protocol in
that module): it sees the current noisy motion ``x_t`` and the clean estimate ``x0_hat`` in
the decoder's model space and edits them. All of them can be combined (applied in the order
given) on the same decoder:

* :class:`Refinement` (MoTok): ``x0 <- x0 - lr * grad L_ctrl(joints(x0))`` for a few Adam
  iterations per step and many at the last, clean step, with joints recovered by the
  differentiable :func:`~motok_robot.motion.features_torch.joints_from_features`.
* :class:`GMDGuidance` (Karunratanakul et al. 2023): imputation of the root trajectory in the
  original feature space followed by re-projection, and dense guidance through the denoiser
  for the rest, ``x_t <- x_t - (1 - M) s Sigma_t grad_{x_t} G(P f(x_t))``, where ``M`` masks the
  imputed root dimensions (only applied per dimension without emphasis projection, where
  dimensions mix).
* :class:`Inpainting` (MDM): overwrite the known part of ``x0_hat`` at every step: prefix and
  suffix frames (temporal), the root trajectory and kept joints' feature dimensions (spatial).
"""

from __future__ import annotations

import torch

from motok_robot.control.config import ControlConfig
from motok_robot.control.constraints import Constraints
from motok_robot.control.losses import ConstraintTensors, control_loss
from motok_robot.motion.features_torch import joints_from_features, root_from_features

ROOT_DIMS = slice(0, 4)


def joint_feature_dims(joint: int) -> list[int]:
    """Feature dimensions that describe joint ``joint`` (root: dims 0-3 and its velocity)."""
    if joint == 0:
        return [0, 1, 2, 3, 193, 194, 195]
    ric = list(range(4 + (joint - 1) * 3, 4 + joint * 3))
    rot = list(range(67 + (joint - 1) * 6, 67 + joint * 6))
    vel = list(range(193 + joint * 3, 196 + joint * 3))
    return ric + rot + vel


def with_root(features: torch.Tensor, root: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """Features whose root trajectory is ``root [..., T, 3]`` (z up) with heading ``yaw [..., T]``.

    Inverse of :func:`root_from_features` for dims 1-3 (planar velocity in the root frame and
    height); the body's ric heights move with the root height. The root angular velocity
    (dim 0) is kept, so ``yaw`` must be the features' own heading. Frame 0's ground position is
    the origin by construction of the representation.
    """
    a = -yaw
    old_root, _ = root_from_features(features)
    wx = root[..., 1:, 1] - root[..., :-1, 1]  # HumanML3D x = project y (left)
    wz = root[..., 1:, 0] - root[..., :-1, 0]  # HumanML3D z = project x (forward)
    c, s = torch.cos(a[..., 1:]), torch.sin(a[..., 1:])
    out = features.clone()
    out[..., :-1, 1] = c * wx + s * wz
    out[..., :-1, 2] = -s * wx + c * wz
    out[..., 3] = root[..., 2]
    # ric heights are absolute: shift the body with the pelvis height
    dz = (root[..., 2] - old_root[..., 2])[..., None]
    ric_y = [4 + 3 * k + 1 for k in range(21)]
    out[..., ric_y] = out[..., ric_y] + dz
    return out


def interpolate_known(values: torch.Tensor, known: torch.Tensor) -> torch.Tensor:
    """``values [B, T]`` given where ``known [T]`` (bool) is true, linearly interpolated in between
    and held constant before the first / after the last known frame; zeros when none is known."""
    T = values.shape[-1]
    idx = torch.nonzero(known).squeeze(-1)
    if idx.numel() == 0:
        return torch.zeros_like(values)
    t = torch.arange(T, device=values.device)
    pos = torch.searchsorted(idx, t)
    hi = idx[pos.clamp(max=idx.numel() - 1)]
    lo = idx[(pos - 1).clamp(min=0)]
    lo = torch.where(pos == 0, hi, lo)
    a = ((t - lo).to(values.dtype) / (hi - lo).clamp(min=1).to(values.dtype)).clamp(0.0, 1.0)
    return values[..., lo] + (values[..., hi] - values[..., lo]) * a


def impute_root(features: torch.Tensor, ct: ConstraintTensors) -> torch.Tensor:
    """Put the constrained root positions of ``ct`` into raw ``features [B, T, 263]``.

    The residual (target - current root) at the constrained frames is interpolated linearly
    over the free frames and added to the whole path, so constrained frames are met exactly and
    sparse waypoints do not leave jumps next to them. Frame 0's ground position is the origin
    by construction of the features, so its planar residual is 0.
    """
    root, yaw = root_from_features(features)
    w = ct.weight[:, 0, :] > 0  # [T, 3]
    if not bool(w.any()):
        return features
    residual = (ct.targets[:, 0, :] - root) * w  # [B, T, 3]
    new_root = root.clone()
    for d in range(3):
        known = w[:, d].clone()
        values = residual[..., d]
        if d < 2:  # planar: frame 0 stays at the origin
            known[0] = True
            values = values.clone()
            values[:, 0] = 0.0
        if bool(w[:, d].any()):
            new_root[..., d] = root[..., d] + interpolate_known(values, known)
    return with_root(features, new_root, yaw)


class _Hook:
    def __init__(self, constraints: Constraints, config: ControlConfig, device, dtype):
        self.constraints = constraints
        self.config = config
        self.ct = ConstraintTensors.from_constraints(constraints, device, dtype)

    def loss(self, features: torch.Tensor) -> torch.Tensor:
        joints = joints_from_features(features)
        return control_loss(joints, self.ct, self.config.obstacle_weight, self.config.foot_weight, self.config.bone_weight)


class Refinement(_Hook):
    """MoTok: gradient refinement of the clean estimate at every denoising step."""

    def step(self, state) -> None:
        iters = self.config.refine_final_iters if state.t_prev < 0 else self.config.refine_iters
        if iters <= 0:
            return
        x0 = state.x0_hat.detach().clone().requires_grad_(True)
        optimiser = torch.optim.Adam([x0], lr=self.config.refine_lr)
        with torch.enable_grad():
            for _ in range(iters):
                loss = self.loss(state.to_features(x0)).sum()
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
        state.x0_hat = x0.detach()


class GMDGuidance(_Hook):
    """GMD: root imputation in the original space + dense guidance through the denoiser."""

    def step(self, state) -> None:
        if self.config.gmd_scale > 0:
            with torch.enable_grad():
                x = state.x_t.detach().clone().requires_grad_(True)
                loss = self.loss(state.to_features(state.denoise(x))).sum()
                (grad,) = torch.autograd.grad(loss, x)
            if state.projection is None and self.config.gmd_impute:
                grad = grad * (1.0 - self._root_mask(grad))
            variance = 1.0 - state.alpha_bar
            state.x_t = (x - self.config.gmd_scale * variance * grad).detach()
            with torch.no_grad():
                state.x0_hat = state.denoise(state.x_t)
        if self.config.gmd_impute and self.constraints.has_root_trajectory:
            with torch.no_grad():
                state.x0_hat = state.from_features(impute_root(state.to_features(state.x0_hat), self.ct))

    def _root_mask(self, like: torch.Tensor) -> torch.Tensor:
        mask = torch.zeros_like(like)
        frames = self.ct.weight[:, 0, :2].any(dim=-1)
        mask[:, frames, ROOT_DIMS] = 1.0
        return mask


class Inpainting(_Hook):
    """MDM: overwrite the known part of the clean estimate at every step."""

    def __init__(self, constraints: Constraints, config: ControlConfig, device, dtype):
        super().__init__(constraints, config, device, dtype)
        c = constraints
        self.prefix = None if c.prefix_features is None else torch.as_tensor(c.prefix_features, device=device, dtype=dtype)
        self.suffix = None if c.suffix_features is None else torch.as_tensor(c.suffix_features, device=device, dtype=dtype)
        self.edit = None
        if c.edit_features is not None and c.edit_joints:
            dims = sorted({d for j in c.edit_joints for d in joint_feature_dims(j)})
            self.edit = (torch.as_tensor(c.edit_features, device=device, dtype=dtype), dims)

    def step(self, state) -> None:
        with torch.no_grad():
            x = state.to_features(state.x0_hat)
            x = overwrite_known(x, self.prefix, self.suffix, self.edit)
            if self.constraints.has_root_trajectory and self.edit is None:
                x = impute_root(x, self.ct)
            state.x0_hat = state.from_features(x)


def overwrite_known(x: torch.Tensor, prefix, suffix, edit) -> torch.Tensor:
    """Raw features with prefix / suffix frames and kept-joint dimensions copied in."""
    x = x.clone()
    if prefix is not None:
        x[:, : len(prefix)] = prefix
    if suffix is not None:
        x[:, x.shape[1] - len(suffix) :] = suffix
    if edit is not None:
        features, dims = edit
        x[:, :, dims] = features[: x.shape[1], dims]
    return x


def make_guidance(constraints: Constraints, config: ControlConfig, device="cpu", dtype=torch.float32):
    """The hook for ``tokenizer.decode(guidance=...)``, or None without control."""
    if constraints.is_empty or config.mechanisms in (("none",), ()):
        return None
    classes = {"motok": Refinement, "gmd": GMDGuidance, "inpaint": Inpainting}
    hooks = [classes[name](constraints, config, device, dtype) for name in config.mechanisms]

    def combined(state) -> None:
        for hook in hooks:
            hook.step(state)

    return combined
