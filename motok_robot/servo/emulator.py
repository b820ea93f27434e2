# Size (630 lines): one emulated device: control table, Protocol 2.0 packet parsing and the servo model.
"""An emulated chain of Dynamixel X-series servos, as an in-memory ``dynamixel_sdk.PortHandler``.

Give :class:`EmulatedServoChain` to :class:`~motok_robot.servo.bus.DynamixelBus` as its
``port_handler``: the real SDK then builds every instruction packet and parses every status
packet, and the emulated servos parse and answer them with Protocol 2.0 framing (header,
byte stuffing, CRC-16) from :mod:`motok_robot.servo.protocol`.

What is emulated
  * per-ID control tables (X-series layout, model number e.g. XM430-W350 = 1020);
  * PING (single and broadcast), READ, WRITE, SYNC WRITE, SYNC READ, FAST SYNC READ and
    BULK READ (each listed device answers in turn with its own status packet);
  * the torso IMU of the ROBOTIS OP3 (:class:`EmulatedOpenCR`, the OpenCR sub-controller at
    ID 200): button, voltage, gyro and accelerometer registers (:mod:`motok_robot.servo.imu`)
    that tests set (:meth:`EmulatedOpenCR.set_counts`, :meth:`EmulatedOpenCR.set_motion`);
    the faults below apply to it as to a servo;
  * access rules: read-only registers, EEPROM writable only with torque off, Goal Position
    outside the Min/Max Position Limit registers rejected (data limit error);
  * Return Delay Time (address 9, 2 us per unit) delays each reply in real time;
  * the bus watchdog (address 98): when no instruction reached a servo for longer than the
    watchdog time, it sets the register to 255 and ignores Goal Position until 0 is written;
  * a first-order position response: the present position approaches the goal with time
    constant ``time_constant_s`` and a speed cap of the Profile Velocity (or the Velocity
    Limit register when the profile velocity is 0), advanced by ``clock`` (seconds);
  * every Goal Position a servo decoded is kept in ``servo.goal_history`` (ticks, in order).

Injectable faults (:meth:`EmulatedServoChain.disconnect`, ``drop_replies``,
``corrupt_replies``, ``slow_replies``, ``set_hardware_error``): a servo that disappears (no
reply, ignores writes), no reply for N packets or forever (timeout), status packets with one
bit flipped on the wire (CRC mismatch), replies delayed by a fixed time, hardware-error bits
(Hardware Error Status 70, alert bit 0x80 in every status packet, torque off).

Choices where the real firmware's behaviour is not modelled: there is no wire-time model (bytes
arrive after the return delay only); switching torque on copies the present position into Goal
Position; in a Fast Sync Read the chain stops at the first servo that does not answer.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from dynamixel_sdk import PortHandler

from motok_robot.servo import control_table as ct
from motok_robot.servo import protocol as pr

_SUPPORTED_BAUDS = set(ct.BAUD_RATE_VALUES.values())
_BAUD_REGISTER = {bps: value for value, bps in ct.BAUD_RATE_VALUES.items()}


@dataclass
class ServoFaults:
    """Faults injected into one emulated servo (counts: -1 = forever, 0 = off)."""

    disconnected: bool = False
    drop_replies: int = 0
    corrupt_replies: int = 0
    reply_delay_s: float = 0.0


@dataclass
class EmulatedServo:
    """One emulated X-series servo: control table, position state and fault switches.

    ``position`` is the true shaft position in (fractional) ticks.
    """

    servo_id: int
    model: str = "XM430-W350"
    position: float = 2048.0
    min_position: int = 0
    max_position: int = 4095
    baud: int = 2_000_000
    time_constant_s: float = 0.02
    table: bytearray = field(default_factory=lambda: bytearray(ct.CONTROL_TABLE_SIZE))
    faults: ServoFaults = field(default_factory=ServoFaults)
    goal_history: list[int] = field(default_factory=list)
    rejected_goals: int = 0
    last_instruction_time: float | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.servo_id <= 252:
            raise ValueError(f"servo ID {self.servo_id} outside 0..252")
        self.poke(ct.ADDR_MODEL_NUMBER, 2, ct.model_number(self.model))
        self.poke(ct.ADDR_FIRMWARE_VERSION, 1, 46)
        self.poke(ct.ADDR_ID, 1, self.servo_id)
        self.poke(ct.ADDR_BAUD_RATE, 1, _BAUD_REGISTER[self.baud])
        self.poke(ct.ADDR_RETURN_DELAY_TIME, 1, 250)
        self.poke(ct.ADDR_OPERATING_MODE, 1, ct.OPERATING_MODE_POSITION)
        self.poke(ct.ADDR_VELOCITY_LIMIT, 4, ct.DEFAULT_VELOCITY_LIMIT_UNITS.get(self.model, 200))
        self.poke(ct.ADDR_MAX_POSITION_LIMIT, 4, self.max_position)
        self.poke(ct.ADDR_MIN_POSITION_LIMIT, 4, self.min_position)
        self.poke(ct.ADDR_SHUTDOWN, 1, 0b110100)
        self.poke(ct.ADDR_STATUS_RETURN_LEVEL, 1, 2)
        self.poke(ct.ADDR_PRESENT_INPUT_VOLTAGE, 2, 120)
        self.poke(ct.ADDR_PRESENT_TEMPERATURE, 1, 30)
        self.poke(ct.ADDR_GOAL_POSITION, 4, int(round(self.position)))
        self._sync_present()

    # ---------------------------------------------------------------- table access
    def peek(self, address: int, size: int, signed: bool = False) -> int:
        return int.from_bytes(self.table[address:address + size], "little", signed=signed)

    def poke(self, address: int, size: int, value: int) -> None:
        self.table[address:address + size] = (int(value) & ((1 << (8 * size)) - 1)).to_bytes(size, "little")

    @property
    def torque_enabled(self) -> bool:
        return self.table[ct.ADDR_TORQUE_ENABLE] == ct.TORQUE_ON

    @property
    def hardware_error(self) -> int:
        return self.table[ct.ADDR_HARDWARE_ERROR_STATUS]

    @property
    def present_position(self) -> int:
        return self.peek(ct.ADDR_PRESENT_POSITION, 4, signed=True)

    @property
    def goal_position(self) -> int:
        return self.peek(ct.ADDR_GOAL_POSITION, 4, signed=True)

    def _sync_present(self, velocity_ticks_s: float = 0.0) -> None:
        self.poke(ct.ADDR_PRESENT_POSITION, 4, int(round(self.position)))
        rpm = velocity_ticks_s / 4096.0 * 60.0
        self.poke(ct.ADDR_PRESENT_VELOCITY, 4, int(round(rpm / ct.RPM_PER_VELOCITY_UNIT)))
        self.poke(ct.ADDR_MOVING, 1, int(abs(velocity_ticks_s) > 1.0))

    def advance(self, dt: float) -> None:
        """Move the shaft toward the goal for ``dt`` seconds (first order, speed capped)."""
        if dt <= 0.0:
            return
        if not self.torque_enabled or self.hardware_error:
            self._sync_present()
            return
        units = self.peek(ct.ADDR_PROFILE_VELOCITY, 4) or self.peek(ct.ADDR_VELOCITY_LIMIT, 4)
        speed = units * ct.RPM_PER_VELOCITY_UNIT / 60.0 * 4096.0  # ticks/s
        error = self.goal_position - self.position
        step = error * (1.0 - math.exp(-dt / self.time_constant_s))
        step = max(-speed * dt, min(speed * dt, step))
        self.position += step
        self._sync_present(step / dt)

    # ---------------------------------------------------------------- instructions
    def write(self, address: int, data: bytes, now: float) -> int:
        """Apply a WRITE; returns the status error number (0 = ok)."""
        size = len(data)
        if size == 0 or address + size > ct.CONTROL_TABLE_SIZE:
            return pr.ERROR_DATA_LENGTH
        for start, length in ct.READ_ONLY_RANGES:
            if address < start + length and start < address + size:
                return pr.ERROR_ACCESS
        if address < ct.EEPROM_END and self.torque_enabled:
            return pr.ERROR_ACCESS
        value = int.from_bytes(data, "little", signed=True)
        if address == ct.ADDR_TORQUE_ENABLE and size == 1:
            if data[0] == ct.TORQUE_ON and self.hardware_error:
                return 1  # result fail: torque cannot come back before a reboot
            if data[0] == ct.TORQUE_ON and not self.torque_enabled:
                self.poke(ct.ADDR_GOAL_POSITION, 4, self.present_position)
        if address <= ct.ADDR_GOAL_POSITION < address + size:
            if address != ct.ADDR_GOAL_POSITION or size != 4:
                return pr.ERROR_DATA_LENGTH
            if self.table[ct.ADDR_BUS_WATCHDOG] == 0xFF:
                self.rejected_goals += 1
                return pr.ERROR_DATA_LIMIT
            if not self.min_limit <= value <= self.max_limit:
                self.rejected_goals += 1
                return pr.ERROR_DATA_LIMIT
            self.goal_history.append(value)
        self.table[address:address + size] = data
        return 0

    @property
    def min_limit(self) -> int:
        return self.peek(ct.ADDR_MIN_POSITION_LIMIT, 4, signed=True)

    @property
    def max_limit(self) -> int:
        return self.peek(ct.ADDR_MAX_POSITION_LIMIT, 4, signed=True)

    def touch(self, now: float) -> None:
        """An instruction reached this servo at ``now``: check the bus watchdog first."""
        units = self.table[ct.ADDR_BUS_WATCHDOG]
        if (0 < units <= 127 and self.last_instruction_time is not None
                and now - self.last_instruction_time > units * ct.SECONDS_PER_WATCHDOG_UNIT):
            self.table[ct.ADDR_BUS_WATCHDOG] = 0xFF
            self.poke(ct.ADDR_GOAL_POSITION, 4, self.present_position)
        self.last_instruction_time = now

    def error_byte(self, error: int = 0) -> int:
        return (error & 0x7F) | (ct.STATUS_ALERT_BIT if self.hardware_error else 0)


@dataclass
class EmulatedOpenCR(EmulatedServo):
    """The OpenCR sub-controller of a ROBOTIS OP3 at ``servo_id`` (200): the IMU registers of
    :mod:`motok_robot.servo.imu`, read-only to the host.  At rest it reads 1 g up the sensor's z.

    It has no position dynamics and no Hardware Error Status register: :attr:`alert_bits`
    (set with :meth:`EmulatedServoChain.set_hardware_error`) raises the alert bit of its status
    packets.  Values are set in register counts (:meth:`set_counts`) or in sensor-axis
    physical units (:meth:`set_motion`: rad/s, m/s^2).
    """

    model: str = "OpenCR"
    alert_bits: int = 0

    def __post_init__(self) -> None:
        from motok_robot.servo import imu

        if not 0 <= self.servo_id <= 252:
            raise ValueError(f"device ID {self.servo_id} outside 0..252")
        self.poke(ct.ADDR_MODEL_NUMBER, 2, imu.OPENCR_MODEL_NUMBER)
        self.poke(ct.ADDR_FIRMWARE_VERSION, 1, 6)
        self.poke(ct.ADDR_ID, 1, self.servo_id)
        self.poke(ct.ADDR_BAUD_RATE, 1, _BAUD_REGISTER[self.baud])
        self.poke(ct.ADDR_RETURN_DELAY_TIME, 1, 0)
        self.poke(imu.ADDR_PRESENT_VOLTAGE, 1, 120)
        self.set_counts(gyro=(0, 0, 0), accel=(0, 0, int(round(1.0 / imu.G_PER_ACCEL_COUNT))))

    @property
    def hardware_error(self) -> int:
        return self.alert_bits

    def set_counts(self, gyro=None, accel=None, roll_pitch_yaw=None) -> None:
        """Raw int16 register values (sensor axes x, y, z) of the gyro (2000/32800 deg/s per
        count), the accelerometer (2/32768 g per count) and the roll/pitch/yaw estimate."""
        from motok_robot.servo import imu

        for address, values in ((imu.ADDR_GYRO, gyro), (imu.ADDR_ACCEL, accel),
                                (imu.ADDR_ROLL_PITCH_YAW, roll_pitch_yaw)):
            if values is None:
                continue
            for k, value in enumerate(values):
                value = int(value)
                if not -32768 <= value <= 32767:
                    raise ValueError(f"IMU register {address + 2 * k}: {value} outside int16")
                self.poke(address + 2 * k, 2, value)

    def set_motion(self, gyro_rad_s=None, accel_m_s2=None) -> None:
        """Gyro (rad/s) and specific force (m/s^2) along the sensor's own axes, as counts."""
        from motok_robot.servo import imu

        self.set_counts(gyro=None if gyro_rad_s is None else imu.gyro_counts(gyro_rad_s),
                        accel=None if accel_m_s2 is None else imu.accel_counts(accel_m_s2))

    def counts(self) -> tuple[list[int], list[int]]:
        """(gyro, accelerometer) register counts as set."""
        from motok_robot.servo import imu

        return ([self.peek(imu.ADDR_GYRO + 2 * k, 2, signed=True) for k in range(3)],
                [self.peek(imu.ADDR_ACCEL + 2 * k, 2, signed=True) for k in range(3)])

    def advance(self, dt: float) -> None:
        return  # no actuator

    def write(self, address: int, data: bytes, now: float) -> int:
        from motok_robot.servo import imu

        size = len(data)
        if size == 0 or address + size > ct.CONTROL_TABLE_SIZE:
            return pr.ERROR_DATA_LENGTH
        if address < imu.ADDR_ROLL_PITCH_YAW + 6 and imu.ADDR_BUTTON < address + size:
            return pr.ERROR_ACCESS  # sensor registers are read-only
        if address < ct.ADDR_ID + 1 and ct.ADDR_MODEL_NUMBER < address + size:
            return pr.ERROR_ACCESS
        self.table[address:address + size] = data
        return 0

    def touch(self, now: float) -> None:
        self.last_instruction_time = now  # no bus watchdog


class EmulatedServoChain(PortHandler):
    """A ``PortHandler`` whose wire is a chain of :class:`EmulatedServo` in memory.

    Args:
        servos: the emulated servos (IDs must be unique).
        port_name: label shown in messages.
        clock: time source (seconds) for the servo dynamics and the bus watchdog; pass the
            streamer's fake clock in tests so the servos move in the streamer's time.
        latency_timer_ms: the emulated adapter's latency, used by ``setPacketTimeout`` (the SDK
            waits ``2 * latency + 2 ms`` plus the wire time before giving up on a reply).
        baud: the rate the servos listen at; a host opening the port at another baud gets no replies.
    """

    def __init__(
        self,
        servos: Iterable[EmulatedServo],
        *,
        port_name: str = "emulated",
        clock: Callable[[], float] = time.perf_counter,
        latency_timer_ms: float = 1.0,
    ):
        super().__init__(port_name)
        self.servos: dict[int, EmulatedServo] = {}
        for servo in servos:
            if servo.servo_id in self.servos:
                raise ValueError(f"duplicate emulated servo ID {servo.servo_id}")
            self.servos[servo.servo_id] = servo
        self.clock = clock
        self.latency_timer_ms = float(latency_timer_ms)
        self._parser = pr.PacketParser()
        self._pending: list[tuple[float, bytes]] = []  # (ready time, bytes) not yet on the wire
        self._rx = bytearray()  # bytes that reached the host
        self._last_advance = clock()
        self.packets_received = 0
        self.bad_packets = 0

    @classmethod
    def from_ids(cls, ids: Sequence[int], *, model: str = "XM430-W350", positions: Sequence[float] | None = None,
                 limits: Sequence[tuple[int, int]] | None = None, baud: int = 2_000_000, **kwargs):
        """A chain of identical servos with the given IDs, start positions and limits (ticks)."""
        servos = []
        for k, servo_id in enumerate(ids):
            lo, hi = limits[k] if limits is not None else (0, 4095)
            pos = float(positions[k]) if positions is not None else 2048.0
            servos.append(EmulatedServo(int(servo_id), model=model, position=pos, min_position=int(lo),
                                        max_position=int(hi), baud=baud))
        return cls(servos, **kwargs)

    # ------------------------------------------------------------------ fault injection
    def _servo(self, servo_id: int) -> EmulatedServo:
        return self.servos[int(servo_id)]

    def disconnect(self, servo_id: int) -> None:
        """The servo disappears: no replies, writes ignored (a broken cable)."""
        self._servo(servo_id).faults.disconnected = True

    def reconnect(self, servo_id: int) -> None:
        self._servo(servo_id).faults.disconnected = False

    def drop_replies(self, servo_id: int, count: int = -1) -> None:
        """Drop the servo's next ``count`` replies (-1: all) -> the host times out."""
        self._servo(servo_id).faults.drop_replies = count

    def corrupt_replies(self, servo_id: int, count: int = -1) -> None:
        """Flip one bit of the servo's next ``count`` replies (-1: all) -> CRC mismatch."""
        self._servo(servo_id).faults.corrupt_replies = count

    def slow_replies(self, servo_id: int, delay_s: float) -> None:
        """Delay every reply of the servo by ``delay_s`` seconds (on top of its return delay)."""
        self._servo(servo_id).faults.reply_delay_s = float(delay_s)

    @property
    def imu(self) -> "EmulatedOpenCR | None":
        """The emulated OpenCR (IMU) on this chain, or None."""
        return next((s for s in self.servos.values() if isinstance(s, EmulatedOpenCR)), None)

    def set_hardware_error(self, servo_id: int, bits: int) -> None:
        """Raise Hardware Error Status bits (e.g. 0x20 overload); torque switches off.  On the
        OpenCR: the alert bit of its status packets."""
        servo = self._servo(servo_id)
        if isinstance(servo, EmulatedOpenCR):
            servo.alert_bits = bits & 0xFF
            return
        servo.table[ct.ADDR_HARDWARE_ERROR_STATUS] = bits & 0xFF
        if bits:
            servo.table[ct.ADDR_TORQUE_ENABLE] = ct.TORQUE_OFF

    # ------------------------------------------------------------------ PortHandler API
    def openPort(self):  # noqa: N802 (SDK naming)
        return self.setBaudRate(self.baudrate)

    def setBaudRate(self, baudrate):  # noqa: N802
        if baudrate not in _SUPPORTED_BAUDS:
            return False
        self.baudrate = baudrate
        return self.setupPort(baudrate)

    def setupPort(self, cflag_baud):  # noqa: N802
        self.is_open = True
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        self._rx.clear()
        return True

    def closePort(self):  # noqa: N802
        self.is_open = False

    def clearPort(self):  # noqa: N802
        self._collect()
        self._rx.clear()

    def getBytesAvailable(self):  # noqa: N802
        self._collect()
        return len(self._rx)

    def readPort(self, length):  # noqa: N802
        self._collect()
        out = bytes(self._rx[:length])
        del self._rx[:length]
        return out

    def writePort(self, packet):  # noqa: N802
        if not self.is_open:
            return 0
        data = bytes(packet)
        now = time.perf_counter()
        self._advance_servos()
        for inst in self._parser.feed(data):
            self.packets_received += 1
            self._dispatch(inst, now)
        return len(data)

    def setPacketTimeout(self, packet_length):  # noqa: N802
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * self.latency_timer_ms + 2.0

    def isPacketTimeout(self):  # noqa: N802
        # A reply that reached the wire before the deadline is not a timeout, even when this
        # process was descheduled past the deadline before reading it (the SDK checks the time
        # after an empty read without reading again; on a loaded machine that misfires).
        if self.getTimeSinceStart() <= self.packet_timeout:
            return False
        deadline = (self.packet_start_time + self.packet_timeout) / 1000.0
        if self._rx or any(ready <= deadline for ready, _ in self._pending):
            return False
        self.packet_timeout = 0
        return True

    def getCurrentTime(self):  # noqa: N802 (monotonic ms)
        return time.perf_counter() * 1000.0

    # ------------------------------------------------------------------ internals
    def _collect(self) -> None:
        if not self._pending:
            return
        now = time.perf_counter()
        still = []
        for ready, data in self._pending:
            if ready <= now:
                self._rx.extend(data)
            else:
                still.append((ready, data))
        self._pending = still

    def _advance_servos(self) -> None:
        now = self.clock()
        dt = now - self._last_advance
        if dt > 0:
            for servo in self.servos.values():
                servo.advance(dt)
            self._last_advance = now

    def _listening(self, servo_id: int) -> EmulatedServo | None:
        servo = self.servos.get(servo_id)
        if servo is None or servo.faults.disconnected:
            return None
        if ct.BAUD_RATE_VALUES.get(servo.table[ct.ADDR_BAUD_RATE]) != self.baudrate:
            return None
        return servo

    def _reply_allowed(self, servo: EmulatedServo) -> bool:
        faults = servo.faults
        if faults.drop_replies:
            if faults.drop_replies > 0:
                faults.drop_replies -= 1
            return False
        return True

    def _corrupt(self, servo: EmulatedServo, packet: bytes, position: int) -> bytes:
        faults = servo.faults
        if not faults.corrupt_replies:
            return packet
        if faults.corrupt_replies > 0:
            faults.corrupt_replies -= 1
        out = bytearray(packet)
        out[position] ^= 0x01
        return bytes(out)

    def _delay(self, servo: EmulatedServo) -> float:
        return servo.table[ct.ADDR_RETURN_DELAY_TIME] * ct.SECONDS_PER_RETURN_DELAY_UNIT + servo.faults.reply_delay_s

    def _send(self, servo: EmulatedServo, error: int, params: bytes, start: float) -> float:
        """Queue a status packet from ``servo``; returns when its last byte is on the wire."""
        if not self._reply_allowed(servo):
            return start
        packet = pr.build_status(servo.servo_id, servo.error_byte(error), params)
        packet = self._corrupt(servo, packet, len(packet) - 3)
        ready = start + self._delay(servo)
        self._pending.append((ready, packet))
        return ready

    def _dispatch(self, inst: pr.Instruction, now: float) -> None:
        if not inst.crc_ok:
            self.bad_packets += 1
            return
        clock_now = self.clock()
        op, params = inst.instruction, inst.params
        if inst.servo_id == pr.BROADCAST_ID:
            if op == pr.INST_PING:
                t = now
                for servo_id in sorted(self.servos):
                    servo = self._listening(servo_id)
                    if servo is not None:
                        servo.touch(clock_now)
                        t = self._send(servo, 0, self._ping_params(servo), t)
            elif op == pr.INST_SYNC_WRITE:
                self._sync_write(params, clock_now)
            elif op in (pr.INST_SYNC_READ, pr.INST_FAST_SYNC_READ):
                self._sync_read(params, now, clock_now, fast=op == pr.INST_FAST_SYNC_READ)
            elif op == pr.INST_BULK_READ:
                self._bulk_read(params, now, clock_now)
            elif op == pr.INST_WRITE and len(params) > 2:
                for servo_id in self.servos:
                    servo = self._listening(servo_id)
                    if servo is not None:
                        servo.touch(clock_now)
                        servo.write(params[0] | (params[1] << 8), params[2:], clock_now)
            return
        servo = self._listening(inst.servo_id)
        if servo is None:
            return
        servo.touch(clock_now)
        if op == pr.INST_PING:
            self._send(servo, 0, self._ping_params(servo), now)
        elif op == pr.INST_READ:
            if len(params) != 4:
                self._send(servo, pr.ERROR_DATA_LENGTH, b"", now)
                return
            address, size = params[0] | (params[1] << 8), params[2] | (params[3] << 8)
            if address + size > ct.CONTROL_TABLE_SIZE:
                self._send(servo, pr.ERROR_DATA_RANGE, b"", now)
                return
            self._send(servo, 0, bytes(servo.table[address:address + size]), now)
        elif op == pr.INST_WRITE:
            if len(params) < 3:
                self._send(servo, pr.ERROR_DATA_LENGTH, b"", now)
                return
            error = servo.write(params[0] | (params[1] << 8), params[2:], clock_now)
            self._send(servo, error, b"", now)
        elif op == pr.INST_REBOOT:
            self._send(servo, 0, b"", now)
            servo.table[ct.ADDR_HARDWARE_ERROR_STATUS] = 0
            servo.table[ct.ADDR_TORQUE_ENABLE] = ct.TORQUE_OFF
        else:
            self._send(servo, pr.ERROR_INSTRUCTION, b"", now)

    @staticmethod
    def _ping_params(servo: EmulatedServo) -> bytes:
        return bytes(servo.table[ct.ADDR_MODEL_NUMBER:ct.ADDR_MODEL_NUMBER + 2]) + bytes(
            [servo.table[ct.ADDR_FIRMWARE_VERSION]])

    def _sync_write(self, params: bytes, clock_now: float) -> None:
        if len(params) < 4:
            return
        address, size = params[0] | (params[1] << 8), params[2] | (params[3] << 8)
        body = params[4:]
        stride = 1 + size
        for k in range(len(body) // stride):
            chunk = body[k * stride:(k + 1) * stride]
            servo = self._listening(chunk[0])
            if servo is not None:
                servo.touch(clock_now)
                servo.write(address, chunk[1:], clock_now)

    def _sync_read(self, params: bytes, now: float, clock_now: float, fast: bool) -> None:
        if len(params) < 5:
            return
        address, size = params[0] | (params[1] << 8), params[2] | (params[3] << 8)
        ids = list(params[4:])
        if not fast:
            t = now
            for servo_id in ids:
                servo = self._listening(servo_id)
                if servo is None:
                    continue  # the host times out waiting for this one
                servo.touch(clock_now)
                t = self._send(servo, 0, bytes(servo.table[address:address + size]), t)
            return
        # Fast Sync Read: one status packet; each servo appends error, ID, data and a CRC of the
        # packet so far; the last CRC is the packet's.  Total length is fixed by the first servo.
        length = 1 + (size + 4) * len(ids)  # instruction + segments (LEN counts the final CRC)
        packet = bytearray(pr.HEADER + bytes([pr.BROADCAST_ID, length & 0xFF, length >> 8, pr.INST_STATUS]))
        ready = now
        noisy = []  # servos whose bytes get a bit flipped on the wire (after all CRCs are made)
        for servo_id in ids:
            servo = self._listening(servo_id)
            if servo is None or not self._reply_allowed(servo):
                break  # the chain stops: the host sees a short packet and times out
            servo.touch(clock_now)
            packet += bytes([servo.error_byte(0), servo_id]) + bytes(servo.table[address:address + size])
            crc = pr.crc16(packet)
            packet += bytes([crc & 0xFF, crc >> 8])
            noisy.append((servo, len(packet) - 3))
            ready += self._delay(servo)
        out = bytes(packet)
        for servo, position in noisy:
            out = self._corrupt(servo, out, position)
        self._pending.append((ready, out))


    def _bulk_read(self, params: bytes, now: float, clock_now: float) -> None:
        # Protocol 2.0 Bulk Read: (ID, address, length) per device; each answers in list order
        t = now
        for k in range(len(params) // 5):
            chunk = params[5 * k:5 * k + 5]
            servo = self._listening(chunk[0])
            if servo is None:
                continue  # the host times out waiting for this one
            address, size = chunk[1] | (chunk[2] << 8), chunk[3] | (chunk[4] << 8)
            servo.touch(clock_now)
            if address + size > ct.CONTROL_TABLE_SIZE:
                t = self._send(servo, pr.ERROR_DATA_RANGE, b"", t)
                continue
            t = self._send(servo, 0, bytes(servo.table[address:address + size]), t)


def emulated_chain(servo_map, *, baud: int = 2_000_000, positions: Sequence[float] | None = None,
                   clock: Callable[[], float] = time.perf_counter, imu_id: int | None = None,
                   **kwargs) -> EmulatedServoChain:
    """An emulated chain matching a :class:`~motok_robot.servo.convert.ServoMap`.

    Same IDs and models, Min/Max Position Limit registers = the map's tick limits, servos
    listening at ``baud``, starting at ``positions`` (ticks [n]; default: the zero pose).
    With ``imu_id`` an :class:`EmulatedOpenCR` (the IMU) answers at that ID too.
    """
    start = servo_map.zero_ticks() if positions is None else positions
    servos = [
        EmulatedServo(int(servo_id), model=model, position=float(p), min_position=int(lo), max_position=int(hi),
                      baud=baud)
        for servo_id, model, p, lo, hi in zip(servo_map.ids, servo_map.models, start, servo_map.min_ticks,
                                               servo_map.max_ticks)
    ]
    if imu_id is not None:
        servos.append(EmulatedOpenCR(int(imu_id), baud=baud))
    return EmulatedServoChain(servos, clock=clock, **kwargs)
