"""Longer double support: the motion slowed around each transfer of support between the feet.

A human walk moves its weight from one foot to the other in 0.05-0.1 s of double support (one
or two 20 fps frames in retargeted Bandai walks).  A small servo robot cannot move its centre
of mass across in that time, so it ends up leaning past the new stance foot.  This module
plays every double-support phase shorter than ``min_seconds`` slower, from the frame before
to the frame after it, until it lasts ``min_seconds``; the rest of the clip keeps its timing.
The footsteps and poses are unchanged; the clip gets longer by the added time, recorded as a
time warp (``retime_factor``).
"""

from __future__ import annotations

import numpy as np


def double_support_phases(contacts: np.ndarray) -> list[tuple[int, int]]:
    """``(i, j)`` of every run of frames i .. j with both feet down that has a frame with one
    foot down right before and right after it (a transfer of support, or a pause in a step)."""
    both = np.asarray(contacts, dtype=bool).all(axis=1)
    single = np.asarray(contacts, dtype=bool).sum(axis=1) == 1
    phases, t, T = [], 0, both.size
    while t < T:
        if both[t]:
            j = t
            while j + 1 < T and both[j + 1]:
                j += 1
            if t > 0 and j + 1 < T and single[t - 1] and single[j + 1]:
                phases.append((t, j))
            t = j + 1
        else:
            t += 1
    return phases


def stretched_times(contacts: np.ndarray, fps: float, min_seconds: float) -> tuple[np.ndarray, int]:
    """Original times (s) of the frames of the stretched clip, and how many phases were stretched."""
    T = contacts.shape[0]
    step = np.full(max(T - 1, 0), 1.0 / fps)  # new duration of each original frame interval
    count = 0
    for i, j in double_support_phases(contacts):
        have = (j - i + 1) / fps
        if have >= min_seconds:
            continue
        window = np.arange(i - 1, j + 1)  # intervals from the frame before to the frame after
        step[window] *= (window.size / fps + (min_seconds - have)) / (window.size / fps)
        count += 1
    new_end = np.r_[0.0, np.cumsum(step)]
    n = int(np.floor(new_end[-1] * fps + 1e-9)) + 1
    old = np.interp(np.arange(n) / fps, new_end, np.arange(T) / fps)
    return old, count
