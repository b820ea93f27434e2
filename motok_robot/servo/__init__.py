"""Playback to Dynamixel servos (no torch; mujoco only inside :mod:`motok_robot.servo.sim_rig`).

* :mod:`~motok_robot.servo.bus`: the :class:`ServoBus` seam and :class:`DynamixelBus`.
* :mod:`~motok_robot.servo.emulator`: an emulated servo chain (an in-memory ``PortHandler``).
* :mod:`~motok_robot.servo.imu`: the torso IMU on the bus (the OP3's OpenCR at ID 200).
* :mod:`~motok_robot.servo.sim_rig`: the MuJoCo model as a servo bus.
* :mod:`~motok_robot.servo.convert`: radians <-> ticks and the per-tick safety limiter.
* :mod:`~motok_robot.servo.trajectory`: the report gate and what is played (validated goals).
* :mod:`~motok_robot.servo.streamer`: pre-flight, fixed-rate streaming, safe stop.

The names below load on first use, so ``motok-robot`` commands that never touch a servo (training
and evaluation on a GPU box, say) do not need ``dynamixel_sdk`` installed.
"""

import importlib

_WHERE = {
    "DynamixelBus": "bus",
    "ServoAlertError": "bus",
    "ServoBus": "bus",
    "ServoCommError": "bus",
    "ServoError": "bus",
    "ServoRejectedError": "bus",
    "PlaybackConfig": "config",
    "ImuMount": "imu",
    "ServoMap": "convert",
    "limit_command": "convert",
    "PlaybackInterrupted": "streamer",
    "PlaybackResult": "streamer",
    "PlaybackWarning": "trajectory",
    "Streamer": "streamer",
    "Trajectory": "trajectory",
    "check_validation_report": "trajectory",
    "load_trajectory": "trajectory",
    "play_file": "streamer",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"motok_robot.servo.{_WHERE[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
