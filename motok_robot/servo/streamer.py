# Size (690 lines): one fixed-rate loop and every one of its fail-safe exits (ramp, limiter, retries, signals, hold), reviewed together.
"""Stream a validated ``robot.npz`` to a servo bus at a fixed rate, failing safe.

Sequence (:func:`play_file`):

1. **Report gate** (:func:`~motok_robot.servo.trajectory.check_validation_report`): a
   ``report.json`` with ``"passed": true`` (next to ``robot.npz`` or given explicitly) is
   required; ``force=True`` plays anyway and warns (:class:`PlaybackWarning`).
2. **Load** (:func:`~motok_robot.servo.trajectory.load_trajectory`): the servo goals the report validated
   (``servo_goals.npz``: the joint angles plus inverse-dynamics feedforward, see
   :mod:`motok_robot.feasibility.feedforward`), or the joint columns of ``qpos`` when the report
   records none; servo-map order.
3. **Pre-flight** (:meth:`Streamer.preflight`): ping every ID, check model numbers and
   Hardware Error Status, set Return Delay Time, read present positions (each must lie in its
   limits), set Profile Velocity to the servo's velocity limit, write Goal = present, enable
   torque.  The bus watchdog is armed when streaming starts.
4. **Stream** (:meth:`Streamer.play`): ramp (smoothstep) from the present pose to frame 0 over
   ``ramp_s``, then the trajectory linearly interpolated from its frame rate (20 fps) to the
   control rate (125 Hz).  Every command passes :func:`~motok_robot.servo.convert.limit_command`:
   clamped to the position limits and to a per-tick step of ``velocity_limit / rate``; NaN/inf
   targets are replaced by the last safe command (counted, warned).  Each tick: sync-write
   goals, sync-read present positions, append a log row (flushed).
   **Closed loop**: when the validated servo goals carry a balance plan (``servo_goals.npz``
   fields ``balance_*``) and ``config.balance`` is on, each tick instead reads the present
   positions and the torso IMU in one Bulk Read, lets the same
   :class:`~motok_robot.feasibility.balance.BalanceController` that validation's rollout ran
   correct the tick's goal (trajectory ticks only, time 0 at the first frame; the ramp is not
   corrected), passes the corrected goal through the limiter and sync-writes it.  A bus
   without an IMU refuses such a trajectory unless ``config.balance`` is off (then a warning).
5. **Stop**: on Ctrl-C, SIGTERM or SIGHUP, more than ``retry_budget`` consecutive failed
   ticks (an IMU read counts as any other read), or a hardware error alert: stop streaming,
   hold the present position (or switch torque off when ``on_stop="torque_off"``), write a
   final log row, close the log, and raise :class:`HardwareError` (a signal:
   :class:`PlaybackInterrupted`) whose message names the servo (or the IMU, ID 200), its
   joint and the cause.

Timing uses ``perf_counter`` deadlines (:class:`~motok_robot.servo.timing.RealClock`): sleep
most of the period, spin the last 0.5 ms.  A tick whose work overruns the next deadline is
counted and the schedule restarts from the present time (no burst of catch-up writes, so
consecutive writes are never closer than one period and the step limit stays a velocity limit).
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.errors import HardwareError, InputError
from motok_robot.servo import control_table as ct
from motok_robot.servo.bus import (
    ServoAlertError,
    ServoBus,
    ServoCommError,
    ServoError,
    ServoRejectedError,
    ServoWatchdogError,
)
from motok_robot.servo.config import ON_STOP_HOLD, PlaybackConfig
from motok_robot.servo.convert import ServoMap, limit_command
from motok_robot.servo.playback_log import PlaybackLog
from motok_robot.servo.timing import LoopStats, RealClock, loop_stats, realtime_priority


from motok_robot.servo.trajectory import (  # noqa: F401 (public here too)
    PlaybackWarning, Trajectory, check_validation_report, load_trajectory, plan_targets,
)

class PlaybackInterrupted(HardwareError):
    """Playback stopped by Ctrl-C, SIGTERM or SIGHUP (after the servos were put in their safe
    state); ``signal_number`` is the signal, ``exit_status`` the shell's ``128 + signal``."""

    def __init__(self, message: str, signal_number: int = int(signal.SIGINT)):
        super().__init__(message)
        self.signal_number = int(signal_number)

    @property
    def exit_status(self) -> int:
        return 128 + self.signal_number


class _StopSignal(KeyboardInterrupt):
    """SIGINT / SIGTERM / SIGHUP during playback: raised where the loop is, like Ctrl-C."""

    def __init__(self, signal_number: int):
        super().__init__(signal_number)
        self.signal_number = int(signal_number)


def _signal_label(signal_number: int) -> str:
    if signal_number == signal.SIGINT:
        return "Ctrl-C"
    try:
        return signal.Signals(signal_number).name
    except ValueError:
        return f"signal {signal_number}"


#: the signals that stop playback the way Ctrl-C does
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextlib.contextmanager
def _stop_signals_raise(state: dict):
    """While playing, SIGINT, SIGTERM and SIGHUP raise :class:`_StopSignal` in the loop (the
    Ctrl-C path); once ``state["stopping"]`` is set (the safe stop runs) further ones are only
    recorded, so a second signal cannot cut the safe stop short.  Only in the main thread
    (Python delivers signals there); elsewhere the handlers are left alone."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signal_number, frame):
        if state.get("stopping"):
            state.setdefault("ignored", []).append(int(signal_number))
            return
        state["stopping"] = True
        raise _StopSignal(signal_number)

    previous = {}
    for sig in STOP_SIGNALS:
        try:
            previous[sig] = signal.signal(sig, handler)
        except (ValueError, OSError):  # not settable here
            pass
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


# ----------------------------------------------------------------------------- results
@dataclass
class PlaybackResult:
    """What a playback did. Counts of servo-ticks: ``non_finite`` targets replaced,
    ``limited`` targets clamped (position or step limit); ``failed_ticks`` ticks whose bus I/O
    failed and were retried."""

    stats: LoopStats
    ticks: int
    ramp_ticks: int
    trajectory_s: float
    non_finite: int
    limited: int
    failed_ticks: int
    log_path: str | None
    completed: bool = True
    stopped_because: str | None = None
    extra: dict = field(default_factory=dict)

    def line(self) -> str:
        balance = self.extra.get("balance")
        loop = ""
        if balance and balance.get("loop") == "closed":
            loop = f"; balance closed loop (largest correction {balance['max_correction_rad']:.3f} rad)"
        elif balance:
            loop = "; balance OFF (validated closed loop)"
        return (f"played {self.trajectory_s:.2f} s ({self.ticks} ticks incl. {self.ramp_ticks} ramp): "
                f"{self.stats.line()}; clamped {self.limited}, non-finite {self.non_finite}, "
                f"failed ticks {self.failed_ticks}" + loop + (f"; log {self.log_path}" if self.log_path else ""))

    def as_dict(self) -> dict:
        out = asdict(self)
        out["stats"] = self.stats.as_dict()
        return out


# ----------------------------------------------------------------------------- streamer
class Streamer:
    """Plays joint trajectories on a :class:`ServoBus` (see the module docstring).

    Args:
        bus: the servo bus (DynamixelBus, DynamixelBus over the emulator, SimRig).
        servo_map: the robot's servos.
        config: :class:`PlaybackConfig`.
        clock: ``RealClock`` by default; a ``FakeClock`` in tests.
        log_path: CSV log (see :mod:`motok_robot.servo.playback_log`); None = no log.
        on_tick: ``on_tick(tick, streamer)`` called at the start of every control tick (tests
            use it to inject faults or a KeyboardInterrupt).
        joint_range: ``{joint: (low, high)}`` rad, the robot's joint ranges (``Robot.joint_range``)
            the balance controller clamps its goals to, as in validation; joints not listed
            use their servo's tick limits.

    After :meth:`play` started a closed-loop trajectory, :attr:`controller` is its
    :class:`~motok_robot.feasibility.balance.BalanceController` (None: open loop).
    """

    def __init__(self, bus: ServoBus, servo_map: ServoMap, config: PlaybackConfig | None = None, *,
                 clock=None, log_path: str | Path | None = None,
                 on_tick: Callable[[int, "Streamer"], None] | None = None,
                 joint_range: dict[str, tuple[float, float]] | None = None):
        self.bus = bus
        self.map = servo_map
        self.config = config or PlaybackConfig()
        self.clock = clock or RealClock(self.config.spin_s)
        self.log_path = Path(log_path) if log_path is not None else None
        self.on_tick = on_tick
        self.ids = [int(i) for i in servo_map.ids]
        self.present: np.ndarray | None = None
        self._names = servo_map.names_by_id
        self.joint_range = dict(joint_range or {})
        self.controller = None
        self._balance_for: Trajectory | None = None
        self._balance_cols: np.ndarray | None = None
        self._imu_checked = False

    def _label(self, servo_id: int) -> str:
        if servo_id is not None and servo_id == self.bus.imu_id and int(servo_id) not in self._names:
            return f"IMU (ID {servo_id})"
        joint = self._names.get(int(servo_id))
        return f"servo {servo_id}" + (f" ({joint})" if joint else "")

    def _describe(self, exc: ServoError) -> str:
        if exc.servo_id is not None and exc.servo_id == self.bus.imu_id and int(exc.servo_id) not in self._names:
            where = f" on {exc.port}" if exc.port else ""
            return f"{self._label(exc.servo_id)}{where}: {exc.cause}"
        return exc.describe(self._names)

    # ------------------------------------------------------------------ closed loop
    def _balance(self, trajectory: Trajectory):
        """The balance controller for ``trajectory`` (None: open loop); refuses (InputError)
        a closed-loop trajectory this bus cannot close the loop for.  Nothing moves here."""
        if self._balance_for is trajectory:
            return self.controller
        plan = getattr(trajectory, "plan", None)
        where = str(trajectory.source or "trajectory")
        controller = None
        if plan is not None and not self.config.balance:
            warnings.warn(f"{where}: validation ran it CLOSED LOOP (balance controller on the torso IMU); "
                          "--no-balance plays the same servo goals open loop, which is not what passed "
                          "validation", PlaybackWarning, stacklevel=3)
        elif plan is not None:
            if self.bus.imu_id is None:
                raise InputError(f"{where}: refusing to play: validation ran it closed loop (balance controller on "
                                 f"the torso IMU) but the bus {self.bus.port_name} has no IMU (no [bus.imu] in the "
                                 "robot description); pass --no-balance to play it open loop")
            if abs(float(plan.config.rate_hz) - self.config.rate_hz) > 1e-6:
                raise InputError(f"{where}: refusing to play: the balance controller was validated at "
                                 f"{plan.config.rate_hz:g} Hz, playback runs at {self.config.rate_hz:g} Hz; play at "
                                 f"--rate {plan.config.rate_hz:g} (or --no-balance for open loop)")
            joints = tuple(trajectory.plan_joints)
            index = {j: i for i, j in enumerate(joints)}
            lacking = [j for j in self.map.joints if j not in index]
            if lacking or len(joints) != plan.tilt_matrix.shape[1]:
                raise InputError(f"{where}: the balance plan's joints ({len(joints)}) do not cover the servo "
                                 f"joint(s) {', '.join(lacking) or '?'}")
            from motok_robot.feasibility.balance import BalanceController

            ranges = np.tile([-np.inf, np.inf], (len(joints), 1))
            ends = self.map.to_rad(np.stack([self.map.min_ticks, self.map.max_ticks]))
            for k, joint in enumerate(self.map.joints):
                ranges[index[joint]] = (ends[:, k].min(), ends[:, k].max())
            for joint, (low, high) in self.joint_range.items():
                if joint in index:
                    ranges[index[joint]] = (float(low), float(high))
            controller = BalanceController(plan, ranges)
            self._balance_cols = np.array([index[j] for j in self.map.joints], dtype=np.int64)
        self.controller = controller
        self._balance_for = trajectory
        return controller

    def _check_imu(self) -> None:
        """The IMU answers and reads about 1 g at rest; HardwareError naming it otherwise."""
        from motok_robot.servo.imu import STANDARD_GRAVITY

        bus, label = self.bus, self._label(self.bus.imu_id)
        cause = "no reply"
        for _attempt in range(self.config.retry_budget + 1):
            try:
                bus.ping_imu()
                break
            except ServoCommError as exc:
                cause = exc.cause
                bus.reset()
        else:
            raise HardwareError(f"pre-flight: {label} on {bus.port_name} does not answer ping ({cause}); the balance "
                                "controller needs it (--no-balance plays open loop)")
        try:
            gyro, accel = self._retry(bus.read_imu)
        except ServoError as exc:
            raise HardwareError(f"pre-flight: reading the IMU: {self._describe(exc)}") from None
        norm = float(np.linalg.norm(accel))
        at_rest = 0.5 * STANDARD_GRAVITY <= norm <= 1.5 * STANDARD_GRAVITY or not bus.imu_at_rest_in_preflight
        if not (np.isfinite(gyro).all() and np.isfinite(accel).all() and at_rest):
            raise HardwareError(f"pre-flight: {label} reads an acceleration of {norm:.2f} m/s^2 (gyro "
                                f"{np.round(gyro, 3).tolist()} rad/s) with the robot at rest, expected about "
                                f"{STANDARD_GRAVITY:.2f}: check the IMU and its [bus.imu] mounting")
        self._imu_checked = True

    # ------------------------------------------------------------------ pre-flight
    def preflight(self, trajectory: Trajectory | None = None) -> np.ndarray:
        """Check and prepare the servos; returns present positions (int64 ticks [n]).

        With the ``trajectory`` about to be played: when it is closed loop, first check that
        the bus can close the loop (an IMU; InputError otherwise) and that the IMU answers and
        reads about 1 g.  Raises HardwareError naming every servo at fault; torque is only
        switched on at the end.
        """
        if trajectory is not None and self._balance(trajectory) is not None:
            self._check_imu()
        try:
            return self._preflight()
        except ServoAlertError as exc:
            raise HardwareError(f"pre-flight: {self._describe(exc)}; fix the cause and reboot the servo") from None
        except ServoError as exc:
            raise HardwareError(f"pre-flight: {self._describe(exc)}") from None

    def _preflight(self) -> np.ndarray:
        bus, ids, cfg = self.bus, self.ids, self.config
        silent, wrong = [], []
        for k, servo_id in enumerate(ids):
            number = None
            for _attempt in range(cfg.retry_budget + 1):
                try:
                    number = bus.ping(servo_id)
                    break
                except ServoCommError as exc:
                    cause = exc.cause
                    bus.reset()
            if number is None:
                silent.append(f"{self._label(servo_id)}: {cause}")
                continue
            if cfg.check_models:
                model = self.map.models[k]
                expected = ct.MODEL_NUMBERS.get(model.upper())
                if expected is None:
                    raise InputError(f"{self._label(servo_id)}: unknown servo model '{model}' in the servo map "
                                     f"(known: {', '.join(ct.MODEL_NUMBERS)})")
                if number != expected:
                    found = ct.MODEL_NAMES.get(number, "unknown model")
                    wrong.append(f"{self._label(servo_id)}: model number {number} ({found}), "
                                 f"servo map says {model} ({expected})")
        if silent:
            raise HardwareError(f"pre-flight on {bus.port_name}: {len(silent)} servo(s) do not answer ping: "
                                + "; ".join(silent))
        if wrong:
            raise HardwareError(f"pre-flight on {bus.port_name}: " + "; ".join(wrong))
        errors = bus.read_hardware_errors(ids)
        bad = {i: b for i, b in errors.items() if b}
        if bad:
            raise HardwareError("pre-flight: " + "; ".join(
                f"{self._label(i)}: hardware error: {ct.describe_hardware_error(b)} (Hardware Error Status 0x{b:02x}); "
                "fix the cause and reboot the servo" for i, b in bad.items()))
        if cfg.return_delay_units is not None:
            for servo_id in ids:
                try:
                    bus.set_return_delay_time([servo_id], cfg.return_delay_units)
                except ServoRejectedError:
                    warnings.warn(f"{self._label(servo_id)}: Return Delay Time not changed (torque is on; it is an "
                                  "EEPROM register). Set it to 0 with torque off for the fastest loop.",
                                  PlaybackWarning, stacklevel=2)
        bus.set_bus_watchdog(ids, 0)  # clears a watchdog that fired in an earlier session
        present = self._retry(lambda: bus.read_present_positions(ids))
        outside = [f"{self._label(i)} at {p} outside [{lo}, {hi}]"
                   for i, p, lo, hi in zip(ids, present, self.map.min_ticks, self.map.max_ticks) if not lo <= p <= hi]
        if outside:
            raise HardwareError("pre-flight: present position outside the servo's limits: " + "; ".join(outside)
                                + ". Move the joint into range by hand (torque off) before playing")
        if cfg.set_profile_velocity:
            units = [ct.velocity_units_from_rad_s(v * cfg.velocity_margin) for v in self.map.velocity_limit]
            bus.set_profile_velocity(ids, units)
        bus.write_goal_positions(ids, present)  # no jump when torque comes on
        bus.set_torque(ids, True)
        self.present = present
        return present

    def _retry(self, operation):
        """``operation()``, retried up to ``retry_budget`` times on a communication error."""
        for attempt in range(self.config.retry_budget + 1):
            try:
                return operation()
            except ServoCommError:
                if attempt == self.config.retry_budget:
                    raise
                self.bus.reset()

    # ------------------------------------------------------------------ streaming
    def play(self, trajectory: Trajectory, present: np.ndarray | None = None) -> PlaybackResult:
        """Ramp to frame 0 and stream ``trajectory``; runs :meth:`preflight` first if needed."""
        controller = self._balance(trajectory)  # refuses before anything moves
        if present is None:
            present = self.present if self.present is not None else self.preflight(trajectory)
        if controller is not None and not self._imu_checked:
            self._check_imu()
        cfg, bus, ids, smap, clock = self.config, self.bus, self.ids, self.map, self.clock
        present = np.asarray(present, dtype=np.int64)
        if present.shape != (smap.n,) or ((present < smap.min_ticks) | (present > smap.max_ticks)).any():
            raise HardwareError(f"cannot start from present positions {present.tolist()}: they must be {smap.n} "
                                "ticks inside the servo limits")
        period = 1.0 / cfg.rate_hz
        targets, is_ramp = plan_targets(trajectory, present, smap, cfg.rate_hz, cfg.ramp_s)
        n_ticks = len(targets)
        n_ramp = int(is_ramp.sum())
        step = smap.step_limit_ticks(period, cfg.velocity_margin)
        lo, hi = smap.min_ticks, smap.max_ticks
        closed = controller is not None
        if closed:
            cols = self._balance_cols
            # goals of plan joints without a servo: unused (each joint's correction is its own)
            full_goal = np.zeros(controller.low.size)
            no_imu = np.full(3, np.nan)  # a failed read: the controller holds its last correction

        starts = np.zeros(n_ticks)
        deadlines = np.zeros(n_ticks)
        work = np.zeros(n_ticks)
        previous = np.asarray(present, dtype=np.int64).copy()
        last_present = previous.copy()
        non_finite = limited = failed_ticks = overruns = 0
        largest_correction = 0.0
        consecutive = 0
        first_failure: ServoCommError | None = None
        warned_non_finite = False
        done = 0
        log = PlaybackLog(self.log_path, smap.joints, smap.to_rad) if self.log_path is not None else None
        stop_exc: BaseException | None = None
        watchdog_units = int(round(cfg.watchdog_ms / (1e3 * ct.SECONDS_PER_WATCHDOG_UNIT)))
        watchdog_s = watchdog_units * ct.SECONDS_PER_WATCHDOG_UNIT
        if watchdog_units:  # armed now: from here on the host must talk at least every watchdog_s
            try:
                bus.set_bus_watchdog(ids, watchdog_units)
            except ServoError as exc:
                if log is not None:
                    log.close()
                raise HardwareError(f"arming the bus watchdog: {self._describe(exc)}") from None
        if cfg.realtime_priority and isinstance(clock, RealClock):
            priority = realtime_priority(cfg.realtime_priority)
        else:
            priority = contextlib.nullcontext("SCHED_OTHER")
        failed = False  # the present tick's bus I/O failed (counted once per tick)

        def comm_failure(exc: ServoCommError) -> ServoError | None:
            nonlocal failed, failed_ticks, consecutive, first_failure
            first_of_streak = not failed and consecutive == 0
            if not failed:
                failed = True
                failed_ticks += 1
                consecutive += 1
            # the first failure that names a servo is the best diagnosis: later ones can be
            # confused by late replies still arriving from the servo at fault
            if first_of_streak or first_failure is None or (
                    first_failure.servo_id is None and exc.servo_id is not None):
                first_failure = exc
            bus.reset()
            if consecutive > cfg.retry_budget:
                culprit = first_failure
                return ServoCommError(culprit.servo_id, f"{culprit.cause}; {consecutive} consecutive "
                                      f"failed ticks (retry budget {cfg.retry_budget})", culprit.port)
            return None

        signals: dict = {}
        with _stop_signals_raise(signals):
            t0 = deadline = last_write = clock.now()
            try:
                with priority as policy:
                    if cfg.realtime_priority and not policy.startswith(("SCHED_FIFO", "SCHED_OTHER")):
                        warnings.warn(f"control loop at {policy}; expect more jitter on a busy host", PlaybackWarning,
                                      stacklevel=2)
                    for k in range(n_ticks):
                        clock.sleep_until(deadline)
                        start = clock.now()
                        starts[k], deadlines[k] = start, deadline
                        if self.on_tick is not None:
                            self.on_tick(k, self)
                        present_now = gyro = accel = correction = None
                        fatal: ServoError | None = None
                        failed = False
                        sent = False

                        try:
                            silent = clock.now() - last_write
                            if watchdog_s and silent > 0.9 * watchdog_s:
                                # the host was silent long enough for the servos' watchdog to fire: they
                                # stopped and refuse goals, so streaming on would command nothing
                                fired = [i for i, v in bus.read_bus_watchdog(ids).items() if v == 0xFF]
                                if fired:
                                    fatal = ServoWatchdogError(
                                        fired[0], f"bus watchdog fired on {len(fired)} servo(s): the host was silent "
                                        f"for {silent * 1e3:.0f} ms (watchdog {cfg.watchdog_ms:g} ms), the servos "
                                        "stopped by themselves", bus.port_name)
                            if fatal is None and closed:
                                # closed loop: sense first (present positions + IMU in one bulk read)
                                try:
                                    if k % cfg.read_every == 0:
                                        present_now, gyro, accel = bus.read_present_positions_and_imu(ids)
                                        last_present = present_now
                                    else:
                                        gyro, accel = bus.read_imu()
                                except ServoCommError as exc:
                                    fatal = comm_failure(exc)
                        except ServoAlertError as exc:
                            fatal = exc
                        except ServoCommError as exc:
                            fatal = comm_failure(exc)
                        target = targets[k]
                        if fatal is None and closed and not is_ramp[k]:
                            if k == n_ramp:
                                controller.reset()  # t = 0 at the first trajectory frame, as validated
                            goal = smap.to_rad(target)
                            full_goal[cols] = goal
                            full_present = None
                            if present_now is not None:
                                full_present = full_goal.copy()
                                full_present[cols] = smap.to_rad(present_now)
                            corrected = controller.step(
                                (k - n_ramp) * period, full_goal[None],
                                (gyro if gyro is not None else no_imu)[None],
                                (accel if accel is not None else no_imu)[None],
                                None if full_present is None else full_present[None])[0, cols]
                            correction = corrected - goal
                            if np.isfinite(correction).any():
                                largest_correction = max(largest_correction,
                                                         float(np.nanmax(np.abs(correction))))
                            target = smap.ticks_float(corrected)
                        # the limiter is the last thing before the bus, corrected goals included
                        command, nf, lim = limit_command(target, previous, lo, hi, step)
                        if nf.any():
                            non_finite += int(nf.sum())
                            if not warned_non_finite:
                                bad = [self._label(i) for i in np.asarray(ids)[nf]]
                                warnings.warn(f"non-finite target at tick {k} for {', '.join(bad)}: holding the last "
                                              "safe command (further occurrences are counted, not warned)",
                                              PlaybackWarning, stacklevel=2)
                                warned_non_finite = True
                        limited += int(lim.sum())
                        if fatal is None:
                            try:
                                bus.write_goal_positions(ids, command)
                                sent = True
                                last_write = clock.now()
                                if not closed and k % cfg.read_every == 0:
                                    present_now = bus.read_present_positions(ids)
                                    last_present = present_now
                            except ServoAlertError as exc:
                                fatal = exc
                            except ServoCommError as exc:
                                fatal = comm_failure(exc)
                            if not failed:
                                consecutive = 0
                        if fatal is None or sent:
                            previous = command  # sent (a sync write has no reply to prove it arrived)
                        if log is not None:
                            log.write(start - t0, k, "ramp" if is_ramp[k] else "play", previous, present_now,
                                      gyro, accel, correction)
                        if fatal is not None:
                            done = k + 1
                            raise fatal
                        done = k + 1
                        end = clock.now()
                        work[k] = end - start
                        deadline += period
                        if end > deadline:
                            overruns += 1
                            deadline = end
            except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM, SIGHUP
                stop_exc = exc
            except ServoError as exc:
                stop_exc = exc
            signals["stopping"] = True  # from here on a signal cannot cut the stop short
            return self._finish(stop_exc, log, previous, last_present, t0, done, n_ticks, n_ramp, period,
                                starts, deadlines, work, overruns, non_finite, limited, failed_ticks,
                                closed, largest_correction, trajectory)

    def _finish(self, stop_exc, log, previous, last_present, t0, done, n_ticks, n_ramp, period, starts,
                deadlines, work, overruns, non_finite, limited, failed_ticks, closed, largest_correction,
                trajectory) -> PlaybackResult:
        """After the loop: statistics, then (stopped) the safe stop and the one-line error."""
        bus, ids, clock = self.bus, self.ids, self.clock
        n_done = max(done, 1) if stop_exc is not None else n_ticks
        stats = loop_stats(starts[:n_done], deadlines[:n_done], work[:n_done], period, overruns)
        result = PlaybackResult(
            stats=stats, ticks=done, ramp_ticks=min(n_ramp, done),
            trajectory_s=max(0, done - n_ramp - 1) * period, non_finite=non_finite, limited=limited,
            failed_ticks=failed_ticks, log_path=str(self.log_path) if self.log_path else None)
        if closed:
            result.extra["balance"] = {"loop": "closed", "imu_id": self.bus.imu_id,
                                       "max_correction_rad": round(largest_correction, 6)}
        elif getattr(trajectory, "plan", None) is not None:
            result.extra["balance"] = {"loop": "open (--no-balance; validated closed loop)"}
        if stop_exc is None:
            if log is not None:
                log.close()
            try:
                bus.set_bus_watchdog(ids, 0)  # keep holding the last pose without a watchdog
            except ServoError as exc:
                warnings.warn(f"finished, but could not disarm the bus watchdog ({self._describe(exc)}); the servos "
                              "hold their last goal and refuse new ones until it is cleared", PlaybackWarning,
                              stacklevel=3)
            self._write_stats(result)
            if non_finite:
                warnings.warn(f"{non_finite} non-finite servo targets were replaced by the last safe command",
                              PlaybackWarning, stacklevel=3)
            if limited:
                warnings.warn(f"{limited} servo targets were clamped to the position limits or the per-tick step "
                              "limit (commanded positions are in the log)", PlaybackWarning, stacklevel=3)
            return result

        action = self._safe_stop(previous, last_present, log, clock.now() - t0, done)
        if log is not None:
            log.close()
        when = f"playback stopped at t={done * period:.2f} s (tick {done}/{n_ticks})"
        where = f"; log: {self.log_path}" if self.log_path else ""
        result.completed = False
        if isinstance(stop_exc, KeyboardInterrupt):
            number = getattr(stop_exc, "signal_number", int(signal.SIGINT))
            result.stopped_because = f"interrupted ({_signal_label(number)})"
            self._write_stats(result)
            raise PlaybackInterrupted(f"interrupted ({_signal_label(number)}); {when}; {action}{where}",
                                      number) from None
        result.stopped_because = self._describe(stop_exc)
        self._write_stats(result)
        raise HardwareError(f"{self._describe(stop_exc)}; {when}; {action}{where}") from None

    def _safe_stop(self, last_command: np.ndarray, last_present: np.ndarray, log: PlaybackLog | None,
                   time_s: float, tick: int) -> str:
        """Put every servo that still answers into the configured safe state, write the final
        log row (``hold``: the hold command; ``torque_off``: the last command and the
        positions read after switching off); say what happened."""
        bus, ids, smap = self.bus, self.ids, self.map
        bus.reset()
        if self.config.on_stop == ON_STOP_HOLD:
            try:
                present = bus.read_present_positions(ids, allow_alert=True)
            except ServoError:
                present = None
            source = present if present is not None else last_command
            hold = np.clip(np.asarray(source, dtype=np.int64), smap.min_ticks, smap.max_ticks)
            try:
                bus.write_goal_positions(ids, hold)
            except ServoError as exc:
                if log is not None:
                    log.write(time_s, tick, "hold", np.asarray(last_command, dtype=np.int64), present)
                return f"could not command the hold position ({self._describe(exc)})"
            if log is not None:
                log.write(time_s, tick, "hold", hold, present)
            what = "present" if present is not None else "last commanded"
            return f"servos that answer are holding their {what} position (torque on)"
        failed = []
        for servo_id in ids:
            try:
                bus.set_torque([servo_id], False)
            except ServoAlertError:
                pass  # the write went through; the alert bit only repeats the hardware error
            except ServoError as exc:
                failed.append(f"{self._label(servo_id)} ({exc.cause})")
        if log is not None:
            try:
                bus.reset()
                present = bus.read_present_positions(ids, allow_alert=True)
            except ServoError:
                present = None
            log.write(time_s, tick, "torque_off", np.asarray(last_command, dtype=np.int64), present)
        if failed:
            return "torque switched off except on " + ", ".join(failed)
        return "torque switched off on every servo"

    def _write_stats(self, result: PlaybackResult) -> None:
        if self.log_path is None:
            return
        path = self.log_path.with_name(self.log_path.stem + ".stats.json")
        path.write_text(json.dumps(result.as_dict(), indent=2) + "\n", encoding="utf-8")


# ----------------------------------------------------------------------------- one call
def play_file(trajectory_path: str | Path, robot, bus: ServoBus, *, config: PlaybackConfig | None = None,
              report_path: str | Path | None = None, force: bool = False, log_path: str | Path | None = None,
              clock=None, on_tick=None) -> PlaybackResult:
    """Gate on the validation report, load ``robot.npz`` for ``robot``, pre-flight and play."""
    digest = getattr(robot, "description_sha256", None)
    check_validation_report(trajectory_path, report_path, force=force, robot_name=robot.name, robot_sha256=digest)
    servo_map = ServoMap.from_specs(robot.servos)
    trajectory = load_trajectory(trajectory_path, servo_map, robot.name, report_path, robot_sha256=digest)
    streamer = Streamer(bus, servo_map, config, clock=clock, log_path=log_path, on_tick=on_tick,
                        joint_range=robot_joint_ranges(robot))
    streamer.preflight(trajectory)
    return streamer.play(trajectory)


def robot_joint_ranges(robot) -> dict[str, tuple[float, float]]:
    """``{joint: (low, high)}`` rad of ``robot`` (what validation's controller clamps to)."""
    names = getattr(robot, "joint_names", None)
    ranges = getattr(robot, "joint_range", None)
    if names is None or ranges is None:
        return {}
    return {str(n): (float(r[0]), float(r[1])) for n, r in zip(names, np.asarray(ranges))}
