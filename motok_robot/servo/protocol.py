"""Dynamixel Protocol 2.0 framing, written from the protocol description (servo side).

A packet is ``FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS... | CRC_L CRC_H`` where ``LEN``
counts the bytes after itself (instruction, parameters and the CRC).  Inside the
instruction/parameter field every ``FF FF FD`` is followed by an extra ``FD`` ("byte
stuffing") so a header can never appear inside a packet; ``LEN`` and the CRC refer to the
stuffed bytes.  The CRC is CRC-16 with polynomial 0x8005, initial value 0, no bit reflection,
over every byte before it (header included).

The host side of the protocol is ``dynamixel_sdk``; this module is what the emulated servos
(:mod:`motok_robot.servo.emulator`) use to parse instructions and build status packets.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
INST_PING = 0x01
INST_READ = 0x02
INST_WRITE = 0x03
INST_REBOOT = 0x08
INST_STATUS = 0x55
INST_SYNC_READ = 0x82
INST_SYNC_WRITE = 0x83
INST_FAST_SYNC_READ = 0x8A
INST_BULK_READ = 0x92

ERROR_INSTRUCTION = 2
ERROR_CRC = 3
ERROR_DATA_RANGE = 4
ERROR_DATA_LENGTH = 5
ERROR_DATA_LIMIT = 6
ERROR_ACCESS = 7


def _crc_table(poly: int = 0x8005) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ poly) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """CRC-16 (poly 0x8005, MSB first) of ``data``, continuing from ``crc``."""
    table = _CRC_TABLE
    for byte in data:
        crc = ((crc << 8) ^ table[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` in an instruction/parameter field."""
    if b"\xff\xff\xfd" not in body:
        return bytes(body)
    out = bytearray()
    for i, byte in enumerate(body):
        out.append(byte)
        if byte == 0xFD and i >= 2 and body[i - 1] == 0xFF and body[i - 2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the ``FD`` that :func:`stuff` inserted (the inverse of :func:`stuff`)."""
    if b"\xff\xff\xfd\xfd" not in body:
        return bytes(body)
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if body[i] == 0xFD and i >= 2 and body[i - 1] == 0xFF and body[i - 2] == 0xFF:
            i += 1  # skip the stuffing byte that follows
        i += 1
    return bytes(out)


def build_packet(servo_id: int, instruction: int, params: bytes) -> bytes:
    """A complete, stuffed, CRC-terminated packet."""
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    packet = HEADER + bytes([servo_id, length & 0xFF, length >> 8]) + body
    crc = crc16(packet)
    return packet + bytes([crc & 0xFF, crc >> 8])


def build_status(servo_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet (instruction 0x55) with error byte ``error`` and ``params``."""
    return build_packet(servo_id, INST_STATUS, bytes([error]) + bytes(params))


@dataclass(frozen=True)
class Instruction:
    """A parsed instruction packet. ``params`` are unstuffed; ``crc_ok`` tells whether it checked."""

    servo_id: int
    instruction: int
    params: bytes
    crc_ok: bool


class PacketParser:
    """Incremental parser of a byte stream into :class:`Instruction` packets.

    Bytes before a header are discarded (as a servo does with line noise).
    """

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[Instruction]:
        self._buffer.extend(data)
        packets = []
        while True:
            start = self._buffer.find(HEADER)
            if start < 0:
                # keep a possible partial header at the end
                del self._buffer[: max(0, len(self._buffer) - 3)]
                return packets
            if start:
                del self._buffer[:start]
            if len(self._buffer) < 7:
                return packets
            length = self._buffer[5] | (self._buffer[6] << 8)
            total = 7 + length
            if length < 3:
                del self._buffer[:4]
                continue
            if len(self._buffer) < total:
                return packets
            raw = bytes(self._buffer[:total])
            del self._buffer[:total]
            crc = raw[-2] | (raw[-1] << 8)
            body = unstuff(raw[7:-2])
            packets.append(Instruction(raw[4], body[0], body[1:], crc16(raw[:-2]) == crc))

    def clear(self) -> None:
        self._buffer.clear()
