"""How far a planted foot may turn about the vertical between two frames (a pivot).

A planted robot sole keeps its site where it is and, by default, its yaw too (the no-slip
rows of :mod:`retarget.problem`). A person who spins on one foot turns that foot with the
body: in ``dataset-1_kick_normal_001`` the planted left foot turns 168 degrees in 6 frames
while the heading turns 153. A robot foot that may not turn holds the base back until its
yaw bound (heading +- ``SolverConfig.max_yaw_offset``) forces the base round in one frame,
the planted sole flipping with it.

So a planted foot may turn, between frame ``t - 1`` and ``t``, by as much as the person turns
on it: the smaller of the human foot's and the human heading's turn in that frame, where both
turn the same way and the heading turns faster than ``ContactConfig.pivot_speed``. Slower
turns (walking round a corner: at most 50 degrees/s on the Bandai walks) and a foot that
twists while the body does not (toes rolling, a dancer's swivel) keep the sole fixed. The
problem's constraint rows never let a planted sole turn a quarter turn or more in one frame,
so it cannot flip whatever these bounds are.
"""

from __future__ import annotations

import numpy as np

from retarget.config import ContactConfig

#: the largest pivot bound (rad per frame): below the quarter turn the constraint rows forbid
MAX_PIVOT_STEP = np.pi / 3


def foot_yaw(foot_dir: np.ndarray) -> np.ndarray:
    """Unwrapped yaw ``[T, 2]`` (rad) of the horizontal foot directions ``foot_dir[T, 2, 2]``."""
    d = np.asarray(foot_dir, dtype=np.float64)
    return np.unwrap(np.arctan2(d[..., 1], d[..., 0]), axis=0)


def pivot_bounds(heading: np.ndarray, foot_dir: np.ndarray, contacts: np.ndarray, fps: float,
                 config: ContactConfig = ContactConfig()) -> np.ndarray:
    """The largest yaw change (rad, ``>= 0``) of each planted sole between frame ``t - 1`` and
    ``t``, ``[T, 2]`` (left, right); 0 where the sole must keep its yaw, and in frame 0.

    ``heading[T]`` unwrapped human facing angle (rad); ``foot_dir[T, 2, 2]`` human foot
    directions; ``contacts[T, 2]`` bool; ``fps`` frames per second.
    """
    c = np.asarray(contacts, dtype=bool)
    out = np.zeros(c.shape)
    if len(c) < 2 or config.pivot_speed is None:
        return out
    turn = np.diff(np.asarray(heading, dtype=np.float64))[:, None]  # [T-1, 1]
    foot = np.diff(foot_yaw(foot_dir), axis=0)  # [T-1, 2]
    pivot = (np.abs(turn) * fps > config.pivot_speed) & (turn * foot > 0) & c[1:] & c[:-1]
    out[1:] = np.where(pivot, np.minimum(np.minimum(np.abs(turn), np.abs(foot)), MAX_PIVOT_STEP), 0.0)
    return out
