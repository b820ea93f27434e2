"""Playback to Dynamixel servos (no torch; mujoco only inside :mod:`motok_robot.servo.sim_rig`).

* :mod:`~motok_robot.servo.bus`: the :class:`ServoBus` seam and :class:`DynamixelBus`.
* :mod:`~motok_robot.servo.emulator`: an emulated servo chain (an in-memory ``PortHandler``).
* :mod:`~motok_robot.servo.sim_rig`: the MuJoCo model as a servo bus.
* :mod:`~motok_robot.servo.convert`: radians <-> ticks and the per-tick safety limiter.
* :mod:`~motok_robot.servo.streamer`: report gate, pre-flight, fixed-rate streaming, safe stop.
"""

from motok_robot.servo.bus import (
    DynamixelBus,
    ServoAlertError,
    ServoBus,
    ServoCommError,
    ServoError,
    ServoRejectedError,
)
from motok_robot.servo.config import PlaybackConfig
from motok_robot.servo.convert import ServoMap, limit_command
from motok_robot.servo.streamer import (
    PlaybackInterrupted,
    PlaybackResult,
    PlaybackWarning,
    Streamer,
    Trajectory,
    check_validation_report,
    load_trajectory,
    play_file,
)

__all__ = [
    "DynamixelBus",
    "PlaybackConfig",
    "PlaybackInterrupted",
    "PlaybackResult",
    "PlaybackWarning",
    "ServoAlertError",
    "ServoBus",
    "ServoCommError",
    "ServoError",
    "ServoMap",
    "ServoRejectedError",
    "Streamer",
    "Trajectory",
    "check_validation_report",
    "limit_command",
    "load_trajectory",
    "play_file",
]
