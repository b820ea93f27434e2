# Size (588 lines): the ServoBus seam and its one real implementation, DynamixelBus, side by side.
"""The servo bus seam: one :class:`ServoBus` interface and the real :class:`DynamixelBus`.

Everything that talks to servos goes through :class:`ServoBus`.  Positions cross it as integer
ticks (int64 arrays, one entry per requested servo ID, in the order of the ``ids`` argument).
Three implementations exist:

* :class:`DynamixelBus` (this module): ``dynamixel_sdk`` ``PortHandler`` + Protocol 2.0
  ``PacketHandler``, sync write of Goal Position and (fast) sync read of Present Position.
  With ``imu`` (the OP3's OpenCR at ID 200, :mod:`motok_robot.servo.imu`) it also reads the
  torso IMU, together with the present positions in one Bulk Read.
  Its ``port_handler`` argument is the seam: pass an
  :class:`~motok_robot.servo.emulator.EmulatedServoChain` and the real SDK builds and parses
  every packet against emulated servos.
* :class:`~motok_robot.servo.emulator.EmulatedServoChain` (a ``PortHandler`` in memory).
* :class:`~motok_robot.servo.sim_rig.SimRig`: the servos are the MuJoCo model's actuators.

Errors raised by a bus are :class:`ServoError` subclasses (all :class:`HardwareError`):
:class:`ServoCommError` (no status packet, corrupt status packet, port failure: may be
retried) and :class:`ServoAlertError` (the servo reports a hardware error: never retried).

Latency and baud rate.  A Protocol 2.0 round trip costs the bytes on the wire (10 bits per
byte: 5 us per byte at 2 Mbit/s), each servo's Return Delay Time (factory 250 = 0.5 ms; we
set 0) and the USB-serial adapter's latency timer (FTDI default 16 ms; set it to 1 ms with
``echo 1 | sudo tee /sys/bus/usb-serial/devices/ttyUSB0/latency_timer``).  With the latency
timer at 16 ms a 125 Hz loop that reads positions cannot keep up.  :class:`DynamixelBus`
reads the adapter's latency timer from sysfs where it exists and sizes its packet timeouts
from it (``latency_timer_ms``).
"""

from __future__ import annotations

import abc
import os
import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from dynamixel_sdk import (
    BROADCAST_ID,
    COMM_NOT_AVAILABLE,
    COMM_RX_CORRUPT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from motok_robot.errors import HardwareError
from motok_robot.servo import control_table as ct

DEFAULT_BAUD = 2_000_000


class ServoError(HardwareError):
    """A servo or the bus failed. ``servo_id`` is None when no single servo is to blame."""

    def __init__(self, servo_id: int | None, cause: str, port: str = ""):
        self.servo_id = servo_id
        self.cause = cause
        self.port = port
        super().__init__(self.describe())

    def describe(self, joint_names: dict[int, str] | None = None) -> str:
        where = f" on {self.port}" if self.port else ""
        if self.servo_id is None:
            return f"servo bus{where}: {self.cause}"
        joint = (joint_names or {}).get(self.servo_id)
        label = f"servo {self.servo_id}" + (f" ({joint})" if joint else "")
        return f"{label}{where}: {self.cause}"


class ServoCommError(ServoError):
    """No status packet, a corrupt one, or a transmit failure (a retry may succeed)."""


class ServoRejectedError(ServoError):
    """The servo answered but refused the instruction (access, range, limit error ...)."""


class ServoWatchdogError(ServoError):
    """The servo's bus watchdog fired (the host was silent too long): it stopped and refuses goals."""


class ServoAlertError(ServoError):
    """The servo raised its hardware-alert bit; ``bits`` is its Hardware Error Status (70)."""

    def __init__(self, servo_id: int, bits: int | None, port: str = ""):
        self.bits = bits
        if bits is None:
            cause = "hardware error (alert bit set; Hardware Error Status unreadable)"
        else:
            cause = f"hardware error: {ct.describe_hardware_error(bits)} (Hardware Error Status 0x{bits:02x})"
        super().__init__(servo_id, cause, port)


class ServoBus(abc.ABC):
    """Interface every servo bus implements. Positions are ticks; ``ids`` fix the order."""

    port_name: str = ""

    @abc.abstractmethod
    def ping(self, servo_id: int) -> int:
        """Model number of ``servo_id``; raises :class:`ServoCommError` if it does not answer."""

    def read_model_numbers(self, ids: Sequence[int]) -> dict[int, int]:
        """Model number of every servo in ``ids`` (pings each)."""
        return {int(i): self.ping(int(i)) for i in ids}

    @abc.abstractmethod
    def scan(self) -> dict[int, int]:
        """Every servo that answers: ``{id: model number}``."""

    @abc.abstractmethod
    def read_present_positions(self, ids: Sequence[int], *, allow_alert: bool = False) -> np.ndarray:
        """Present Position (132) of ``ids`` in one sync read: int64 [len(ids)] ticks.

        A servo reporting a hardware error raises :class:`ServoAlertError` unless ``allow_alert``.
        """

    def read_present_positions_each(self, ids: Sequence[int]) -> np.ndarray:
        """Present Position of ``ids`` read servo by servo (slower; works with any Return Delay Time)."""
        return np.concatenate([self.read_present_positions([int(i)]) for i in ids]) if len(ids) else np.zeros(0, np.int64)

    @abc.abstractmethod
    def write_goal_positions(self, ids: Sequence[int], ticks: np.ndarray) -> None:
        """Goal Position (116) of ``ids`` in one sync write; ``ticks`` int [len(ids)]."""

    @abc.abstractmethod
    def set_torque(self, ids: Sequence[int], enabled: bool) -> None:
        """Torque Enable (64)."""

    @abc.abstractmethod
    def set_profile_velocity(self, ids: Sequence[int], units: Sequence[int] | int) -> None:
        """Profile Velocity (112), 0.229 rpm per unit (0 = unlimited)."""

    @abc.abstractmethod
    def read_hardware_errors(self, ids: Sequence[int]) -> dict[int, int]:
        """Hardware Error Status (70) bits of every servo in ``ids``."""

    @abc.abstractmethod
    def set_bus_watchdog(self, ids: Sequence[int], units: int) -> None:
        """Bus Watchdog (98), 20 ms per unit, 0 = off (writing it also clears a fired watchdog)."""

    @abc.abstractmethod
    def read_bus_watchdog(self, ids: Sequence[int]) -> dict[int, int]:
        """Bus Watchdog (98) of every servo in ``ids``: 255 means it fired (goals are refused)."""

    @abc.abstractmethod
    def set_return_delay_time(self, ids: Sequence[int], units: int) -> None:
        """Return Delay Time (9), 2 us per unit (EEPROM: torque must be off)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the port."""

    def reset(self) -> None:
        """Recover the bus after an interrupted transfer (no-op where nothing can be stuck)."""

    # ------------------------------------------------------------------ the torso IMU
    #: bus ID of the IMU (the OpenCR at 200 on an OP3), None when this bus has none
    imu_id: int | None = None
    #: pre-flight may expect the IMU to read about 1 g (the robot at rest before torque is on)
    imu_at_rest_in_preflight: bool = True

    def ping_imu(self) -> int:
        """Model number of the IMU device; :class:`ServoCommError` if it does not answer."""
        if self.imu_id is None:
            raise ServoCommError(None, "this bus has no IMU", self.port_name)
        return self.ping(self.imu_id)

    def read_imu(self) -> tuple[np.ndarray, np.ndarray]:
        """(gyro [3] rad/s, accelerometer [3] m/s^2, specific force) in the robot's IMU frame."""
        raise ServoCommError(None, "this bus has no IMU", self.port_name)

    def read_present_positions_and_imu(self, ids: Sequence[int], *, allow_alert: bool = False
                                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Present positions of ``ids`` and the IMU in one bus transaction where the bus can
        (:class:`DynamixelBus`: one Bulk Read); returns ``(ticks [n], gyro [3], accel [3])``."""
        present = self.read_present_positions(ids, allow_alert=allow_alert)
        gyro, accel = self.read_imu()
        return present, gyro, accel

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def usb_latency_timer_ms(port: str) -> int | None:
    """The USB-serial adapter's latency timer (ms) from Linux sysfs, or None if unknown."""
    name = Path(os.path.realpath(port)).name
    path = Path("/sys/bus/usb-serial/devices") / name / "latency_timer"
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def _make_serial_port_handler(port: str, latency_timer_ms: float):
    """A ``dynamixel_sdk.PortHandler`` that locks the port and sizes timeouts from the latency."""
    import serial

    class SerialPortHandler(PortHandler):
        def setupPort(self, cflag_baud):  # noqa: N802 (SDK naming)
            if self.is_open:
                self.closePort()
            # exclusive=True: a port already opened by another program is reported as busy
            self.ser = serial.Serial(
                port=self.port_name,
                baudrate=self.baudrate,
                bytesize=serial.EIGHTBITS,
                timeout=0,
                exclusive=sys.platform != "win32",
            )
            self.is_open = True
            self.ser.reset_input_buffer()
            self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
            return True

        def setPacketTimeout(self, packet_length):  # noqa: N802
            self.packet_start_time = self.getCurrentTime()
            self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * latency_timer_ms + 2.0

        def getCurrentTime(self):  # noqa: N802 (ms; monotonic, unlike the SDK's time.time())
            return time.perf_counter() * 1000.0

        def isPacketTimeout(self):  # noqa: N802
            # The SDK checks the time after an empty read; a host descheduled past the deadline
            # would drop a reply that is already in the buffer.  Bytes waiting = not timed out
            # (bounded, so a stream of garbage still ends in a timeout).
            elapsed = self.getTimeSinceStart()
            if elapsed <= self.packet_timeout:
                return False
            if elapsed <= 4.0 * self.packet_timeout and self.ser.in_waiting:
                return False
            self.packet_timeout = 0
            return True

    return SerialPortHandler(port)


class DynamixelBus(ServoBus):
    """A Protocol 2.0 Dynamixel bus through ``dynamixel_sdk``.

    Args:
        port: serial device (``/dev/ttyUSB0``, ``COM3``); only a label when ``port_handler``
            is given.
        baud: bits per second; must match the servos' Baud Rate register (OP3 class: 2 Mbit/s).
        port_handler: a ``dynamixel_sdk.PortHandler`` (or subclass, e.g. the emulator) to use
            instead of opening ``port`` with pyserial.  It is opened here.
        fast_sync_read: use Fast Sync Read (instruction 0x8A: one status packet for all
            servos) when the servos answer it; falls back to Sync Read otherwise.
        latency_timer_ms: USB adapter latency used to size packet timeouts; by default read
            from sysfs, else the SDK's 16 ms.
        imu: the torso IMU on this bus (:class:`~motok_robot.servo.imu.ImuMount`: the OpenCR
            at ID 200 and its axis mapping), None when there is none.  Its registers are read
            with the servos' present positions in one Bulk Read
            (:meth:`read_present_positions_and_imu`).
    """

    def __init__(
        self,
        port: str,
        baud: int = DEFAULT_BAUD,
        *,
        port_handler=None,
        fast_sync_read: bool = True,
        latency_timer_ms: float | None = None,
        imu=None,
    ):
        self.port_name = port
        self.imu = imu
        self.imu_id = int(imu.id) if imu is not None else None
        self.baud = int(baud)
        self._success = COMM_SUCCESS
        self.packet_handler = PacketHandler(2.0)
        if port_handler is None:
            if latency_timer_ms is None:
                measured = usb_latency_timer_ms(port)
                latency_timer_ms = float(measured) if measured is not None else 16.0
                if measured is not None and measured > 2:
                    warnings.warn(
                        f"{port}: USB latency timer is {measured} ms; set it to 1 ms for a 125 Hz loop "
                        f"(echo 1 | sudo tee /sys/bus/usb-serial/devices/{Path(os.path.realpath(port)).name}"
                        "/latency_timer)",
                        stacklevel=2,
                    )
            if not os.path.exists(port) and not port.upper().startswith("COM"):
                raise HardwareError(f"serial port {port} does not exist (is the USB adapter plugged in?)")
            port_handler = _make_serial_port_handler(port, latency_timer_ms)
        self.port_handler = port_handler
        self._open()
        self._fast_sync_read = fast_sync_read
        self._fast_checked = not fast_sync_read
        self._readers: dict[tuple[int, ...], object] = {}
        self._goal_writer = None
        self._goal_ids: tuple[int, ...] = ()
        self._bulk_readers: dict[tuple[int, ...], object] = {}

    # ----------------------------------------------------------------------------- port
    def _open(self) -> None:
        handler = self.port_handler
        try:
            handler.baudrate = self.baud
            opened = handler.openPort()
        except Exception as exc:  # pyserial raises SerialException / OSError with errno text
            reason = str(exc).split("\n")[0]
            if "lock" in reason.lower() or "busy" in reason.lower() or "Resource temporarily" in reason:
                raise HardwareError(f"serial port {self.port_name} is busy (in use by another program): {reason}") from None
            raise HardwareError(f"cannot open serial port {self.port_name}: {reason}") from None
        if not opened:
            raise HardwareError(f"cannot open serial port {self.port_name} at {self.baud} baud (unsupported baud rate?)")

    def close(self) -> None:
        handler = self.port_handler
        if getattr(handler, "is_open", False):
            try:
                handler.closePort()
            except Exception:  # closing must never mask the error that led here
                pass

    def _comm_error(self, servo_id: int | None, result: int, what: str) -> ServoCommError:
        text = self.packet_handler.getTxRxResult(result).replace("[TxRxResult] ", "").rstrip("!")
        return ServoCommError(servo_id, f"{what}: {text} (code {result})", self.port_name)

    def _check_status(self, servo_id: int, result: int, error: int, what: str) -> None:
        if result != self._success:
            raise self._comm_error(servo_id, result, what)
        if error & ct.STATUS_ALERT_BIT:
            raise ServoAlertError(servo_id, self._try_read_hardware_error(servo_id), self.port_name)
        if error:
            name = ct.STATUS_ERRORS.get(error & 0x7F, f"error {error & 0x7F}")
            raise ServoRejectedError(servo_id, f"{what}: servo answered '{name}'", self.port_name)

    def _try_read_hardware_error(self, servo_id: int) -> int | None:
        value, result, _ = self.packet_handler.read1ByteTxRx(self.port_handler, servo_id, ct.ADDR_HARDWARE_ERROR_STATUS)
        return int(value) if result == self._success else None

    # ------------------------------------------------------------------------ single ops
    def ping(self, servo_id: int) -> int:
        model, result, error = self.packet_handler.ping(self.port_handler, int(servo_id))
        self._check_status(int(servo_id), result, error, "ping")
        return int(model)

    def scan(self) -> dict[int, int]:
        found, result = self.packet_handler.broadcastPing(self.port_handler)
        if result != self._success and not found:
            return {}
        return {int(i): int(v[0]) for i, v in sorted(found.items())}

    def _write_each(self, ids: Sequence[int], address: int, size: int, values, what: str) -> None:
        values = np.broadcast_to(np.asarray(values, dtype=np.int64), (len(ids),))
        write = {1: self.packet_handler.write1ByteTxRx, 2: self.packet_handler.write2ByteTxRx,
                 4: self.packet_handler.write4ByteTxRx}[size]
        for servo_id, value in zip(ids, values):
            result, error = write(self.port_handler, int(servo_id), address, int(value) & ((1 << (8 * size)) - 1))
            self._check_status(int(servo_id), result, error, what)

    def set_torque(self, ids, enabled):
        self._write_each(ids, ct.ADDR_TORQUE_ENABLE, 1, ct.TORQUE_ON if enabled else ct.TORQUE_OFF,
                         "torque enable" if enabled else "torque disable")

    def set_profile_velocity(self, ids, units):
        self._write_each(ids, ct.ADDR_PROFILE_VELOCITY, 4, units, "set profile velocity")

    def set_bus_watchdog(self, ids, units):
        self._write_each(ids, ct.ADDR_BUS_WATCHDOG, 1, units, "set bus watchdog")

    def set_return_delay_time(self, ids, units):
        self._write_each(ids, ct.ADDR_RETURN_DELAY_TIME, 1, units, "set return delay time")

    def read_hardware_errors(self, ids):
        out = {}
        for servo_id in ids:
            value, result, _error = self.packet_handler.read1ByteTxRx(
                self.port_handler, int(servo_id), ct.ADDR_HARDWARE_ERROR_STATUS)
            if result != self._success:
                raise self._comm_error(int(servo_id), result, "read hardware error status")
            out[int(servo_id)] = int(value)
        return out

    def read_bus_watchdog(self, ids):
        return {int(i): self.read_register(int(i), ct.ADDR_BUS_WATCHDOG, 1) for i in ids}

    def read_register(self, servo_id: int, address: int, size: int) -> int:
        """One register (1, 2 or 4 bytes, unsigned) of one servo."""
        read = {1: self.packet_handler.read1ByteTxRx, 2: self.packet_handler.read2ByteTxRx,
                4: self.packet_handler.read4ByteTxRx}[size]
        value, result, error = read(self.port_handler, int(servo_id), address)
        self._check_status(int(servo_id), result, error, f"read address {address}")
        return int(value)

    # -------------------------------------------------------------------------- sync ops
    def write_goal_positions(self, ids, ticks):
        ids = tuple(int(i) for i in ids)
        ticks = np.asarray(ticks)
        if ticks.shape != (len(ids),) or not np.issubdtype(ticks.dtype, np.integer):
            raise ValueError(f"goal ticks must be an integer array of shape ({len(ids)},), got {ticks.dtype} {ticks.shape}")
        if self._goal_writer is None or self._goal_ids != ids:
            self._goal_writer = GroupSyncWrite(self.port_handler, self.packet_handler, ct.ADDR_GOAL_POSITION,
                                               ct.SIZE_GOAL_POSITION)
            self._goal_ids = ids
            for servo_id in ids:
                self._goal_writer.addParam(servo_id, [0, 0, 0, 0])
        for servo_id, value in zip(ids, ticks.tolist()):
            self._goal_writer.changeParam(servo_id, list(int(value).to_bytes(4, "little", signed=True)))
        result = self._goal_writer.txPacket()
        if result != self._success:
            raise self._comm_error(None, result, "sync write of goal positions")

    def read_present_positions(self, ids, *, allow_alert=False):
        ids = tuple(int(i) for i in ids)
        reader = self._readers.get(ids)
        if reader is None:
            reader = _StatusKeepingSyncRead(self.port_handler, self.packet_handler, ct.ADDR_PRESENT_POSITION,
                                            ct.SIZE_PRESENT_POSITION)
            for servo_id in ids:
                reader.addParam(servo_id)
            self._readers[ids] = reader
        if not self._fast_checked:
            # probe once: firmware before v45 does not know Fast Sync Read.  Fall back only when
            # fast fails twice while plain Sync Read works in between (not on a one-off glitch).
            if reader.fastSyncRead() != self._success:
                self.reset()
                if reader.txRxPacket() == self._success and reader.fastSyncRead() != self._success:
                    self._fast_sync_read = False
                self.reset()
            self._fast_checked = True
        result = reader.fastSyncRead() if self._fast_sync_read else reader.txRxPacket()
        if result != self._success:
            if reader.failed_id is not None:
                raise self._comm_error(reader.failed_id, result, "sync read of present positions")
            # one combined status packet failed: ping servo by servo to name the culprit
            what = "fast sync read of present positions"
            for servo_id in ids:
                _model, ping_result, _error = self.packet_handler.ping(self.port_handler, servo_id)
                if ping_result != self._success:
                    ping_text = self.packet_handler.getTxRxResult(ping_result).replace("[TxRxResult] ", "").rstrip("!")
                    raise self._comm_error(servo_id, result, what + f" failed and ping fails too ({ping_text})")
            raise self._comm_error(None, result, what + " (every servo answers ping)")
        for servo_id in ids:
            error = reader.errors.get(servo_id, 0)
            if error & ct.STATUS_ALERT_BIT and not allow_alert:
                raise ServoAlertError(servo_id, self._try_read_hardware_error(servo_id), self.port_name)
        return np.array([int.from_bytes(bytes(reader.data_dict[i][:4]), "little", signed=True) for i in ids],
                        dtype=np.int64)

    # ------------------------------------------------------------------------------ IMU
    def _imu_mount(self):
        if self.imu is None:
            raise ServoCommError(None, "this bus has no IMU (the robot description's [bus] has no imu)",
                                 self.port_name)
        return self.imu

    def _check_imu_status(self, error: int, what: str) -> None:
        if error & ct.STATUS_ALERT_BIT:
            # the OpenCR has no X-series Hardware Error Status register to ask for the bits
            raise ServoAlertError(self.imu_id, None, self.port_name)
        if error:
            name = ct.STATUS_ERRORS.get(error & 0x7F, f"error {error & 0x7F}")
            raise ServoRejectedError(self.imu_id, f"{what}: device answered '{name}'", self.port_name)

    def read_imu(self):
        mount = self._imu_mount()
        from motok_robot.servo import imu as imu_regs

        data, result, error = self.packet_handler.readTxRx(self.port_handler, self.imu_id, imu_regs.IMU_BLOCK_ADDRESS,
                                                           imu_regs.IMU_BLOCK_SIZE)
        if result != self._success:
            raise self._comm_error(self.imu_id, result, "read of the IMU registers")
        self._check_imu_status(error, "read of the IMU registers")
        return mount.decode(bytes(data))

    def read_present_positions_and_imu(self, ids, *, allow_alert=False):
        """One Bulk Read (instruction 0x92): Present Position (132, 4 bytes) of every servo in
        ``ids`` and the IMU block (32, 12 bytes) of the IMU; each device answers in turn."""
        mount = self._imu_mount()
        from motok_robot.servo import imu as imu_regs

        ids = tuple(int(i) for i in ids)
        reader = self._bulk_readers.get(ids)
        if reader is None:
            reader = _StatusKeepingBulkRead(self.port_handler, self.packet_handler)
            for servo_id in ids:
                reader.addParam(servo_id, ct.ADDR_PRESENT_POSITION, ct.SIZE_PRESENT_POSITION)
            reader.addParam(self.imu_id, imu_regs.IMU_BLOCK_ADDRESS, imu_regs.IMU_BLOCK_SIZE)
            self._bulk_readers[ids] = reader
        result = reader.txRxPacket()
        what = "bulk read of present positions and the IMU"
        if result != self._success:
            raise self._comm_error(reader.failed_id, result, what)
        for servo_id in ids:
            error = reader.errors.get(servo_id, 0)
            if error & ct.STATUS_ALERT_BIT and not allow_alert:
                raise ServoAlertError(servo_id, self._try_read_hardware_error(servo_id), self.port_name)
        self._check_imu_status(reader.errors.get(self.imu_id, 0), what)
        present = np.array([int.from_bytes(bytes(reader.data_dict[i][0][:4]), "little", signed=True) for i in ids],
                           dtype=np.int64)
        gyro, accel = mount.decode(bytes(reader.data_dict[self.imu_id][0]))
        return present, gyro, accel

    def reset(self) -> None:
        """Forget a transfer that an interrupt cut short (the SDK would report the port busy)."""
        self.port_handler.is_using = False
        try:
            self.port_handler.clearPort()
        except Exception:
            pass


class _StatusKeeping:
    """Mixin for the SDK's group reads: keeps each device's status error byte and the failing ID.
    The class it is mixed into defines ``_reply_length(device_id)`` (bytes of that device's
    reply) and ``_store(device_id, data)`` (where the data goes)."""

    def __init__(self, *args):
        super().__init__(*args)
        self.errors: dict[int, int] = {}
        self.failed_id: int | None = None

    def rxPacket(self):  # noqa: N802 (SDK naming)
        self.last_result = False
        self.errors = {}
        self.failed_id = None
        if not self.data_dict:
            return COMM_NOT_AVAILABLE
        for device_id in list(self.data_dict):
            data, result, error = self.ph.readRx(self.port, device_id, self._reply_length(device_id))
            if result != COMM_SUCCESS:
                self.failed_id = device_id
                return result
            self._store(device_id, data)
            self.errors[device_id] = error
        self.last_result = True
        return COMM_SUCCESS


class _StatusKeepingBulkRead(_StatusKeeping, GroupBulkRead):
    """The SDK's GroupBulkRead, keeping each device's status error byte and the failing ID."""

    def _reply_length(self, device_id: int) -> int:
        return self.data_dict[device_id][2]

    def _store(self, device_id: int, data) -> None:
        self.data_dict[device_id][0] = data


class _StatusKeepingSyncRead(_StatusKeeping, GroupSyncRead):
    """The SDK's GroupSyncRead, keeping each servo's status error byte and the failing ID."""

    def _reply_length(self, device_id: int) -> int:
        return self.data_length

    def _store(self, device_id: int, data) -> None:
        self.data_dict[device_id] = data

    def fastSyncReadRxPacket(self):  # noqa: N802
        self.last_result = False
        self.errors = {}
        self.failed_id = None
        if not self.data_dict:
            return COMM_NOT_AVAILABLE
        count = len(self.data_dict)
        stride = self.data_length + 4  # error, id, data, crc
        raw, result, _ = self.ph.fastSyncReadRx(self.port, BROADCAST_ID, stride * count)
        if result != COMM_SUCCESS:
            return result
        raw = bytes(raw)
        if len(raw) < stride * count:
            return COMM_RX_CORRUPT
        seen = set()
        for k in range(count):
            chunk = raw[k * stride:(k + 1) * stride]
            servo_id = chunk[1]
            if servo_id not in self.data_dict or servo_id in seen:
                return COMM_RX_CORRUPT
            seen.add(servo_id)
            self.errors[servo_id] = chunk[0]
            self.data_dict[servo_id] = bytearray(chunk[2:2 + self.data_length])
        self.last_result = True
        return COMM_SUCCESS
