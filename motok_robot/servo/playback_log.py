"""The playback log: one CSV row per control tick, flushed as it is written.

Columns: ``time_s`` (seconds since the first tick), ``tick``, ``phase`` (``ramp``, ``play``,
``hold``), then ``cmd_<joint>`` (commanded ticks) and ``present_<joint>`` (present ticks, empty
when that tick's read failed or was skipped) for every servo in servo-map order.  Each row is
flushed to the operating system at once, so a crash or a kill loses at most the row being
written.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np


class PlaybackLog:
    """CSV writer for the playback loop (see the module docstring for the columns)."""

    def __init__(self, path: str | Path, joints: Sequence[str]):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._n = len(joints)
        self._file = open(self.path, "w", encoding="utf-8", newline="")
        header = ["time_s", "tick", "phase"] + [f"cmd_{j}" for j in joints] + [f"present_{j}" for j in joints]
        self._file.write(",".join(header) + "\n")
        self._file.flush()
        self._empty = "," * (self._n - 1)
        self.rows = 0

    def write(self, time_s: float, tick: int, phase: str, command: np.ndarray, present: np.ndarray | None) -> None:
        cmd = ",".join(map(str, command.tolist()))
        pos = ",".join(map(str, present.tolist())) if present is not None else self._empty
        self._file.write(f"{time_s:.6f},{tick},{phase},{cmd},{pos}\n")
        self._file.flush()
        self.rows += 1

    def close(self) -> None:
        if not self._file.closed:
            self._file.flush()
            self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def read_log(path: str | Path) -> dict[str, np.ndarray]:
    """Read a playback log back: ``{column: array}`` (``phase`` as str, empty cells as NaN)."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:] if line]
    out: dict[str, np.ndarray] = {}
    for k, name in enumerate(header):
        column = [row[k] if k < len(row) else "" for row in rows]
        if name == "phase":
            out[name] = np.array(column, dtype=str)
        else:
            out[name] = np.array([float(v) if v != "" else np.nan for v in column], dtype=np.float64)
    return out
