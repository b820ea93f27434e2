"""The emulated servo chain, driven by the real dynamixel_sdk through DynamixelBus."""

import os

import numpy as np
import pytest
from dynamixel_sdk import Protocol2PacketHandler

from motok_robot.servo import control_table as ct
from motok_robot.servo import protocol as pr
from motok_robot.servo.bus import DynamixelBus, ServoAlertError, ServoCommError, ServoRejectedError
from motok_robot.servo.emulator import EmulatedServo, EmulatedServoChain
from motok_robot.servo.timing import FakeClock

IDS = list(range(1, 21))


def make_bus(ids=IDS, fast=True, **kwargs):
    chain = EmulatedServoChain.from_ids(ids, positions=[2000 + 3 * i for i in ids], **kwargs)
    bus = DynamixelBus("emulated", 2_000_000, port_handler=chain, fast_sync_read=fast)
    bus.set_return_delay_time(ids, 0)
    return bus, chain


def test_crc_and_stuffing_agree_with_the_sdk():
    sdk = Protocol2PacketHandler()
    rng = np.random.default_rng(0)
    for _ in range(50):
        data = bytes(rng.integers(0, 256, 40, dtype=np.uint8))
        assert pr.crc16(data) == sdk.updateCRC(0, list(data), len(data))
    body = bytes([0x03, 0xFF, 0xFF, 0xFD, 0x01, 0xFF, 0xFF, 0xFD])
    assert pr.stuff(body) == bytes([0x03, 0xFF, 0xFF, 0xFD, 0xFD, 0x01, 0xFF, 0xFF, 0xFD, 0xFD])
    assert pr.unstuff(pr.stuff(body)) == body
    # a packet we build is what the SDK builds (header, length, stuffing, CRC)
    params = [0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x00]
    packet = [0] * (10 + len(params) + 2)
    packet[4], packet[5], packet[6], packet[7] = 1, len(params) + 3, 0, pr.INST_WRITE
    packet[8:8 + len(params)] = params
    sdk_packet = sdk.addStuffing(packet)
    total = sdk_packet[5] + 7
    sdk_packet[0:4] = [0xFF, 0xFF, 0xFD, 0x00]
    crc = sdk.updateCRC(0, sdk_packet, total - 2)
    sdk_packet[total - 2:total] = [crc & 0xFF, crc >> 8]
    assert pr.build_packet(1, pr.INST_WRITE, bytes(params)) == bytes(sdk_packet[:total])
    parsed = pr.PacketParser().feed(b"\x00\x17" + bytes(sdk_packet[:total]))
    assert parsed == [pr.Instruction(1, pr.INST_WRITE, bytes(params), True)]


def test_ping_scan_model_numbers_and_register_reads():
    bus, chain = make_bus([1, 2, 7])
    chain.servos[7].table[ct.ADDR_MODEL_NUMBER:ct.ADDR_MODEL_NUMBER + 2] = (1060).to_bytes(2, "little")
    assert bus.ping(1) == 1020
    assert bus.read_model_numbers([1, 7]) == {1: 1020, 7: 1060}
    assert bus.scan() == {1: 1020, 2: 1020, 7: 1060}
    assert bus.read_register(2, ct.ADDR_VELOCITY_LIMIT, 4) == 200
    with pytest.raises(ServoCommError, match="servo 9 .*no status packet"):
        bus.ping(9)


@pytest.mark.parametrize("fast", [True, False])
def test_sync_read_and_sync_write_through_the_sdk(fast):
    bus, chain = make_bus(fast=fast)
    assert bus.read_present_positions(IDS).tolist() == [2000 + 3 * i for i in IDS]
    goals = np.array([1500 + 10 * i for i in IDS], dtype=np.int64)
    bus.write_goal_positions(IDS, goals)
    assert [chain.servos[i].goal_history[-1] for i in IDS] == goals.tolist()
    assert bus._fast_sync_read is fast


def test_fast_sync_read_falls_back_for_old_firmware():
    bus, chain = make_bus()
    original = chain._sync_read

    def no_fast(params, now, clock_now, fast):
        if not fast:
            original(params, now, clock_now, fast)  # an old servo ignores instruction 0x8A

    chain._sync_read = no_fast
    assert bus.read_present_positions(IDS).tolist() == [2000 + 3 * i for i in IDS]
    assert bus._fast_sync_read is False


def test_status_packet_with_stuffing_is_decoded_by_the_sdk():
    bus, chain = make_bus([3])
    servo = chain.servos[3]
    servo.table[200:204] = bytes([0xFF, 0xFF, 0xFD, 0x12])  # indirect-data area: needs byte stuffing
    assert bus.read_register(3, 200, 4) == int.from_bytes(bytes([0xFF, 0xFF, 0xFD, 0x12]), "little")


def test_access_rules_and_goal_limits():
    bus, chain = make_bus([1], limits=[(1000, 3000)])
    bus.set_torque([1], True)
    with pytest.raises(ServoRejectedError, match="access error"):
        bus.set_return_delay_time([1], 0)  # EEPROM while torque is on
    with pytest.raises(ServoRejectedError, match="data limit error"):
        bus.packet_handler and bus._write_each([1], ct.ADDR_GOAL_POSITION, 4, 3500, "write goal")
    bus.write_goal_positions([1], np.array([3500]))  # sync write: no status, servo drops it
    assert chain.servos[1].rejected_goals == 2
    assert chain.servos[1].goal_history == []


def test_position_follows_goal_at_profile_velocity():
    clock = FakeClock()
    chain = EmulatedServoChain.from_ids([1], positions=[2048], clock=clock)
    bus = DynamixelBus("emulated", port_handler=chain)
    bus.set_return_delay_time([1], 0)
    bus.set_profile_velocity([1], 100)  # 22.9 rpm = 1563 ticks/s
    bus.set_torque([1], True)
    bus.write_goal_positions([1], np.array([3048]))
    clock.advance(0.2)
    moved = bus.read_present_positions([1])[0] - 2048
    assert 0.9 * 0.2 * 1563 <= moved <= 1.01 * 0.2 * 1563  # speed capped by the profile velocity
    clock.advance(2.0)
    assert abs(bus.read_present_positions([1])[0] - 3048) <= 1


def test_bus_watchdog_stops_a_servo_the_host_forgot():
    clock = FakeClock()
    chain = EmulatedServoChain.from_ids([1], positions=[2048], clock=clock)
    bus = DynamixelBus("emulated", port_handler=chain)
    bus.set_torque([1], True)
    bus.set_bus_watchdog([1], 5)  # 100 ms
    clock.advance(0.15)
    bus.write_goal_positions([1], np.array([2500]))
    assert chain.servos[1].table[ct.ADDR_BUS_WATCHDOG] == 0xFF
    assert chain.servos[1].goal_position == 2048  # the late goal was refused
    bus.set_bus_watchdog([1], 0)
    bus.write_goal_positions([1], np.array([2500]))
    assert chain.servos[1].goal_position == 2500


def test_fault_missing_servo_is_named():
    bus, chain = make_bus()
    chain.disconnect(12)
    with pytest.raises(ServoCommError) as info:
        bus.read_present_positions(IDS)
    assert info.value.servo_id == 12
    bus2, chain2 = make_bus(fast=False)
    chain2.disconnect(12)
    with pytest.raises(ServoCommError, match="no status packet") as info:
        bus2.read_present_positions(IDS)
    assert info.value.servo_id == 12


def test_fault_corrupt_crc_is_a_comm_error_naming_the_servo():
    bus, chain = make_bus()
    chain.corrupt_replies(5)
    with pytest.raises(ServoCommError, match="Incorrect status packet") as info:
        bus.read_present_positions(IDS)
    assert info.value.servo_id == 5
    chain.corrupt_replies(5, count=0)
    assert len(bus.read_present_positions(IDS)) == 20


def test_fault_hardware_error_raises_alert_with_the_bits():
    bus, chain = make_bus()
    chain.set_hardware_error(9, 0x20 | 0x04)
    with pytest.raises(ServoAlertError, match="overheating, overload") as info:
        bus.read_present_positions(IDS)
    assert info.value.servo_id == 9 and info.value.bits == 0x24
    assert not chain.servos[9].torque_enabled


def test_fault_slow_replies():
    bus, chain = make_bus()
    chain.slow_replies(4, 0.001)  # late but inside the packet timeout: fine
    assert len(bus.read_present_positions(IDS)) == 20
    chain.slow_replies(4, 0.05)  # beyond the timeout
    with pytest.raises(ServoCommError) as info:
        bus.read_present_positions(IDS)
    assert info.value.servo_id == 4


def test_fault_dropped_replies_then_recovery():
    bus, chain = make_bus()
    bus.read_present_positions(IDS)
    chain.drop_replies(3, count=1)
    with pytest.raises(ServoCommError):
        bus.read_present_positions(IDS)
    bus.reset()
    assert len(bus.read_present_positions(IDS)) == 20


def test_wrong_baud_gets_no_reply():
    chain = EmulatedServoChain([EmulatedServo(1, baud=1_000_000)])
    bus = DynamixelBus("emulated", 2_000_000, port_handler=chain)
    with pytest.raises(ServoCommError):
        bus.ping(1)


def test_missing_and_busy_serial_port_are_one_line_hardware_errors(tmp_path):
    serial = pytest.importorskip("serial")
    from motok_robot.errors import HardwareError

    with pytest.raises(HardwareError, match="does not exist") as info:
        DynamixelBus(str(tmp_path / "ttyUSB9"))
    assert "\n" not in str(info.value)
    if not hasattr(os, "openpty"):
        pytest.skip("no pseudo-terminals here")
    master, slave = os.openpty()
    name = os.ttyname(slave)
    holder = serial.Serial(name, 2_000_000, timeout=0, exclusive=True)
    try:
        with pytest.raises(HardwareError, match="busy") as info:
            DynamixelBus(name)
        assert "\n" not in str(info.value)
    finally:
        holder.close()
        os.close(master)
        os.close(slave)


def test_dynamixel_bus_over_a_real_serial_device_with_emulated_servos_behind_it():
    """pyserial + DynamixelBus's serial port handler on a pseudo-terminal; the other end of the
    pty is served by an emulated chain (so the serial code path itself is exercised)."""
    import threading
    import time

    if not hasattr(os, "openpty"):
        pytest.skip("no pseudo-terminals")
    master, slave = os.openpty()
    chain = EmulatedServoChain.from_ids([1, 2, 3], positions=[1000, 2000, 3000])
    chain.setBaudRate(2_000_000)  # the emulated wire runs at the servos' baud
    stop = threading.Event()

    def wire():
        os.set_blocking(master, False)
        while not stop.is_set():
            try:
                data = os.read(master, 4096)
            except BlockingIOError:
                data = b""
            except OSError:
                return
            if data:
                chain.writePort(data)
            out = chain.readPort(4096)
            if out:
                os.write(master, out)
            if not data and not out:
                time.sleep(0.0002)

    thread = threading.Thread(target=wire, daemon=True)
    thread.start()
    bus = DynamixelBus(os.ttyname(slave), 2_000_000, latency_timer_ms=16)
    try:
        assert bus.ping(2) == 1020
        bus.set_return_delay_time([1, 2, 3], 0)
        assert bus.read_present_positions([1, 2, 3]).tolist() == [1000, 2000, 3000]
        bus.write_goal_positions([1, 2, 3], np.array([1100, 2100, 3100]))
        deadline = time.time() + 2
        while chain.servos[3].goal_history != [3100] and time.time() < deadline:
            time.sleep(0.001)
        assert [chain.servos[i].goal_history for i in (1, 2, 3)] == [[1100], [2100], [3100]]
        with pytest.raises(ServoCommError, match="servo 9"):
            bus.ping(9)
    finally:
        stop.set()
        thread.join(1)
        bus.close()
        os.close(master)
        os.close(slave)
