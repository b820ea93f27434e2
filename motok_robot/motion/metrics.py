"""Joint-space motion metrics (numpy only).

Every function takes joint positions ``[..., T, 22, 3]`` in metres, z up, SMPL joint order
(:data:`motok_robot.motion.skeleton.JOINT_NAMES`), with the floor at ``z = 0``, sampled at
``fps`` Hz (20 by default). Results are plain floats (or dicts of floats) in the units named
by the function: metres, millimetres, metres per second, or a ratio in ``[0, 1]``.

* :func:`mpjpe`: mean per-joint position error, with or without aligning the roots.
* :func:`foot_skating_ratio`: the GMD / OmniControl protocol.
* :func:`foot_ground_distances`: penetration below and floating above the floor (mm).
* :func:`root_trajectory_error`: planar root path error.
* :func:`joint_speed_percentiles`: distribution of per-frame joint speeds.
* :func:`motion_summary`: the single-clip metrics above in one JSON-ready dict.
"""

from __future__ import annotations

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion import skeleton

#: GMD / OmniControl foot-skating protocol
SKATING_FOOT_JOINTS = (skeleton.JOINT_INDEX["left_foot"], skeleton.JOINT_INDEX["right_foot"])
SKATING_HEIGHT_THRESHOLD = 0.05  # m: a foot is in contact below this height (in two adjacent frames)
SKATING_SPEED_THRESHOLD = 0.5  # m/s (= 2.5 cm per frame at 20 fps), horizontal
SKATING_AVERAGE_WINDOW = 5  # frames: the speed averaged over this centred window must also exceed it
#: joints whose lowest point defines a frame's foot height for penetration / floating
FOOT_JOINTS = skeleton.FOOT_JOINTS


def _joints(x, name: str, min_frames: int = 1) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a numeric array of shape [..., T, 22, 3]: {exc}") from None
    if arr.ndim < 3 or arr.shape[-2:] != (skeleton.NUM_JOINTS, 3):
        raise InputError(f"{name} must have shape [..., T, {skeleton.NUM_JOINTS}, 3] (frames, joints, xyz metres); got shape {list(arr.shape)}")
    if arr.shape[-3] < min_frames:
        raise InputError(f"{name} has {arr.shape[-3]} frame(s); at least {min_frames} are needed")
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.argwhere(bad)[0]
        raise InputError(f"{name} contain NaN or inf at frame {idx[-3]}, joint {idx[-2]} ({skeleton.JOINT_NAMES[idx[-2]]})")
    return arr


def _pair(pred, target) -> tuple[np.ndarray, np.ndarray]:
    p = _joints(pred, "pred")
    t = _joints(target, "target")
    if p.shape != t.shape:
        raise InputError(f"pred and target must have the same shape; got {list(p.shape)} and {list(t.shape)}")
    return p, t


def _check_fps(fps: float) -> float:
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"fps must be a positive frame rate in Hz; got {fps}")
    return float(fps)


def mpjpe(pred, target, align_root: bool = False) -> float:
    """Mean per-joint position error, metres.

    Args:
        pred, target: ``[..., T, 22, 3]`` metres, same shape.
        align_root: subtract each frame's root (pelvis) position from both first, so only the
            pose is compared (the usual "root-aligned MPJPE").
    """
    p, t = _pair(pred, target)
    if align_root:
        p = p - p[..., :1, :]
        t = t - t[..., :1, :]
    return float(np.linalg.norm(p - t, axis=-1).mean())


def _centred_mean(x: np.ndarray, size: int) -> np.ndarray:
    """Mean over a centred window of ``size`` along the last axis, zeros outside the signal
    (``scipy.ndimage.uniform_filter1d(mode="constant")``)."""
    if size <= 1:
        return x.copy()
    left = size // 2
    right = size - 1 - left
    padded = np.concatenate([np.zeros(x.shape[:-1] + (left,)), x, np.zeros(x.shape[:-1] + (right,))], axis=-1)
    csum = np.concatenate([np.zeros(x.shape[:-1] + (1,)), np.cumsum(padded, axis=-1)], axis=-1)
    return (csum[..., size:] - csum[..., :-size]) / size


def foot_skating_frames(joints, fps: float = skeleton.FPS, height_threshold: float = SKATING_HEIGHT_THRESHOLD,
                        speed_threshold: float = SKATING_SPEED_THRESHOLD,
                        average_window: int = SKATING_AVERAGE_WINDOW) -> np.ndarray:
    """Per-step skating flags ``[..., T-1]`` (bool) by the GMD / OmniControl protocol.

    For the step from frame t to t+1 and each foot joint (left_foot, right_foot): the foot is
    in contact when its height is below ``height_threshold`` (m) in both frames; it skates
    when, in contact, its horizontal speed (m/s) exceeds ``speed_threshold`` both in that step
    and averaged over a centred window of ``average_window`` steps (zero padded, as GMD's
    ``uniform_filter1d(mode="constant")``; 1 disables the window). A step is flagged when
    either foot skates.
    """
    j = _joints(joints, "joints", min_frames=2)
    fps = _check_fps(fps)
    feet = j[..., list(SKATING_FOOT_JOINTS), :]  # [..., T, 2, 3]
    speed = np.linalg.norm(np.diff(feet[..., :2], axis=-3), axis=-1) * fps  # [..., T-1, 2]
    speed = np.moveaxis(speed, -1, -2)  # [..., 2, T-1]
    averaged = _centred_mean(speed, int(average_window))
    height = np.moveaxis(feet[..., 2], -1, -2)  # [..., 2, T]
    contact = (height[..., :-1] < height_threshold) & (height[..., 1:] < height_threshold)
    skating = contact & (speed > speed_threshold) & (averaged > speed_threshold)
    return skating.any(axis=-2)


def foot_skating_ratio(joints, fps: float = skeleton.FPS, **thresholds) -> float:
    """Fraction of steps (frame pairs) in which either foot skates, in ``[0, 1]``.

    See :func:`foot_skating_frames` for the protocol; keyword arguments override its
    thresholds. Averaged over every clip of a batch ``[..., T, 22, 3]``.
    """
    return float(foot_skating_frames(joints, fps, **thresholds).mean())


def foot_ground_distances(joints, float_tolerance: float = 0.005) -> dict[str, float]:
    """Feet below and above the floor (``z = 0``), millimetres.

    Per frame, the foot height is the lowest of the four foot joints (ankles and feet):

    * ``penetration_mean_mm`` / ``penetration_max_mm``: mean / max over frames of how far it
      is below the floor (0 when above);
    * ``floating_mean_mm`` / ``floating_max_mm``: mean / max over frames of how far it is
      above ``float_tolerance`` metres (0 when lower). Jumps count as floating.
    """
    j = _joints(joints, "joints")
    lowest = j[..., list(FOOT_JOINTS), 2].min(axis=-1)
    below = np.maximum(0.0, -lowest) * 1000.0
    above = np.maximum(0.0, lowest - float_tolerance) * 1000.0
    return {
        "penetration_mean_mm": float(below.mean()),
        "penetration_max_mm": float(below.max()),
        "floating_mean_mm": float(above.mean()),
        "floating_max_mm": float(above.max()),
    }


def root_trajectory_error(pred, target) -> dict[str, float]:
    """Planar (x, y) distance between the root (pelvis) paths, metres.

    Returns ``mean_m`` (over frames), ``max_m``, ``final_m`` (last frame) and ``height_mean_m``
    (mean absolute pelvis-height difference).
    """
    p, t = _pair(pred, target)
    d = np.linalg.norm(p[..., 0, :2] - t[..., 0, :2], axis=-1)
    return {
        "mean_m": float(d.mean()),
        "max_m": float(d.max()),
        "final_m": float(d[..., -1].mean()),
        "height_mean_m": float(np.abs(p[..., 0, 2] - t[..., 0, 2]).mean()),
    }


def joint_speed_percentiles(joints, fps: float = skeleton.FPS, percentiles=(50, 95, 99, 100)) -> dict[str, float]:
    """Percentiles of joint speeds over all joints and steps, m/s: ``{"p50": ..., "p95": ...}``.

    The speed of joint j in step t -> t+1 is ``|x[t+1, j] - x[t, j]| * fps``.
    """
    j = _joints(joints, "joints", min_frames=2)
    fps = _check_fps(fps)
    speed = np.linalg.norm(np.diff(j, axis=-3), axis=-1) * fps
    values = np.percentile(speed, list(percentiles))
    return {f"p{p:g}": float(v) for p, v in zip(percentiles, values)}


def motion_summary(joints, fps: float = skeleton.FPS) -> dict[str, float]:
    """Single-clip metrics in one JSON-ready dict: skating ratio, foot penetration / floating
    (mm), joint speed percentiles (m/s), duration (s) and root path length (m)."""
    j = _joints(joints, "joints", min_frames=2)
    fps = _check_fps(fps)
    out: dict[str, float] = {
        "frames": float(j.shape[-3]),
        "seconds": float((j.shape[-3] - 1) / fps),
        "root_path_m": float(np.linalg.norm(np.diff(j[..., 0, :2], axis=-2), axis=-1).sum(axis=-1).mean()),
        "foot_skating_ratio": foot_skating_ratio(j, fps),
    }
    out.update(foot_ground_distances(j))
    out.update({f"joint_speed_{k}_mps": v for k, v in joint_speed_percentiles(j, fps).items()})
    return out
