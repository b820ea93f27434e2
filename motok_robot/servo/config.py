"""Playback settings (defaults in one place)."""

from __future__ import annotations

from dataclasses import dataclass

ON_STOP_HOLD = "hold"
ON_STOP_TORQUE_OFF = "torque_off"


@dataclass
class PlaybackConfig:
    """How :class:`~motok_robot.servo.streamer.Streamer` plays a trajectory.

    Attributes:
        rate_hz: control rate (Hz) of goal-position writes (the OP3 class runs 125 Hz).
        ramp_s: time (s) to move from the present pose to the first frame (smooth, step-limited).
        velocity_margin: fraction of each servo's velocity limit a per-tick step may use (<= 1).
        retry_budget: consecutive failed ticks (no/corrupt status packet) tolerated before
            stopping; a hardware-error alert stops at once.
        read_every: read present positions every N ticks (1 = every tick).
        on_stop: ``"hold"`` (keep torque, command the present position) or ``"torque_off"``.
        watchdog_ms: servo Bus Watchdog (ms, multiple of 20; 0 = off): the servos stop by
            themselves if the host stops talking for this long.
        return_delay_units: Return Delay Time to set before streaming (2 us units; None = leave).
        set_profile_velocity: set Profile Velocity to each servo's velocity limit in pre-flight.
        check_models: require each servo's model number to match the servo map.
        spin_s: the last part of each wait (s) spent spinning instead of sleeping.
        realtime_priority: SCHED_FIFO priority for the real-time loop (Linux, root or
            CAP_SYS_NICE; warns and runs at normal priority when refused); 0 = off.  Only used
            with the real clock.
        balance: run the balance controller of the validated servo goals (their
            ``balance_*`` plan) on the torso IMU; False plays them open loop (``--no-balance``).
    """

    rate_hz: float = 125.0
    ramp_s: float = 2.0
    velocity_margin: float = 1.0
    retry_budget: int = 3
    read_every: int = 1
    on_stop: str = ON_STOP_HOLD
    watchdog_ms: float = 100.0
    return_delay_units: int | None = 0
    set_profile_velocity: bool = True
    check_models: bool = True
    spin_s: float = 0.0005
    realtime_priority: int = 50
    balance: bool = True

    def __post_init__(self) -> None:
        from motok_robot.errors import InputError

        if not (isinstance(self.rate_hz, (int, float)) and 1.0 <= self.rate_hz <= 1000.0):
            raise InputError(f"playback rate (--rate) {self.rate_hz} Hz: must be a number in 1..1000 Hz")
        from motok_robot.limits import check_seconds

        check_seconds(self.ramp_s, "playback", "the ramp time (--ramp)")
        if not 0.0 < self.velocity_margin <= 1.0:
            raise InputError(f"velocity_margin must lie in (0, 1], got {self.velocity_margin}")
        if self.retry_budget < 0 or self.read_every < 1:
            raise InputError("retry_budget must be >= 0 and read_every >= 1")
        if self.on_stop not in (ON_STOP_HOLD, ON_STOP_TORQUE_OFF):
            raise InputError(f"on_stop must be '{ON_STOP_HOLD}' or '{ON_STOP_TORQUE_OFF}', got {self.on_stop!r}")
        if not 0 <= self.realtime_priority <= 99:
            raise InputError(f"realtime_priority must lie in 0..99, got {self.realtime_priority}")
        if not 0.0 <= self.watchdog_ms <= 127 * 20:
            raise InputError(f"watchdog_ms must lie in 0..2540, got {self.watchdog_ms}")
