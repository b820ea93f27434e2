"""Clocks for the fixed-rate playback loop, and loop-timing statistics.

:class:`RealClock` sleeps most of the wait with ``time.sleep`` and spins on
``time.perf_counter`` for the last ``spin_s`` seconds (default 0.5 ms), because
``time.sleep`` alone overshoots by up to a scheduler quantum.  :class:`FakeClock` advances
instantly: tests run a 10 s trajectory in milliseconds with the same loop code.
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import asdict, dataclass

import numpy as np


class RealClock:
    """Monotonic seconds (``time.perf_counter``) and a precise ``sleep_until``."""

    def __init__(self, spin_s: float = 0.0005):
        self.spin_s = float(spin_s)

    def now(self) -> float:
        return time.perf_counter()

    def sleep_until(self, deadline: float) -> None:
        remaining = deadline - time.perf_counter()
        if remaining > self.spin_s:
            time.sleep(remaining - self.spin_s)
        while time.perf_counter() < deadline:
            pass


class FakeClock:
    """A clock that only moves when slept on or advanced (seconds); for tests and dry runs."""

    def __init__(self, start: float = 0.0):
        self.t = float(start)

    def now(self) -> float:
        return self.t

    def __call__(self) -> float:  # usable as a plain time source (emulator, SimRig)
        return self.t

    def sleep_until(self, deadline: float) -> None:
        self.t = max(self.t, float(deadline))

    def advance(self, dt: float) -> None:
        self.t += float(dt)


@contextlib.contextmanager
def realtime_priority(priority: int = 50):
    """Run the body with SCHED_FIFO ``priority`` (Linux; needs root or CAP_SYS_NICE).

    Yields a description of the policy in force; never raises when the OS refuses (then the
    loop runs at normal priority and the description says why).  The previous policy is
    restored afterwards.  On a busy machine this is what keeps the loop jitter low: the
    scheduler wakes the loop on time instead of after another process's time slice.
    """
    try:
        old_policy, old_param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        yield f"normal (real-time priority refused: {exc})"
        return
    try:
        yield f"SCHED_FIFO {priority}"
    finally:
        try:
            os.sched_setscheduler(0, old_policy, old_param)
        except OSError:
            pass


@dataclass
class LoopStats:
    """Timing of a fixed-rate loop (times in ms unless named otherwise).

    ``jitter`` is ``|interval between consecutive tick starts - nominal period|``;
    ``lateness`` is ``tick start - its deadline``; an overrun is a tick whose work ended after
    the next tick's deadline; ``work`` is the time from tick start to the end of its bus I/O.
    """

    ticks: int
    rate_hz: float
    nominal_rate_hz: float
    jitter_p50_ms: float
    jitter_p99_ms: float
    jitter_max_ms: float
    lateness_p99_ms: float
    work_p50_ms: float
    work_p99_ms: float
    overruns: int

    def line(self) -> str:
        return (f"{self.ticks} ticks at {self.rate_hz:.2f} Hz (nominal {self.nominal_rate_hz:g}); "
                f"jitter p50 {self.jitter_p50_ms:.3f} ms, p99 {self.jitter_p99_ms:.3f} ms, "
                f"max {self.jitter_max_ms:.3f} ms; work p99 {self.work_p99_ms:.3f} ms; overruns {self.overruns}")

    def as_dict(self) -> dict:
        return asdict(self)


def loop_stats(starts: np.ndarray, deadlines: np.ndarray, work_s: np.ndarray, period: float, overruns: int) -> LoopStats:
    """Stats from per-tick start times, deadlines and work durations (seconds, [ticks])."""
    starts = np.asarray(starts, dtype=np.float64)
    n = len(starts)
    ms = 1e3
    if n >= 2:
        intervals = np.diff(starts)
        jitter = np.abs(intervals - period) * ms
        span = starts[-1] - starts[0]
        rate = (n - 1) / span if span > 0 else float("inf")
    else:
        jitter = np.zeros(1)
        rate = 0.0
    lateness = (starts - np.asarray(deadlines)) * ms if n else np.zeros(1)
    work = np.asarray(work_s) * ms if n else np.zeros(1)
    return LoopStats(
        ticks=n,
        rate_hz=float(rate),
        nominal_rate_hz=1.0 / period,
        jitter_p50_ms=float(np.percentile(jitter, 50)),
        jitter_p99_ms=float(np.percentile(jitter, 99)),
        jitter_max_ms=float(np.max(jitter)),
        lateness_p99_ms=float(np.percentile(lateness, 99)),
        work_p50_ms=float(np.percentile(work, 50)),
        work_p99_ms=float(np.percentile(work, 99)),
        overruns=int(overruns),
    )
