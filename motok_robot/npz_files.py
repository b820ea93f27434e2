"""Reading the project's ``.npz`` files (motion.npz, robot.npz, servo_goals.npz) with one
behaviour: no pickles, every array read at once, and an :class:`~motok_robot.errors.InputError`
naming the file when it is missing or is not a readable ``.npz``.  Light: numpy only."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motok_robot.errors import InputError


def read_npz_fields(path: str | Path, what: str = ".npz file") -> dict[str, np.ndarray]:
    """All arrays of ``path`` as ``{name: array}``; ``what`` names the kind of file in errors."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: {what} not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except Exception as exc:  # noqa: BLE001 - truncated, foreign or pickled content: all input problems
        raise InputError(f"{path}: not a readable .npz file ({exc})") from None
