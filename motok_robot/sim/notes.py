"""Notes in a validation report: what passed but is worth reading.

A joint that sits within the ``joint_limits`` check's tolerance of a limit (or beyond it) for
more than :data:`PARKED_FRACTION` of the frames is *parked* there: the motion asks for more than
the joint's range, so the trajectory holds the limit.  It is not a failure (the check counts
only samples beyond the range by more than its tolerance), but the robot does not do what the
human did with that joint; op3_like's ``head_tilt`` at its 0.6 rad limit is the common case.
``per_joint`` of report.json gets ``at_limit_ratio``, ``at_limit`` ("low", "high" or null) and
``at_limit_rad``; ``notes`` one line per parked joint, which the summary prints.
"""

from __future__ import annotations

import numpy as np

#: a joint within the joint_limits check's tolerance of a limit for more than this fraction of the
#: frames is "parked" there and gets a note (:func:`joint_limit_notes`)
PARKED_FRACTION = 0.5


def at_limit_fields(angle: np.ndarray, low: float, high: float, tolerance: float) -> dict:
    """``per_joint`` fields: the fraction of frames within ``tolerance`` of a limit or beyond it
    (``at_limit_ratio``), which limit (``at_limit``: "low", "high" or None) and its value."""
    near_low, near_high = angle <= low + tolerance, angle >= high - tolerance
    count_low, count_high = int(near_low.sum()), int(near_high.sum())
    side = None if count_low + count_high == 0 else "low" if count_low >= count_high else "high"
    return {"at_limit_ratio": float((near_low | near_high).mean()) if len(angle) else 0.0, "at_limit": side,
            "at_limit_rad": None if side is None else float(low if side == "low" else high)}


def joint_limit_notes(per_joint: dict, tolerance_rad: float) -> list[str]:
    """One note per joint parked at a limit (``at_limit_ratio`` above :data:`PARKED_FRACTION`):
    the motion asks for more than the joint's range, so it holds the limit (not a failure: the
    joint_limits check counts only samples beyond the range by more than its tolerance,
    ``tolerance_rad``, which ``at_limit_ratio`` was measured with)."""
    notes = []
    for name, entry in per_joint.items():
        ratio = entry.get("at_limit_ratio") or 0.0
        if ratio <= PARKED_FRACTION or entry.get("at_limit") is None:
            continue
        what = "the head" if name.startswith("head") or name.startswith("neck") else "the joint"
        notes.append(f"{name} is at its {entry['at_limit']} limit ({entry['at_limit_rad']:+.2f} rad, within "
                     f"{tolerance_rad:g} rad) in {ratio:.0%} of the frames: the motion asks for more than {what} can "
                     "turn, so it holds the limit there")
    return notes
