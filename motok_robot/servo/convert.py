"""Joint angles (rad) <-> servo ticks, per servo, from a robot's servo map.

For servo ``i`` (the ``ServoSpec`` convention of :mod:`motok_robot.robots.description`)::

    ticks = zero_offset_ticks_i + sign_i * q * ticks_per_rev_i / (2 pi)
    q     = sign_i * (ticks - zero_offset_ticks_i) * 2 pi / ticks_per_rev_i

``zero_offset_ticks`` is the servo position at q = 0: 2048 (horn centred; X-series: 4096
ticks per turn) until ``motok-robot servo calibrate`` measures it.  Commands
are limited to ``[min_ticks, max_ticks]``.  All functions are vectorised over a trailing
servo axis: arrays are ``[..., n_servos]`` in the order of :attr:`ServoMap.ids`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from motok_robot.errors import InputError
from motok_robot.robots import servo_models


@dataclass(frozen=True)
class ServoMap:
    """The servo table of a robot as arrays (one entry per servo, servo-map order).

    Attributes:
        joints: joint name driven by each servo.
        ids: servo IDs, int64 [n].
        models: servo model names ("XM430-W350").
        sign: +1 / -1, float64 [n] (direction of positive joint angle in ticks).
        zero_offset: servo position (ticks) at q = 0, float64 [n].
        min_ticks, max_ticks: command limits, int64 [n].
        ticks_per_rev: float64 [n].
        velocity_limit: rad/s, float64 [n].
    """

    joints: tuple[str, ...]
    ids: np.ndarray
    models: tuple[str, ...]
    sign: np.ndarray
    zero_offset: np.ndarray
    min_ticks: np.ndarray
    max_ticks: np.ndarray
    ticks_per_rev: np.ndarray
    velocity_limit: np.ndarray

    @classmethod
    def from_specs(cls, specs: Sequence) -> "ServoMap":
        """Build from ``robot.servos`` (objects with the ``ServoSpec`` fields of CONTRACTS.md)."""
        if not specs:
            raise InputError("the robot has no servo map (robot.servos is empty): nothing to play")
        ids = [int(s.id) for s in specs]
        seen: dict[int, str] = {}
        for spec in specs:
            label = f"servo {spec.id} ({spec.joint})"
            if int(spec.id) in seen:
                raise InputError(f"{label}: duplicate servo ID (also used by {seen[int(spec.id)]})")
            seen[int(spec.id)] = spec.joint
            if not 0 <= int(spec.id) <= 252:
                raise InputError(f"{label}: ID outside 0..252")
            if float(spec.sign) not in (1.0, -1.0):
                raise InputError(f"{label}: sign must be +1 or -1, got {spec.sign}")
            if not int(spec.min_ticks) < int(spec.max_ticks):
                raise InputError(f"{label}: min_ticks {spec.min_ticks} must be below max_ticks {spec.max_ticks}")
            if not (0 <= int(spec.min_ticks) and int(spec.max_ticks) < int(spec.ticks_per_rev)):
                raise InputError(f"{label}: tick range [{spec.min_ticks}, {spec.max_ticks}] outside 0..{int(spec.ticks_per_rev) - 1}")
            if not (math.isfinite(float(spec.velocity_limit)) and float(spec.velocity_limit) > 0):
                raise InputError(f"{label}: velocity_limit must be a positive number of rad/s, got {spec.velocity_limit}")
            if str(spec.model).upper() not in servo_models.DATASHEETS:
                raise InputError(f"{label}: servo model {spec.model!r} has no datasheet entry (known: "
                                 f"{', '.join(servo_models.DATASHEETS)})")
            problem = servo_models.velocity_problem(spec.model, float(spec.velocity_limit))
            if problem:  # the limiter's per-tick step follows this value: never above the datasheet
                raise InputError(f"{label}: {problem}")
        return cls(
            joints=tuple(str(s.joint) for s in specs),
            ids=np.asarray(ids, dtype=np.int64),
            models=tuple(str(s.model) for s in specs),
            sign=np.asarray([float(s.sign) for s in specs]),
            zero_offset=np.asarray([float(s.zero_offset_ticks) for s in specs]),
            min_ticks=np.asarray([int(s.min_ticks) for s in specs], dtype=np.int64),
            max_ticks=np.asarray([int(s.max_ticks) for s in specs], dtype=np.int64),
            ticks_per_rev=np.asarray([float(s.ticks_per_rev) for s in specs]),
            velocity_limit=np.asarray([float(s.velocity_limit) for s in specs]),
        )

    @property
    def n(self) -> int:
        return len(self.joints)

    def select(self, columns: Sequence[int]) -> "ServoMap":
        """The servos at ``columns`` (indices into this map), in that order."""
        cols = list(columns)
        return ServoMap(
            joints=tuple(self.joints[c] for c in cols), ids=self.ids[cols], models=tuple(self.models[c] for c in cols),
            sign=self.sign[cols], zero_offset=self.zero_offset[cols], min_ticks=self.min_ticks[cols],
            max_ticks=self.max_ticks[cols], ticks_per_rev=self.ticks_per_rev[cols],
            velocity_limit=self.velocity_limit[cols])

    @property
    def names_by_id(self) -> dict[int, str]:
        return {int(i): j for i, j in zip(self.ids, self.joints)}

    def ticks_float(self, q: np.ndarray) -> np.ndarray:
        """Unrounded, unclamped ticks of joint angles ``q`` [..., n] rad (NaN stays NaN)."""
        q = np.asarray(q, dtype=np.float64)
        return self.zero_offset + self.sign * q * (self.ticks_per_rev / (2.0 * np.pi))

    def to_ticks(self, q: np.ndarray) -> np.ndarray:
        """Joint angles [..., n] rad -> int64 ticks [..., n], clamped to [min_ticks, max_ticks].

        Raises InputError (naming the servo) for a non-finite angle.
        """
        ticks = self.ticks_float(q)
        bad = ~np.isfinite(ticks)
        if bad.any():
            servo = int(np.nonzero(bad.reshape(-1, self.n).any(axis=0))[0][0])
            raise InputError(f"servo {self.ids[servo]} ({self.joints[servo]}): joint angle is not a finite number")
        return np.rint(np.clip(ticks, self.min_ticks, self.max_ticks)).astype(np.int64)

    def to_rad(self, ticks: np.ndarray) -> np.ndarray:
        """Ticks [..., n] -> joint angles [..., n] rad (float64)."""
        ticks = np.asarray(ticks, dtype=np.float64)
        return self.sign * (ticks - self.zero_offset) * (2.0 * np.pi / self.ticks_per_rev)

    def step_limit_ticks(self, dt: float, margin: float = 1.0) -> np.ndarray:
        """Largest per-tick change (int64 ticks [n], >= 1) that keeps |velocity| <= margin * limit."""
        step = np.floor(margin * self.velocity_limit * dt * self.ticks_per_rev / (2.0 * np.pi))
        return np.maximum(step, 1.0).astype(np.int64)

    def zero_ticks(self) -> np.ndarray:
        """Ticks of q = 0 for every servo (int64 [n], clamped to the limits)."""
        return self.to_ticks(np.zeros(self.n))


def limit_command(target: np.ndarray, previous: np.ndarray, min_ticks: np.ndarray, max_ticks: np.ndarray,
                  step: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The safe command for one tick: the last line of defence before the bus.

    Args:
        target: wanted ticks, float64 [n] (may hold NaN, inf or huge values).
        previous: last command sent, int64 [n]; must lie in [min_ticks, max_ticks].
        min_ticks, max_ticks: int64 [n] position limits.
        step: int64 [n] largest allowed change per tick (>= 0).

    Returns:
        ``(command int64 [n], non_finite bool [n], limited bool [n])``: the command lies in
        ``[min_ticks, max_ticks]`` and within ``step`` of ``previous``; a non-finite target is
        replaced by ``previous``; ``limited`` marks targets changed by the clamps.
    """
    target = np.asarray(target, dtype=np.float64)
    previous = np.asarray(previous, dtype=np.int64)
    non_finite = ~np.isfinite(target)
    wanted = np.where(non_finite, previous, target)
    low = np.maximum(min_ticks, previous - step)
    high = np.minimum(max_ticks, previous + step)
    bounded = np.clip(wanted, low, high)  # integer bounds: rounding cannot leave them
    command = np.rint(bounded).astype(np.int64)
    limited = ~non_finite & (np.abs(bounded - wanted) > 0.5)
    return command, non_finite, limited
