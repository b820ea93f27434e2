"""Foot-contact phases of a human motion, from foot height and horizontal foot speed.

See :class:`retarget.config.ContactConfig` for the thresholds and their meaning.
"""

from __future__ import annotations

import numpy as np

from motok_robot.errors import InputError
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


SUPPORT_MODES = ("off", "near", "always")


def foot_height_ratio(joints: np.ndarray, config: ContactConfig = ContactConfig()) -> np.ndarray:
    """``[T, 2]`` (left, right): how high each foot is, as the smaller of toe height / ``toe_height``
    and ankle height / ``ankle_height`` above the floor (``config.floor_height``, or the
    ``floor_percentile``-th percentile of the lowest foot joint over the clip); <= 1 is near the floor."""
    joints = np.asarray(joints, dtype=np.float64)
    foot_z = joints[:, [i for side in SIDES for i in FOOT_JOINTS[side]], 2]
    if config.floor_height is not None:
        floor = float(config.floor_height)
    else:
        floor = float(np.percentile(foot_z.min(axis=1), config.floor_percentile)) if len(joints) else 0.0
    return np.stack([np.minimum((joints[:, toe, 2] - floor) / config.toe_height,
                                (joints[:, ankle, 2] - floor) / config.ankle_height)
                     for ankle, toe in (FOOT_JOINTS[side] for side in SIDES)], axis=1)


def near_floor(joints: np.ndarray, config: ContactConfig = ContactConfig()) -> np.ndarray:
    """``[T, 2]`` bool (left, right): the toe within ``toe_height`` or the ankle within
    ``ankle_height`` of the floor -- the height half of contact detection."""
    return foot_height_ratio(joints, config) <= 1.0


def fill_support(contacts: np.ndarray, joints: np.ndarray, config: ContactConfig = ContactConfig()) -> np.ndarray:
    """``contacts[T, 2]`` with a foot planted in frames where none is (``config.support``).

    In each run of frames without contact, the eligible frames (``"near"``: a foot is near the
    floor; ``"always"``: all) get the lower foot (:func:`foot_height_ratio`) planted.  Choices
    shorter than ``min_contact_frames`` take their neighbour's foot (the phase planted right
    before or after the run counts as a neighbour), so the filled frames extend or start phases
    instead of flickering between feet.  ``"off"`` returns the mask unchanged.
    """
    if config.support not in SUPPORT_MODES:
        raise InputError(f"contact support must be one of {SUPPORT_MODES} (got {config.support!r})")
    out = np.array(contacts, dtype=bool, copy=True)
    if config.support == "off" or not len(out):
        return out
    ratio = foot_height_ratio(joints, config)
    eligible = ~out.any(axis=1)
    if config.support == "near":
        eligible &= (ratio <= 1.0).any(axis=1)
    n = max(1, int(config.min_contact_frames))
    for a, b in _runs(eligible):
        # the foot planted right before / after the run counts as a long run of that choice, so a
        # few frames that extend its phase are not "short"
        before = [int(np.argmax(out[a - 1]))] * n if a > 0 and out[a - 1].sum() == 1 else []
        after = [int(np.argmax(out[b]))] * n if b < len(out) and out[b].sum() == 1 else []
        choice = np.concatenate([before, np.argmin(ratio[a:b], axis=1), after]).astype(int)
        _merge_short(choice, n)
        out[np.arange(a, b), choice[len(before):len(choice) - len(after)]] = True
    return out


def ensure_double_support(contacts: np.ndarray, frames: int, min_swing: int = 1) -> np.ndarray:
    """``contacts[T, 2]`` where, at every touch-down of one foot while the other is planted, the
    other foot stays planted for at least ``frames`` frames from the touch-down (its lift-off is
    delayed, keeping ``min_swing`` swing frames before its next contact), so the weight moves
    from foot to foot during a double-support phase.  ``frames`` <= 0 returns the mask unchanged."""
    out = np.array(contacts, dtype=bool, copy=True)
    T = len(out)
    if frames <= 0 or T == 0:
        return out
    for side in range(2):
        other = 1 - side
        for a, _ in contact_phases(contacts[:, side]):
            if a == 0 or not contacts[a - 1, other]:
                continue  # not a hand-over from the other foot
            end = a - 1
            while end < T and contacts[end, other]:
                end += 1  # the other foot's phase ends (exclusive) at ``end``
            nxt = end
            while nxt < T and not contacts[nxt, other]:
                nxt += 1
            stop = min(a + frames, T, nxt - max(1, min_swing) if nxt < T else T)
            if stop > end:
                out[end:stop, other] = True
    return out


def _merge_short(choice: np.ndarray, min_len: int) -> None:
    """In place: runs of equal values in ``choice`` shorter than ``min_len`` take the value of the
    longer neighbouring run (the only run stays as it is)."""
    while True:
        edges = np.flatnonzero(np.diff(choice)) + 1
        starts, stops = np.r_[0, edges], np.r_[edges, len(choice)]
        short = [(k, stops[k] - starts[k]) for k in range(len(starts)) if stops[k] - starts[k] < min_len]
        if len(starts) < 2 or not short:
            return
        k = min(short, key=lambda kv: kv[1])[0]
        left = stops[k - 1] - starts[k - 1] if k > 0 else -1
        right = stops[k + 1] - starts[k + 1] if k + 1 < len(starts) else -1
        choice[starts[k]:stops[k]] = choice[starts[k - 1]] if left >= right else choice[starts[k + 1]]


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
