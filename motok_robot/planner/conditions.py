"""Perception for the planners: condition containers and their encoders.

Global condition ``c_g`` -> one sequence-level feature ``M_g [B, width]``:
  * text: a frozen :class:`~motok_robot.text.TextEncoder` embedding ``[B, D]`` through a learned
    projection (two-layer MLP) to the planner width;
  * action class: a learned embedding per label (MDM's action-to-motion);
  * null: a learned vector (unconditional generation, and the "dropped" branch of
    classifier-free guidance).

Local conditions ``c_s[1:T]`` (per frame, world frame of the generated motion: z up, metres,
the body starts at the origin facing +x) -> token-aligned features ``M_s[1:N] [B, N, width]``
by a small strided 1-D conv whose total stride equals the tokenizer's downsampling:
  * root trajectory: pelvis ``(x, y)`` on the ground plane and optionally its height ``z``,
    each with a per-frame mask;
  * any joint positions ``[T, 22, 3]`` with a per-frame, per-joint mask.
Token windows without any given value get exactly zero (the planner sees "no constraint").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import nn

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import NUM_JOINTS
from motok_robot.planner.config import ControlConfig

LOCAL_CHANNELS = 3 + 3 + NUM_JOINTS * 3 + NUM_JOINTS  # root xyz, root mask, joints, joint mask


@dataclass
class LocalConditions:
    """Per-frame kinematic targets (batched). All positions: metres, z-up world frame.

    Attributes:
        root: ``[B, T, 3]`` pelvis x, y (ground plane) and z (height).
        root_mask: ``[B, T, 3]`` 1 where the corresponding root coordinate is given, else 0.
        joints: ``[B, T, 22, 3]`` joint positions (canonical joint order).
        joint_mask: ``[B, T, 22]`` 1 where the joint's position is given on that frame.
    """

    root: torch.Tensor
    root_mask: torch.Tensor
    joints: torch.Tensor
    joint_mask: torch.Tensor

    @property
    def frames(self) -> int:
        return self.root.shape[1]

    @property
    def batch_size(self) -> int:
        return self.root.shape[0]

    @classmethod
    def empty(cls, batch: int, frames: int, device: str | torch.device = "cpu") -> "LocalConditions":
        z = torch.zeros
        return cls(z(batch, frames, 3, device=device), z(batch, frames, 3, device=device),
                   z(batch, frames, NUM_JOINTS, 3, device=device), z(batch, frames, NUM_JOINTS, device=device))

    @classmethod
    def from_arrays(
        cls,
        frames: int,
        trajectory: np.ndarray | None = None,
        joints: np.ndarray | None = None,
        joint_mask: np.ndarray | None = None,
    ) -> "LocalConditions":
        """One sample (``B = 1``) from numpy arrays, validated.

        Args:
            frames: T, the number of motion frames.
            trajectory: ``[T, 2]`` root x, y or ``[T, 3]`` root x, y, height (metres); NaN = not given.
            joints: ``[T, 22, 3]`` joint targets (metres); NaN entries = not given.
            joint_mask: ``[T, 22]`` bool/0-1, which joints are given (default: where ``joints`` is finite).
        """
        out = cls.empty(1, frames)
        if trajectory is not None:
            traj = np.asarray(trajectory, dtype=np.float64)
            if traj.ndim != 2 or traj.shape[1] not in (2, 3):
                raise InputError(f"trajectory must be [T, 2] or [T, 3] (x, y[, height]) metres, got {traj.shape}")
            if traj.shape[0] != frames:
                raise InputError(f"trajectory has {traj.shape[0]} frames, the motion has {frames}")
            given = np.isfinite(traj)
            c = traj.shape[1]
            out.root[0, :, :c] = torch.from_numpy(np.where(given, traj, 0.0)).float()
            out.root_mask[0, :, :c] = torch.from_numpy(given).float()
        if joints is not None:
            j = np.asarray(joints, dtype=np.float64)
            if j.shape != (frames, NUM_JOINTS, 3):
                raise InputError(f"joint targets must be [{frames}, {NUM_JOINTS}, 3] metres, got {j.shape}")
            given = np.isfinite(j).all(-1)
            if joint_mask is not None:
                m = np.asarray(joint_mask).astype(bool)
                if m.shape != (frames, NUM_JOINTS):
                    raise InputError(f"joint_mask must be [{frames}, {NUM_JOINTS}], got {m.shape}")
                bad = m & ~given
                if bad.any():
                    f, jj = np.argwhere(bad)[0]
                    raise InputError(f"joint target frame {f}, joint {jj} is masked in but not finite")
                given = m
            out.joints[0] = torch.from_numpy(np.where(given[..., None], np.nan_to_num(j), 0.0)).float()
            out.joint_mask[0] = torch.from_numpy(given).float()
        return out

    def to(self, device) -> "LocalConditions":
        return LocalConditions(*(t.to(device) for t in (self.root, self.root_mask, self.joints, self.joint_mask)))

    def fit_frames(self, frames: int) -> "LocalConditions":
        """Pad with "not given" frames (or raise if longer) to exactly ``frames`` frames."""
        t = self.frames
        if t == frames:
            return self
        if t > frames:
            raise InputError(f"local conditions have {t} frames, more than the {frames} frames being planned")
        pad = frames - t

        def grow(x: torch.Tensor) -> torch.Tensor:
            return torch.cat([x, x.new_zeros((x.shape[0], pad) + tuple(x.shape[2:]))], dim=1)

        return LocalConditions(grow(self.root), grow(self.root_mask), grow(self.joints), grow(self.joint_mask))

    def channels(self) -> torch.Tensor:
        """``[B, LOCAL_CHANNELS, T]`` masked values followed by masks (conv input layout)."""
        b, t = self.root.shape[:2]
        parts = [
            self.root * self.root_mask,
            self.root_mask,
            (self.joints * self.joint_mask[..., None]).reshape(b, t, -1),
            self.joint_mask,
        ]
        return torch.cat(parts, dim=-1).transpose(1, 2).float()

    def any_given(self) -> torch.Tensor:
        """``[B, T]`` bool: some value is given on that frame."""
        return (self.root_mask.sum(-1) + self.joint_mask.sum(-1)) > 0


@dataclass
class Conditions:
    """Everything a planner conditions on, for a batch of B samples.

    Attributes:
        text_embedding: ``[B, D]`` text-encoder embeddings, or None.
        text_present: ``[B]`` bool, which rows of ``text_embedding`` are real (default: all).
        action: ``[B]`` int64 action-label index (``-1`` = none), or None. An action wins over text.
        local: per-frame local conditions, or None.
    Samples with neither text nor action use the null condition.
    """

    text_embedding: torch.Tensor | None = None
    text_present: torch.Tensor | None = None
    action: torch.Tensor | None = None
    local: LocalConditions | None = None
    batch: int | None = None

    @property
    def batch_size(self) -> int:
        for t in (self.text_embedding, self.action):
            if t is not None:
                return t.shape[0]
        if self.local is not None:
            return self.local.batch_size
        if self.batch is None:
            raise InputError("Conditions: give batch= for an unconditional batch without local conditions")
        return self.batch

    def without_global(self) -> "Conditions":
        """The same local conditions with the null global condition (CFG's unconditional branch)."""
        return Conditions(local=self.local, batch=self.batch_size)

    def select(self, index: torch.Tensor) -> "Conditions":
        """Rows ``index`` of every tensor."""
        local = None
        if self.local is not None:
            local = LocalConditions(*(t[index] for t in (self.local.root, self.local.root_mask,
                                                          self.local.joints, self.local.joint_mask)))
        pick = (lambda t: None if t is None else t[index])
        return replace(self, text_embedding=pick(self.text_embedding), text_present=pick(self.text_present),
                       action=pick(self.action), local=local, batch=int(index.numel()))

    def to(self, device) -> "Conditions":
        mv = (lambda t: None if t is None else t.to(device))
        return replace(self, text_embedding=mv(self.text_embedding), text_present=mv(self.text_present),
                       action=mv(self.action), local=None if self.local is None else self.local.to(device))


class GlobalConditionEncoder(nn.Module):
    """Text embedding / action label / null -> ``M_g [B, width]``."""

    def __init__(self, text_dim: int, width: int, n_actions: int) -> None:
        super().__init__()
        self.text_projection = nn.Sequential(nn.Linear(text_dim, width), nn.GELU(), nn.Linear(width, width))
        self.action_embedding = nn.Embedding(max(1, n_actions), width)
        self.null = nn.Parameter(torch.randn(width) * 0.02)
        self.n_actions = n_actions
        self.text_dim = text_dim

    def forward(self, cond: Conditions, drop: torch.Tensor | None = None) -> torch.Tensor:
        """``drop`` ``[B]`` bool replaces the global condition of those samples by the null one."""
        b = cond.batch_size
        device = self.null.device
        out = self.null.expand(b, -1).clone()
        if cond.text_embedding is not None:
            emb = cond.text_embedding.to(device, torch.float32)
            if emb.shape != (b, self.text_dim):
                raise InputError(f"text embedding has shape {tuple(emb.shape)}, the planner expects "
                                 f"[{b}, {self.text_dim}] (was it trained with another text encoder?)")
            present = torch.ones(b, dtype=torch.bool, device=device) if cond.text_present is None \
                else cond.text_present.to(device).bool()
            out = torch.where(present[:, None], self.text_projection(emb), out)
        if cond.action is not None:
            action = cond.action.to(device).long()
            if int(action.max()) >= self.n_actions:
                raise InputError(f"action index {int(action.max())} out of range (the planner knows {self.n_actions} labels)")
            has = action >= 0
            out = torch.where(has[:, None], self.action_embedding(action.clamp_min(0)), out)
        if drop is not None:
            out = torch.where(drop.to(device)[:, None], self.null.expand(b, -1), out)
        return out


class LocalConditionEncoder(nn.Module):
    """Per-frame local conditions ``[B, T, ...]`` -> token-aligned ``M_s [B, T / downsample, width]``.

    A 3-tap conv, then stride-2 convs (one per factor 2 of ``downsample``; a single conv of
    stride ``downsample`` otherwise), then a zero-initialised 1x1 output conv so that an untrained
    control path leaves the planner unchanged.
    """

    def __init__(self, downsample: int, width: int, hidden: int) -> None:
        super().__init__()
        self.downsample = downsample
        layers: list[nn.Module] = [nn.Conv1d(LOCAL_CHANNELS, hidden, 3, padding=1), nn.GELU()]
        if downsample & (downsample - 1) == 0:
            for _ in range(int(math.log2(downsample))):
                layers += [nn.Conv1d(hidden, hidden, 4, stride=2, padding=1), nn.GELU()]
        else:
            layers += [nn.Conv1d(hidden, hidden, downsample, stride=downsample), nn.GELU()]
        self.net = nn.Sequential(*layers)
        self.out = nn.Conv1d(hidden, width, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, local: LocalConditions, n_tokens: int) -> torch.Tensor:
        frames = n_tokens * self.downsample
        local = local.fit_frames(frames)
        x = self.out(self.net(local.channels().to(self.out.weight.device)))  # [B, width, N]
        given = local.any_given().to(x.device).float().reshape(x.shape[0], n_tokens, self.downsample).amax(-1)
        return x.transpose(1, 2) * given[..., None]


def random_local_conditions(
    joints: np.ndarray, control: ControlConfig, rng: np.random.Generator
) -> LocalConditions:
    """Coarse control for training: one random local condition derived from ground-truth joints.

    Args:
        joints: ``[T, 22, 3]`` metres, z up, the clip's joints in the frame of the generated motion
            (as ``joints_from_features`` returns them).
        control: the mode probabilities.
        rng: numpy generator (seeded by the trainer).
    Returns:
        ``LocalConditions`` with ``B = 1`` and T frames (possibly all "not given").
    """
    t = joints.shape[0]
    out = LocalConditions.empty(1, t)
    probs = np.array([control.none_prob, control.root_prob, control.joints_prob, control.keyframes_prob], dtype=float)
    if probs.sum() <= 0:
        return out
    mode = rng.choice(4, p=probs / probs.sum())
    j = torch.from_numpy(np.ascontiguousarray(joints, dtype=np.float32))
    if mode == 1:  # root trajectory on the ground, optionally height
        out.root[0] = j[:, 0, :]
        out.root_mask[0, :, :2] = 1.0
        if rng.random() < control.height_prob:
            out.root_mask[0, :, 2] = 1.0
    elif mode == 2:  # a few random joints on every frame
        k = int(rng.integers(1, control.max_random_joints + 1))
        chosen = rng.choice(NUM_JOINTS, size=k, replace=False)
        out.joints[0] = j
        out.joint_mask[0, :, chosen] = 1.0
    elif mode == 3:  # sparse keyframes of random joints (all joints with probability 1/2)
        k = int(rng.integers(1, min(control.max_keyframes, t) + 1))
        frames = rng.choice(t, size=k, replace=False)
        out.joints[0] = j
        if rng.random() < 0.5:
            out.joint_mask[0, frames, :] = 1.0
        else:
            n = int(rng.integers(1, control.max_random_joints + 1))
            chosen = rng.choice(NUM_JOINTS, size=n, replace=False)
            for f in frames:
                out.joint_mask[0, f, chosen] = 1.0
    return out


def stack_local(items: list[LocalConditions]) -> LocalConditions:
    """Concatenate B=1 local conditions of equal length along the batch axis."""
    return LocalConditions(*(torch.cat([getattr(i, name) for i in items]) for name in
                             ("root", "root_mask", "joints", "joint_mask")))
