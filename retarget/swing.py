"""Swing-foot clearance profile: how high every sole corner must be above the ground, per frame.

See :class:`retarget.config.SwingConfig` for the meaning of the settings. The profile is a
lower bound on the sole corner heights (rows that exist in every window problem already),
so it changes constraint bounds only and needs no rebuild of the IPOPT problem.
"""

from __future__ import annotations

import numpy as np

from retarget.config import SwingConfig
from retarget.contacts import contact_phases


def swing_clearance(contacts: np.ndarray, fps: float, config: SwingConfig = SwingConfig()) -> np.ndarray:
    """Minimum height (m above the ground) of all sole corners, ``[T, 2]`` (left, right).

    ``contacts[T, 2]`` bool contact mask; ``fps`` frames per second. Contact frames get 0 (their
    corners are held *at* the ground by the contact constraints). A swing frame ``d`` frames
    from the nearest contact frame (``d = 1`` next to it) gets
    ``lift + (height - lift) * smoothstep((d - 1) / ramp)`` metres, ``ramp = ramp_seconds * fps``
    frames (at least 1). Only
    contact phases inside the clip count: a clip that starts or ends in swing has no ramp there,
    and a foot that never touches the ground while the other one does (a one-legged stance, a
    kick) is held ``height`` up throughout.  A clip in which neither foot touches gets no clearance.
    """
    c = np.asarray(contacts, dtype=bool)
    T = len(c)
    out = np.zeros((T, 2))
    if config.height <= 0 or T == 0:
        return out
    ramp = max(1.0, float(config.ramp_seconds) * float(fps))
    lift, height = min(config.lift, config.height), config.height
    for s in range(2):
        for a, b in contact_phases(~c[:, s]):  # swing runs [a, b)
            if a == 0 and b == T and not c[:, 1 - s].any():
                continue  # neither foot ever touches the ground: nothing to clear
            t = np.arange(a, b)
            d = np.minimum(t - a + 1 if a > 0 else np.full(len(t), np.inf), b - t if b < T else np.full(len(t), np.inf))
            u = np.clip((d - 1.0) / ramp, 0.0, 1.0)
            out[a:b, s] = lift + (height - lift) * (u * u * (3.0 - 2.0 * u))
    return out


def transition_frames(contacts: np.ndarray) -> np.ndarray:
    """``[T, 2]`` bool: swing frames next to a contact frame (the frame after lift-off and the
    frame before touch-down) where the sole is held flat."""
    c = np.asarray(contacts, dtype=bool)
    out = np.zeros_like(c)
    if len(c) < 2:
        return out
    out[1:] |= ~c[1:] & c[:-1]
    out[:-1] |= ~c[:-1] & c[1:]
    return out
