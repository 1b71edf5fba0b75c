"""DDCMP framing (assumed ALTER wire format, see PROTOCOL.md): frames, encoders, decoder.

Pure: no clock, no I/O. ``DdcmpDecoder.feed(bytes)`` returns the frames and framing
errors found so far and keeps any incomplete tail for the next call. It never raises on
input bytes: garbage is skipped, a failed CRC costs one byte of resynchronisation.

Header layout (8 bytes, all frames)::

    0     1      2        3     4     5     6..7
    SOH   COUNT (14 bit, LE) RESP  NUM   ADDR  CRC-16 of bytes 0..5 (LE)
          + QSYNC 0x4000, SELECT 0x8000
    ENQ   TYPE  SUBTYPE  RCVR  SNDR  ADDR  CRC-16 of bytes 0..5 (LE)
                (6 bit) + QSYNC 0x40, SELECT 0x80

A data (SOH) header is followed by COUNT data bytes and their CRC-16 (LE).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from humanpt.robot_gateway.links.alter.crc import crc16

SOH = 0x81  # data message
ENQ = 0x05  # control message

HEADER_BYTES = 8
CRC_BYTES = 2
MAX_COUNT = 0x3FFF  # 14-bit count field
QSYNC_COUNT_BIT = 0x4000
SELECT_COUNT_BIT = 0x8000
QSYNC_SUBTYPE_BIT = 0x40
SELECT_SUBTYPE_BIT = 0x80
SUBTYPE_MASK = 0x3F
DEFAULT_ADDRESS = 1  # point-to-point station address

# Why overhead constants: the cycle budget (budget.py) needs them.
DATA_FRAME_OVERHEAD_BYTES = HEADER_BYTES + CRC_BYTES  # 10
CONTROL_FRAME_BYTES = HEADER_BYTES  # 8

_HEADER = struct.Struct("<BHBBB")  # class, count|flags, RESP, NUM, ADDR (6 bytes)
_CONTROL = struct.Struct("<BBBBBB")  # ENQ, TYPE, SUBTYPE|flags, RCVR, SNDR, ADDR


class ControlType(IntEnum):
    """TYPE byte of an ENQ control message (DDCMP numbering)."""

    ACK = 1
    NAK = 2
    REP = 3
    STRT = 6
    STACK = 7


class NakReason(IntEnum):
    """SUBTYPE of a NAK (DDCMP reason codes)."""

    HEADER_CRC = 1
    DATA_CRC = 2
    REP_RESPONSE = 3
    BUFFER_UNAVAILABLE = 8
    RECEIVE_OVERRUN = 9
    MESSAGE_TOO_LONG = 16
    HEADER_FORMAT = 17


class FrameErrorReason(IntEnum):
    """Why the decoder rejected bytes. Values of the NAK-worthy ones equal the NAK code."""

    HEADER_CRC = NakReason.HEADER_CRC
    DATA_CRC = NakReason.DATA_CRC
    MESSAGE_TOO_LONG = NakReason.MESSAGE_TOO_LONG
    HEADER_FORMAT = NakReason.HEADER_FORMAT
    GARBAGE = 100  # bytes skipped while hunting for SOH/ENQ; no NAK

    @property
    def nak_reason(self) -> NakReason | None:
        """The NAK a running link answers this error with (None: no NAK)."""
        return None if self is FrameErrorReason.GARBAGE else NakReason(int(self))


def _check_byte(name: str, value: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 0xFF:
        raise ValueError(f"{name} must be an int in [0, 255], got {value!r}")


@dataclass(frozen=True)
class DataFrame:
    """A SOH data message. ``num``: its sequence number; ``resp``: last good NUM received."""

    num: int
    resp: int
    payload: bytes
    addr: int = DEFAULT_ADDRESS
    qsync: bool = False
    select: bool = False

    def __post_init__(self) -> None:
        _check_byte("num", self.num)
        _check_byte("resp", self.resp)
        _check_byte("addr", self.addr)
        if not isinstance(self.payload, bytes):
            raise TypeError(f"payload must be bytes, got {type(self.payload).__name__}")
        if not 1 <= len(self.payload) <= MAX_COUNT:
            raise ValueError(f"payload length must be in [1, {MAX_COUNT}], got {len(self.payload)}")


@dataclass(frozen=True)
class ControlFrame:
    """An ENQ control message. Field use by type (others zero):

    ACK: rcvr = RESP.  NAK: subtype = reason, rcvr = RESP.  REP: sndr = NUM of the last
    data message sent.  STRT, STACK: none.
    """

    kind: ControlType
    subtype: int = 0
    rcvr: int = 0
    sndr: int = 0
    addr: int = DEFAULT_ADDRESS
    qsync: bool = False
    select: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", ControlType(self.kind))
        if not isinstance(self.subtype, int) or not 0 <= self.subtype <= SUBTYPE_MASK:
            raise ValueError(f"subtype must be an int in [0, 63], got {self.subtype!r}")
        _check_byte("rcvr", self.rcvr)
        _check_byte("sndr", self.sndr)
        _check_byte("addr", self.addr)
        problem = _control_field_problem(self.kind, self.subtype, self.rcvr, self.sndr)
        if problem:
            raise ValueError(problem)

    @property
    def nak_reason(self) -> NakReason | None:
        """The reason of a NAK if it is a known code, else None."""
        if self.kind is not ControlType.NAK:
            return None
        try:
            return NakReason(self.subtype)
        except ValueError:
            return None


def _control_field_problem(kind: ControlType, subtype: int, rcvr: int, sndr: int) -> str | None:
    """The reason a control header is malformed, or None. Unused fields must be zero."""
    if kind is ControlType.NAK:
        return (
            None
            if sndr == 0 and subtype != 0
            else f"NAK needs a reason and SNDR 0 ({subtype=}, {sndr=})"
        )
    if subtype != 0:
        return f"{kind.name} must have SUBTYPE 0, got {subtype}"
    if kind is ControlType.ACK and sndr != 0:
        return f"ACK must have SNDR 0, got {sndr}"
    if kind is ControlType.REP and rcvr != 0:
        return f"REP must have RCVR 0, got {rcvr}"
    if kind in (ControlType.STRT, ControlType.STACK) and (rcvr or sndr):
        return f"{kind.name} must have RCVR and SNDR 0"
    return None


Frame = DataFrame | ControlFrame


@dataclass(frozen=True)
class FrameError:
    """Bytes the decoder rejected. ``discarded``: bytes dropped for this error."""

    reason: FrameErrorReason
    discarded: int
    detail: str = ""


# --- constructors for the control messages ---------------------------------------------


def ack(resp: int, addr: int = DEFAULT_ADDRESS) -> ControlFrame:
    """ACK: every data message up to and including ``resp`` was received."""
    return ControlFrame(ControlType.ACK, rcvr=resp, addr=addr)


def nak(resp: int, reason: NakReason, addr: int = DEFAULT_ADDRESS) -> ControlFrame:
    """NAK: messages up to ``resp`` are good, resend the rest; ``reason`` says why."""
    return ControlFrame(ControlType.NAK, subtype=int(reason), rcvr=resp, addr=addr)


def rep(num: int, addr: int = DEFAULT_ADDRESS) -> ControlFrame:
    """REP: 'I have sent up to ``num``, what have you received?'"""
    return ControlFrame(ControlType.REP, sndr=num, addr=addr)


def strt(addr: int = DEFAULT_ADDRESS) -> ControlFrame:
    return ControlFrame(ControlType.STRT, addr=addr, qsync=True, select=True)


def stack(addr: int = DEFAULT_ADDRESS) -> ControlFrame:
    return ControlFrame(ControlType.STACK, addr=addr, qsync=True, select=True)


# --- encoding ----------------------------------------------------------------------------


def encode_frame(frame: Frame) -> bytes:
    """The wire bytes of one frame (header with its CRC, then data and its CRC for SOH)."""
    if isinstance(frame, DataFrame):
        word = len(frame.payload)
        word |= QSYNC_COUNT_BIT if frame.qsync else 0
        word |= SELECT_COUNT_BIT if frame.select else 0
        head = _HEADER.pack(SOH, word, frame.resp, frame.num, frame.addr)
        return b"".join(
            (
                head,
                crc16(head).to_bytes(2, "little"),
                frame.payload,
                crc16(frame.payload).to_bytes(2, "little"),
            )
        )
    if isinstance(frame, ControlFrame):
        sub = frame.subtype
        sub |= QSYNC_SUBTYPE_BIT if frame.qsync else 0
        sub |= SELECT_SUBTYPE_BIT if frame.select else 0
        head = _CONTROL.pack(ENQ, int(frame.kind), sub, frame.rcvr, frame.sndr, frame.addr)
        return head + crc16(head).to_bytes(2, "little")
    raise TypeError(f"not a frame: {frame!r}")


def data_frame_bytes(payload_bytes: int) -> int:
    """Wire size of a data frame carrying ``payload_bytes`` of data."""
    return DATA_FRAME_OVERHEAD_BYTES + payload_bytes


# --- decoding ----------------------------------------------------------------------------


class DdcmpDecoder:
    """Incremental DDCMP frame decoder with resynchronisation.

    ``feed(data)`` returns, in stream order, ``DataFrame``, ``ControlFrame`` and
    ``FrameError`` items. Bytes that cannot start a frame are skipped (reported as one
    GARBAGE error per run); a header or data CRC failure drops only the first byte of the
    candidate frame, so a genuine frame hidden behind a corrupted one is still found.
    Memory is bounded: at most one frame's worth (8 + max_data_bytes + 2) is held back.
    """

    def __init__(self, max_data_bytes: int = 256) -> None:
        if not 1 <= max_data_bytes <= MAX_COUNT:
            raise ValueError(f"max_data_bytes must be in [1, {MAX_COUNT}], got {max_data_bytes}")
        self.max_data_bytes = max_data_bytes
        self._buf = bytearray()

    @property
    def pending_bytes(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def reset(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame | FrameError]:
        self._buf += data
        out: list[Frame | FrameError] = []
        garbage = 0
        buf = self._buf

        def flush_garbage() -> None:
            nonlocal garbage
            if garbage:
                out.append(FrameError(FrameErrorReason.GARBAGE, garbage, "no SOH/ENQ"))
                garbage = 0

        while buf:
            start = _find_sync(buf)
            if start < 0:
                garbage += len(buf)
                buf.clear()
                break
            if start:
                garbage += start
                del buf[:start]
            if len(buf) < HEADER_BYTES:
                break  # wait for the rest of the header
            head = bytes(buf[:6])
            if crc16(head) != int.from_bytes(buf[6:8], "little"):
                flush_garbage()
                out.append(FrameError(FrameErrorReason.HEADER_CRC, 1, f"class 0x{head[0]:02x}"))
                del buf[:1]
                continue
            if head[0] == ENQ:
                frame_or_error = _decode_control(head)
                flush_garbage()
                out.append(frame_or_error)
                del buf[: HEADER_BYTES if isinstance(frame_or_error, ControlFrame) else 1]
                continue
            # SOH: header is intact, now the data.
            _, word, resp, num, addr = _HEADER.unpack(head)
            count = word & MAX_COUNT
            if count == 0 or count > self.max_data_bytes:
                flush_garbage()
                reason = (
                    FrameErrorReason.HEADER_FORMAT
                    if count == 0
                    else FrameErrorReason.MESSAGE_TOO_LONG
                )
                out.append(FrameError(reason, 1, f"count {count}"))
                del buf[:1]
                continue
            end = HEADER_BYTES + count + CRC_BYTES
            if len(buf) < end:
                break  # wait for the rest of the data
            payload = bytes(buf[HEADER_BYTES : HEADER_BYTES + count])
            if crc16(payload) != int.from_bytes(buf[end - 2 : end], "little"):
                flush_garbage()
                out.append(FrameError(FrameErrorReason.DATA_CRC, 1, f"num {num} count {count}"))
                del buf[:1]  # why 1, not `end`: bytes may have been lost inside this frame
                continue
            flush_garbage()
            out.append(
                _checked(
                    DataFrame,
                    num=num,
                    resp=resp,
                    payload=payload,
                    addr=addr,
                    qsync=bool(word & QSYNC_COUNT_BIT),
                    select=bool(word & SELECT_COUNT_BIT),
                )
            )
            del buf[:end]
        flush_garbage()
        return out


def _find_sync(buf: bytearray) -> int:
    """Index of the first SOH or ENQ byte, or -1."""
    i_soh = buf.find(SOH)
    i_enq = buf.find(ENQ)
    if i_soh < 0:
        return i_enq
    if i_enq < 0:
        return i_soh
    return min(i_soh, i_enq)


def _decode_control(head: bytes) -> ControlFrame | FrameError:
    _, kind, sub, rcvr, sndr, addr = _CONTROL.unpack(head)
    try:
        kind = ControlType(kind)
    except ValueError:
        return FrameError(FrameErrorReason.HEADER_FORMAT, 1, f"unknown control type {kind}")
    subtype = sub & SUBTYPE_MASK
    problem = _control_field_problem(kind, subtype, rcvr, sndr)
    if problem:
        return FrameError(FrameErrorReason.HEADER_FORMAT, 1, problem)
    return _checked(
        ControlFrame,
        kind=kind,
        subtype=subtype,
        rcvr=rcvr,
        sndr=sndr,
        addr=addr,
        qsync=bool(sub & QSYNC_SUBTYPE_BIT),
        select=bool(sub & SELECT_SUBTYPE_BIT),
    )


def _checked(cls: type, **fields):
    """A frame of fields the decoder has already validated (bytes unpacked from a header
    whose CRC and field rules held), without __post_init__'s checks again: decoding runs
    for every frame on the line."""
    frame = object.__new__(cls)
    frame.__dict__.update(fields)
    return frame


class FrameDecodeError(ValueError):
    """``decode_frame`` was given bytes that are not exactly one valid frame."""


def decode_frame(data: bytes, max_data_bytes: int = MAX_COUNT) -> Frame:
    """Strictly decode exactly one frame (no leading, trailing or missing bytes)."""
    decoder = DdcmpDecoder(max_data_bytes)
    items = decoder.feed(data)
    if len(items) != 1 or isinstance(items[0], FrameError) or decoder.pending_bytes:
        raise FrameDecodeError(
            f"not exactly one valid frame: {items!r}, {decoder.pending_bytes} pending"
        )
    return items[0]
