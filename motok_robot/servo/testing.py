"""Helpers for tests and benchmarks: synthetic servo maps, trajectories and emulated buses."""

from __future__ import annotations

import time

import numpy as np

from motok_robot.servo.bus import DynamixelBus
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.emulator import EmulatedServoChain, emulated_chain
from motok_robot.servo.streamer import Trajectory


def synthetic_specs(n: int = 20, seed: int = 0) -> list:
    """``n`` ServoSpecs (IDs 1..n, XM430-W350) with mixed signs, zero offsets and tick ranges."""
    from motok_robot.robots.description import ServoSpec

    rng = np.random.default_rng(seed)
    specs = []
    for k in range(n):
        zero = int(2048 + rng.integers(-200, 201))
        below, above = int(rng.integers(300, 1400)), int(rng.integers(300, 1400))
        specs.append(ServoSpec(joint=f"joint_{k:02d}", id=k + 1, model="XM430-W350", sign=1 if k % 3 else -1,
                               zero_offset_ticks=zero, min_ticks=zero - below, max_ticks=zero + above,
                               ticks_per_rev=4096, velocity_limit=4.8))
    return specs


def sine_trajectory(servo_map: ServoMap, seconds: float, fps: float = 20.0, freq_hz: float = 0.5,
                    fraction: float = 0.25) -> Trajectory:
    """Sinusoids inside every servo's range: centre of the range +- ``fraction`` of its width.

    ``q`` is float64 [round(seconds * fps) + 1, n] rad, sampled at ``fps``; phases differ per servo.
    """
    lo = servo_map.to_rad(servo_map.min_ticks)
    hi = servo_map.to_rad(servo_map.max_ticks)
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    phase = np.linspace(0.0, np.pi, servo_map.n)
    q = (lo + hi) / 2 + fraction * (hi - lo) * np.sin(2 * np.pi * freq_hz * t[:, None] + phase)
    return Trajectory(q=q, fps=fps, joints=servo_map.joints)


def emulated_bus(servo_map: ServoMap, clock=time.perf_counter, **kwargs) -> tuple[DynamixelBus, EmulatedServoChain]:
    """A DynamixelBus over an emulated chain matching ``servo_map`` (servos start at the zero pose)."""
    chain = emulated_chain(servo_map, clock=clock, **kwargs)
    return DynamixelBus("emulated", 2_000_000, port_handler=chain), chain
