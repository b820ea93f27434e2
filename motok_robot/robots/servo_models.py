"""Datasheet ranges of the Dynamixel servo models a robot description may name.

A description's ``velocity_limit`` (rad/s) and the MJCF actuator's torque limit (N m) of a
servo-driven joint must lie inside these ranges (:func:`check_servo_limits`); the playback
limiter derives its per-tick step from the velocity limit, so a description cannot make a servo
move faster than its datasheet allows.

Values are the ROBOTIS e-Manual figures at 12 V (XL430: 11.1 V): no-load speed and stall torque.
The lowest velocity accepted is one Profile Velocity unit (0.229 rpm): a servo cannot be told to
move slower than that, so a smaller limit is a mistake in the file, not a setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from motok_robot.errors import InputError

RPM = 2.0 * math.pi / 60.0  # rad/s per rpm

#: the smallest velocity a Dynamixel X-series servo can be commanded (one Profile Velocity unit)
MIN_VELOCITY_RAD_S = 0.229 * RPM

#: generic ceiling for joints without a servo model (description ``[velocity_limits]``): rad/s
MAX_GENERIC_VELOCITY_RAD_S = 50.0


@dataclass(frozen=True)
class ServoDatasheet:
    """No-load speed (rad/s) and stall torque (N m) of one servo model at its rated voltage."""

    model: str
    no_load_speed: float
    stall_torque: float
    voltage: float = 12.0


DATASHEETS: dict[str, ServoDatasheet] = {s.model: s for s in (
    ServoDatasheet("XM430-W350", 46 * RPM, 4.1),
    ServoDatasheet("XM430-W210", 77 * RPM, 3.0),
    ServoDatasheet("XH430-W350", 46 * RPM, 3.4),
    ServoDatasheet("XH430-W210", 77 * RPM, 2.5),
    ServoDatasheet("XL430-W250", 57 * RPM, 1.4, voltage=11.1),
    ServoDatasheet("XM540-W270", 30 * RPM, 10.6),
    ServoDatasheet("XM540-W150", 53 * RPM, 7.3),
)}


def datasheet(model: str, where: str = "") -> ServoDatasheet:
    """The datasheet entry of ``model``; InputError naming ``where`` for a model not in the table."""
    entry = DATASHEETS.get(str(model).upper())
    if entry is None:
        prefix = f"{where}: " if where else ""
        raise InputError(f"{prefix}servo model {model!r} has no datasheet entry (known: {', '.join(DATASHEETS)}); "
                         "its velocity and torque limits cannot be checked")
    return entry


def velocity_problem(model: str, value: float) -> str | None:
    """Why ``value`` (rad/s) is not a valid velocity limit for ``model``, or None."""
    sheet = datasheet(model)
    if not (isinstance(value, (int, float)) and math.isfinite(value)):
        return f"velocity_limit must be a finite number of rad/s, got {value!r}"
    if not MIN_VELOCITY_RAD_S <= value <= sheet.no_load_speed:
        return (f"velocity_limit {value:g} rad/s outside the {sheet.model} datasheet range "
                f"{MIN_VELOCITY_RAD_S:.3g}..{sheet.no_load_speed:.3f} rad/s (no-load speed at {sheet.voltage:g} V)")
    return None


def torque_problem(model: str, value: float) -> str | None:
    """Why ``value`` (N m) is not a valid torque limit for a joint driven by ``model``, or None."""
    sheet = datasheet(model)
    if not (math.isfinite(value) and value > 0):
        return f"torque limit must be a positive finite number of N m, got {value!r}"
    if value > sheet.stall_torque * 1.0001:
        return (f"torque limit {value:g} N m above the {sheet.model} stall torque {sheet.stall_torque:g} N m "
                f"(at {sheet.voltage:g} V)")
    return None


def generic_velocity_problem(value: float) -> str | None:
    """Why ``value`` (rad/s) is not a plausible joint velocity limit (no servo model), or None."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        return f"must be a positive finite number of rad/s, got {value!r}"
    if value > MAX_GENERIC_VELOCITY_RAD_S:
        return f"{value:g} rad/s is above {MAX_GENERIC_VELOCITY_RAD_S:g} rad/s, more than any joint motor"
    return None
