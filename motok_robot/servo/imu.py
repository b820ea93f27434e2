"""The torso IMU on the Dynamixel bus: the ROBOTIS OpenCR sub-controller (Protocol 2.0).

The ROBOTIS OP3 carries its IMU on the OpenCR board, which answers on the servo bus at ID 200
with its own control table (the registers used here):

====  ====  =====================================================================
addr  size  register
====  ====  =====================================================================
30    1     button
31    1     present voltage (0.1 V per unit)
32    2x3   gyro x, y, z (int16; 2000 / 32800 deg/s per count)
38    2x3   accelerometer x, y, z (int16; 2 / 32768 g per count, specific force:
            +1 g up at rest)
44    2x3   roll, pitch, yaw (int16, the board's own estimate; not used here)
====  ====  =====================================================================

Playback reads the 12 bytes 32..43 every control tick (in the same Bulk Read as the servos'
present positions) and turns them into physical units in the robot's IMU frame (the MJCF's
``imu`` site, else the base body): gyro in rad/s, accelerometer in m/s^2.  The sensor's axes
are mapped to that frame by the mounting of the robot description (``[bus.imu] axes``,
:class:`motok_robot.robots.description.ImuSpec`); the OP3 mounts it with x and y reversed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

OPENCR_ID = 200
#: model number an OpenCR answers to PING with (0x7400)
OPENCR_MODEL_NUMBER = 0x7400

ADDR_BUTTON = 30  # 1 byte
ADDR_PRESENT_VOLTAGE = 31  # 1 byte, 0.1 V per unit
ADDR_GYRO = 32  # 3 x int16: x, y, z
ADDR_ACCEL = 38  # 3 x int16: x, y, z
ADDR_ROLL_PITCH_YAW = 44  # 3 x int16
#: the block playback reads: gyro x, y, z then accelerometer x, y, z
IMU_BLOCK_ADDRESS = ADDR_GYRO
IMU_BLOCK_SIZE = 12

#: standard gravity: the accelerometer's unit "g"
STANDARD_GRAVITY = 9.80665
DEG_S_PER_GYRO_COUNT = 2000.0 / 32800.0
RAD_S_PER_GYRO_COUNT = DEG_S_PER_GYRO_COUNT * math.pi / 180.0
G_PER_ACCEL_COUNT = 2.0 / 32768.0
M_S2_PER_ACCEL_COUNT = G_PER_ACCEL_COUNT * STANDARD_GRAVITY


@dataclass(frozen=True)
class ImuMount:
    """Where the IMU is and how its axes map to the robot's IMU frame.

    ``axis[i]`` is the sensor axis (0 x, 1 y, 2 z) that gives IMU-frame axis ``i``, ``sign[i]``
    its direction (+1 or -1): ``frame[i] = sign[i] * sensor[axis[i]]``.
    """

    id: int = OPENCR_ID
    axis: tuple[int, int, int] = (0, 1, 2)
    sign: tuple[float, float, float] = (-1.0, -1.0, 1.0)

    @classmethod
    def from_spec(cls, spec) -> "ImuMount":
        """From a description's :class:`~motok_robot.robots.description.ImuSpec` (``axes`` like
        ``("-x", "-y", "z")``)."""
        axis = tuple("xyz".index(a.lstrip("-")) for a in spec.axes)
        sign = tuple(-1.0 if a.startswith("-") else 1.0 for a in spec.axes)
        if sorted(axis) != [0, 1, 2]:
            raise ValueError(f"IMU axes {spec.axes!r} must name x, y and z once each")
        return cls(id=int(spec.id), axis=axis, sign=sign)

    def to_frame(self, sensor: Sequence[float]) -> np.ndarray:
        """Sensor-axis vector [3] -> IMU frame [3]."""
        sensor = np.asarray(sensor, dtype=np.float64)
        return np.asarray(self.sign) * sensor[list(self.axis)]

    def to_sensor(self, frame: Sequence[float]) -> np.ndarray:
        """IMU-frame vector [3] -> sensor axes [3] (the inverse of :meth:`to_frame`)."""
        out = np.zeros(3)
        out[list(self.axis)] = np.asarray(self.sign) * np.asarray(frame, dtype=np.float64)
        return out

    def decode(self, block: bytes | bytearray | Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """The 12 register bytes 32..43 -> (gyro [3] rad/s, accelerometer [3] m/s^2), IMU frame."""
        raw = bytes(block)
        if len(raw) < IMU_BLOCK_SIZE:
            raise ValueError(f"IMU block needs {IMU_BLOCK_SIZE} bytes, got {len(raw)}")
        counts = np.frombuffer(raw[:IMU_BLOCK_SIZE], dtype="<i2").astype(np.float64)
        return (self.to_frame(counts[:3] * RAD_S_PER_GYRO_COUNT),
                self.to_frame(counts[3:] * M_S2_PER_ACCEL_COUNT))


def gyro_counts(rad_s: Sequence[float]) -> np.ndarray:
    """Sensor-axis angular velocity (rad/s) -> register counts (int16, saturated)."""
    counts = np.rint(np.asarray(rad_s, dtype=np.float64) / RAD_S_PER_GYRO_COUNT)
    return np.clip(counts, -32768, 32767).astype(np.int64)


def accel_counts(m_s2: Sequence[float]) -> np.ndarray:
    """Sensor-axis specific force (m/s^2) -> register counts (int16, saturated)."""
    counts = np.rint(np.asarray(m_s2, dtype=np.float64) / M_S2_PER_ACCEL_COUNT)
    return np.clip(counts, -32768, 32767).astype(np.int64)
