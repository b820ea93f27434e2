"""The playback log: one CSV row per control tick, flushed as it is written.

Every column name carries its unit.  Columns, servos in servo-map order:

* ``time_s`` (seconds since the first tick), ``tick``, ``phase`` (``ramp``, ``play``, then a
  final ``hold`` or ``torque_off`` row written by the safe stop);
* ``cmd_<joint>_rad``: the commanded joint angle (what the limiter let through);
* ``present_<joint>_rad``: the present joint angle (empty when that tick's read failed or was
  skipped);
* ``balance_<joint>_rad``: the balance controller's correction of the tick's goal, before the
  limiter (empty when playback runs open loop or during the ramp);
* ``gyro_x_rad_s`` .. ``gyro_z_rad_s``, ``accel_x_m_s2`` .. ``accel_z_m_s2``: the torso IMU
  in the robot's IMU frame (empty when it was not read);
* ``cmd_<joint>_ticks``, ``present_<joint>_ticks``: the same positions in servo ticks, as
  they went over the bus.

Each row is flushed to the operating system at once, so a crash or a kill loses at most the
row being written.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

AXES = ("x", "y", "z")


def _cells(values: np.ndarray | None, n: int, fmt: str | None) -> list[str]:
    if values is None:
        return [""] * n
    values = np.asarray(values).reshape(-1)
    if fmt is None:
        return [str(v) for v in values.tolist()]
    return ["" if not np.isfinite(v) else format(v, fmt) for v in values.tolist()]


class PlaybackLog:
    """CSV writer for the playback loop (see the module docstring for the columns).

    Args:
        path: the CSV file.
        joints: joint name of each servo (servo-map order).
        to_rad: ticks [n] -> joint angles [n] rad (``ServoMap.to_rad``).
    """

    def __init__(self, path: str | Path, joints: Sequence[str], to_rad):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._n = len(joints)
        self._to_rad = to_rad
        self._file = open(self.path, "w", encoding="utf-8", newline="")
        header = (["time_s", "tick", "phase"] + [f"cmd_{j}_rad" for j in joints]
                  + [f"present_{j}_rad" for j in joints] + [f"balance_{j}_rad" for j in joints]
                  + [f"gyro_{a}_rad_s" for a in AXES] + [f"accel_{a}_m_s2" for a in AXES]
                  + [f"cmd_{j}_ticks" for j in joints] + [f"present_{j}_ticks" for j in joints])
        self.columns = header
        self._file.write(",".join(header) + "\n")
        self._file.flush()
        self.rows = 0

    def write(self, time_s: float, tick: int, phase: str, command: np.ndarray, present: np.ndarray | None,
              gyro: np.ndarray | None = None, accel: np.ndarray | None = None,
              balance: np.ndarray | None = None) -> None:
        """One row: ``command`` and ``present`` in ticks [n] (present None: not read), the IMU
        (rad/s, m/s^2 [3]) and the balance correction (rad [n]) when there are any."""
        n = self._n
        cells = [f"{time_s:.6f}", str(int(tick)), phase]
        cells += _cells(self._to_rad(command), n, ".6f")
        cells += _cells(None if present is None else self._to_rad(present), n, ".6f")
        cells += _cells(balance, n, ".6f")
        cells += _cells(gyro, 3, ".6f") + _cells(accel, 3, ".5f")
        cells += _cells(command, n, None) + _cells(present, n, None)
        self._file.write(",".join(cells) + "\n")
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
