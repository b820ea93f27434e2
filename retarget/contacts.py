"""Foot-contact phases of a human motion, from foot height and horizontal foot speed.

See :class:`retarget.config.ContactConfig` for the thresholds and their meaning.
"""

from __future__ import annotations

import numpy as np

from motok_robot.motion.skeleton import JOINT_INDEX
from retarget.config import ContactConfig

FOOT_JOINTS = {
    "left": (JOINT_INDEX["left_ankle"], JOINT_INDEX["left_foot"]),
    "right": (JOINT_INDEX["right_ankle"], JOINT_INDEX["right_foot"]),
}
SIDES = ("left", "right")


def _horizontal_speed(p: np.ndarray, fps: float) -> np.ndarray:
    """Central-difference horizontal speed (m/s) of ``p[T, 3]`` -> ``[T]``."""
    if len(p) < 2:
        return np.zeros(len(p))
    v = np.gradient(p[:, :2], axis=0) * fps
    return np.linalg.norm(v, axis=1)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` half-open runs of True in a 1-D bool array."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.diff(m.astype(int))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def contact_phases(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open frame ranges ``(start, stop)`` of the contact phases in ``mask[T]``."""
    return [(int(a), int(b)) for a, b in _runs(np.asarray(mask, dtype=bool))]


def near_floor(joints: np.ndarray, config: ContactConfig = ContactConfig()) -> np.ndarray:
    """``[T, 2]`` bool (left, right): the toe within ``toe_height`` or the ankle within
    ``ankle_height`` of the floor (``config.floor_height``, or the ``floor_percentile``-th
    percentile of the lowest foot joint over the clip) -- the height half of contact detection."""
    joints = np.asarray(joints, dtype=np.float64)
    foot_z = joints[:, [i for side in SIDES for i in FOOT_JOINTS[side]], 2]
    if config.floor_height is not None:
        floor = float(config.floor_height)
    else:
        floor = float(np.percentile(foot_z.min(axis=1), config.floor_percentile)) if len(joints) else 0.0
    return np.stack([(joints[:, toe, 2] - floor <= config.toe_height) | (joints[:, ankle, 2] - floor <= config.ankle_height)
                     for ankle, toe in (FOOT_JOINTS[side] for side in SIDES)], axis=1)


def detect_contacts(joints: np.ndarray, fps: float, config: ContactConfig = ContactConfig()) -> np.ndarray:
    """Contact mask ``[T, 2]`` (bool; columns left, right) of ``joints[T, 22, 3]`` (metres, z up)."""
    joints = np.asarray(joints, dtype=np.float64)
    T = joints.shape[0]
    near = near_floor(joints, config)
    out = np.zeros((T, 2), dtype=bool)
    for col, side in enumerate(SIDES):
        ankle, toe = FOOT_JOINTS[side]
        speed = np.minimum(_horizontal_speed(joints[:, ankle], fps), _horizontal_speed(joints[:, toe], fps))
        state = False
        for t in range(T):
            limit = config.exit_speed if state else config.enter_speed
            state = bool(near[t, col] and speed[t] <= limit)
            out[t, col] = state
        out[:, col] = _clean(out[:, col], config.min_contact_frames, config.min_swing_frames)
    return out


def _clean(mask: np.ndarray, min_contact: int, min_swing: int) -> np.ndarray:
    mask = mask.copy()
    # fill short swing gaps between two contacts
    for a, b in _runs(~mask):
        if a > 0 and b < len(mask) and b - a < min_swing:
            mask[a:b] = True
    # drop short contacts
    for a, b in _runs(mask):
        if b - a < min_contact:
            mask[a:b] = False
    return mask
