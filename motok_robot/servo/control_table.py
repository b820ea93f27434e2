"""Dynamixel X-series (Protocol 2.0) control-table addresses, units and model numbers.

Addresses follow the ROBOTIS e-Manual control table of the X-series (XM430-W350 and its
siblings share it).  Only the registers playback uses are named here; the emulator
(:mod:`motok_robot.servo.emulator`) keeps a full-size table per servo.

Units (as the servo firmware defines them):

* position: ticks, 4096 per revolution, 2048 = horn centre.
* velocity / profile velocity / velocity limit: 0.229 rev/min per unit.
* return delay time: 2 microseconds per unit (factory default 250 = 0.5 ms).
* bus watchdog: 20 ms per unit (0 = off; the servo writes 255 (-1) when it fired).
"""

from __future__ import annotations

import math

# --- EEPROM area (writable only while torque is off) -------------------------------------
ADDR_MODEL_NUMBER = 0  # 2 bytes, read-only
ADDR_FIRMWARE_VERSION = 6  # 1 byte, read-only
ADDR_ID = 7  # 1 byte
ADDR_BAUD_RATE = 8  # 1 byte (index into BAUD_RATE_VALUES)
ADDR_RETURN_DELAY_TIME = 9  # 1 byte, 2 us per unit
ADDR_DRIVE_MODE = 10  # 1 byte
ADDR_OPERATING_MODE = 11  # 1 byte (3 = position control)
ADDR_VELOCITY_LIMIT = 44  # 4 bytes, 0.229 rpm per unit
ADDR_MAX_POSITION_LIMIT = 48  # 4 bytes, ticks
ADDR_MIN_POSITION_LIMIT = 52  # 4 bytes, ticks
ADDR_SHUTDOWN = 63  # 1 byte: which hardware errors switch torque off
EEPROM_END = 64  # addresses below this are EEPROM

# --- RAM area ------------------------------------------------------------------------------
ADDR_TORQUE_ENABLE = 64  # 1 byte
ADDR_LED = 65  # 1 byte
ADDR_STATUS_RETURN_LEVEL = 68  # 1 byte (2 = reply to every instruction)
ADDR_REGISTERED_INSTRUCTION = 69  # 1 byte, read-only
ADDR_HARDWARE_ERROR_STATUS = 70  # 1 byte, read-only
ADDR_BUS_WATCHDOG = 98  # 1 byte, 20 ms per unit
ADDR_GOAL_PWM = 100  # 2 bytes
ADDR_GOAL_VELOCITY = 104  # 4 bytes
ADDR_PROFILE_ACCELERATION = 108  # 4 bytes
ADDR_PROFILE_VELOCITY = 112  # 4 bytes, 0.229 rpm per unit (0 = unlimited)
ADDR_GOAL_POSITION = 116  # 4 bytes, ticks
ADDR_REALTIME_TICK = 120  # 2 bytes, ms
ADDR_MOVING = 122  # 1 byte
ADDR_PRESENT_VELOCITY = 128  # 4 bytes, 0.229 rpm per unit, signed
ADDR_PRESENT_POSITION = 132  # 4 bytes, ticks, signed
ADDR_PRESENT_INPUT_VOLTAGE = 144  # 2 bytes, 0.1 V per unit
ADDR_PRESENT_TEMPERATURE = 146  # 1 byte, deg C
CONTROL_TABLE_SIZE = 700  # covers the indirect-address area of the X-series

# Registers the host may not write (the servo answers with an access error).
READ_ONLY_RANGES = (
    (ADDR_MODEL_NUMBER, 7),  # model number, model information, firmware version
    (ADDR_REGISTERED_INSTRUCTION, 2),  # registered instruction, hardware error status
    (ADDR_REALTIME_TICK, 28),  # realtime tick .. present temperature (120..147)
)

SIZE_GOAL_POSITION = 4
SIZE_PRESENT_POSITION = 4

TORQUE_ON = 1
TORQUE_OFF = 0
OPERATING_MODE_POSITION = 3

# Baud Rate register value -> bits per second.
BAUD_RATE_VALUES = {
    0: 9_600,
    1: 57_600,
    2: 115_200,
    3: 1_000_000,
    4: 2_000_000,
    5: 3_000_000,
    6: 4_000_000,
    7: 4_500_000,
}

# Hardware Error Status (address 70) bits.
HARDWARE_ERROR_BITS = {
    0: "input voltage error",
    2: "overheating",
    3: "motor encoder error",
    4: "electrical shock",
    5: "overload",
}

# Status-packet error byte (Protocol 2.0): bit 7 = hardware alert, low 7 bits = error number.
STATUS_ALERT_BIT = 0x80
STATUS_ERRORS = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}

# Model numbers reported by PING / address 0.
MODEL_NUMBERS = {
    "XH430-W350": 1000,
    "XH430-W210": 1010,
    "XM430-W350": 1020,
    "XM430-W210": 1030,
    "XL430-W250": 1060,
    "XC430-W150": 1070,
    "XM540-W270": 1120,
    "XM540-W150": 1130,
}
MODEL_NAMES = {number: name for name, number in MODEL_NUMBERS.items()}

# Factory Velocity Limit (address 44) per model, 0.229 rpm units (e.g. 200 = 45.8 rpm, the
# XM430-W350 no-load speed at 12 V).
DEFAULT_VELOCITY_LIMIT_UNITS = {
    "XM430-W350": 200,
    "XM430-W210": 330,
    "XH430-W350": 210,
    "XH430-W210": 340,
    "XL430-W250": 265,
    "XC430-W150": 460,
    "XM540-W270": 128,
    "XM540-W150": 230,
}

RPM_PER_VELOCITY_UNIT = 0.229
RAD_S_PER_VELOCITY_UNIT = RPM_PER_VELOCITY_UNIT * 2.0 * math.pi / 60.0
SECONDS_PER_WATCHDOG_UNIT = 0.020
SECONDS_PER_RETURN_DELAY_UNIT = 2e-6


def model_number(model: str) -> int:
    """Model number of a servo model name such as ``"XM430-W350"`` (KeyError if unknown)."""
    return MODEL_NUMBERS[model.upper()]


def velocity_units_from_rad_s(rad_s: float) -> int:
    """Velocity register units (0.229 rpm each) for ``rad_s`` (rad/s), rounded down, >= 1."""
    return max(1, int(math.floor(rad_s / RAD_S_PER_VELOCITY_UNIT)))


def describe_hardware_error(bits: int) -> str:
    """Human-readable names of the set bits of Hardware Error Status (address 70)."""
    names = [name for bit, name in HARDWARE_ERROR_BITS.items() if bits & (1 << bit)]
    unknown = bits & ~sum(1 << bit for bit in HARDWARE_ERROR_BITS)
    if unknown:
        names.append(f"unknown bits 0x{unknown:02x}")
    return ", ".join(names) if names else "no error bits set"
