"""Uniform time scaling of a robot trajectory: the same path, played ``factor`` times slower.

Retargeting follows the human's timing and may use up to 0.98 of the servo velocity limit, so a
brisk gesture can ask a joint for more torque than the servo has (docs/validation.md,
``torque``).  The inertial part of the required torque scales with ``1 / factor^2`` and the
joint speeds with ``1 / factor``; gravity does not change.  Playing the motion slower is then
the honest fix: the robot performs the same motion, it takes longer.  The pipeline uses
:func:`retime` when only the speed checks fail (``motok_robot.pipeline``, ``max_retime``).

Resampling at the same frame rate: ``n = round((T - 1) x factor) + 1`` frames at original
times ``t / factor``.  Joint angles, base position, keypoint errors and the human source are
interpolated linearly; the base quaternion linearly then normalised (consecutive 20 fps
frames are close and robot.npz quaternions are sign-continuous); contacts take the nearest
original frame.  ``retime_factor`` accumulates (robot.npz, docs/CONTRACTS.md).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from motok_robot.errors import InputError

from .io import RobotTrajectory


def _resample(values: np.ndarray, t_old: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``values`` [T, ...] from ``t_old`` to ``t_new`` along axis 0."""
    flat = values.reshape(values.shape[0], -1).astype(np.float64)
    out = np.stack([np.interp(t_new, t_old, flat[:, k]) for k in range(flat.shape[1])], axis=1)
    return out.reshape((len(t_new),) + values.shape[1:])


def retime(trajectory: RobotTrajectory, factor: float) -> RobotTrajectory:
    """``trajectory`` played ``factor`` (>= 1) times slower, at the same frame rate."""
    if not (math.isfinite(factor) and factor >= 1.0):
        raise InputError(f"retime: factor must be a number >= 1 (slower), got {factor}")
    T = trajectory.qpos.shape[0]
    if factor == 1.0 or T < 2:
        return replace(trajectory)
    fps = float(trajectory.fps)
    t_old = np.arange(T) / fps
    n = int(round((T - 1) * factor)) + 1
    t_new = np.minimum(np.arange(n) / (fps * factor), t_old[-1])
    qpos = _resample(trajectory.qpos, t_old, t_new)
    if qpos.shape[1] >= 7:  # free base: normalise the interpolated quaternion
        qpos[:, 3:7] /= np.linalg.norm(qpos[:, 3:7], axis=1, keepdims=True)
    nearest = np.clip(np.round(t_new * fps).astype(int), 0, T - 1)
    return replace(
        trajectory, qpos=qpos, contacts=np.asarray(trajectory.contacts)[nearest],
        keypoint_error=_resample(np.asarray(trajectory.keypoint_error), t_old, t_new),
        source=_resample(np.asarray(trajectory.source), t_old, t_new).astype(np.float32),
        retime_factor=float(trajectory.retime_factor) * float(factor))


def hold_ends(trajectory: RobotTrajectory, before: int, after: int) -> RobotTrajectory:
    """``trajectory`` with its first frame held for ``before`` extra frames and its last for
    ``after``: time for a robot to shift its weight before its first step, and to bring its feet
    together after the last."""
    T = trajectory.qpos.shape[0]
    before, after = max(0, int(before)), max(0, int(after))
    if before == 0 and after == 0:
        return replace(trajectory)
    return hold_frames(trajectory, np.r_[np.zeros(before, dtype=int), np.arange(T), np.full(after, T - 1, dtype=int)])


def hold_frames(trajectory: RobotTrajectory, frames: np.ndarray) -> RobotTrajectory:
    """``trajectory`` played through the frame indices ``frames`` (non-decreasing, each frame
    at least once): a repeated index holds that pose, a pause in the motion that does not
    change its speed (``retime_factor`` stays)."""
    frames = np.asarray(frames, dtype=int)
    T = trajectory.qpos.shape[0]
    if frames.ndim != 1 or (frames.size and (frames[0] != 0 or frames[-1] != T - 1
                                             or np.any(~np.isin(np.diff(frames), (0, 1))))):
        raise ValueError("hold_frames: frames must run from 0 to the last frame in steps of 0 or 1")
    return replace(
        trajectory, qpos=np.asarray(trajectory.qpos)[frames], contacts=np.asarray(trajectory.contacts)[frames],
        keypoint_error=np.asarray(trajectory.keypoint_error)[frames], source=np.asarray(trajectory.source)[frames])
