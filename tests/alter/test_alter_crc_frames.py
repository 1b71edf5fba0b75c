"""CRC-16 and DDCMP frame encode/decode."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.robot_gateway.links.alter.crc import crc16, crc16_bitwise, crc16_bytes
from humanpt.robot_gateway.links.alter.ddcmp import (
    ENQ,
    SOH,
    ControlFrame,
    ControlType,
    DataFrame,
    DdcmpDecoder,
    FrameDecodeError,
    FrameError,
    FrameErrorReason,
    NakReason,
    ack,
    decode_frame,
    encode_frame,
    nak,
    rep,
    stack,
    strt,
)

FAST = settings(max_examples=150, deadline=None, derandomize=True)

byte = st.integers(0, 255)
data_frames = st.builds(
    DataFrame,
    num=byte,
    resp=byte,
    payload=st.binary(min_size=1, max_size=80),
    addr=byte,
    qsync=st.booleans(),
    select=st.booleans(),
)


@st.composite
def control_frames(draw) -> ControlFrame:
    kind = draw(st.sampled_from(list(ControlType)))
    flags = {"addr": draw(byte), "qsync": draw(st.booleans()), "select": draw(st.booleans())}
    if kind is ControlType.ACK:
        return ControlFrame(kind, rcvr=draw(byte), **flags)
    if kind is ControlType.NAK:
        return ControlFrame(kind, subtype=draw(st.integers(1, 63)), rcvr=draw(byte), **flags)
    if kind is ControlType.REP:
        return ControlFrame(kind, sndr=draw(byte), **flags)
    return ControlFrame(kind, **flags)


frames = st.one_of(data_frames, control_frames())


def test_crc_check_value_is_crc16_arc():
    assert crc16(b"123456789") == 0xBB3D
    assert crc16_bitwise(b"123456789") == 0xBB3D
    assert crc16(b"") == 0


@FAST
@given(st.binary(max_size=200), st.integers(0, 200))
def test_crc_table_matches_bitwise_and_continues(data, split):
    assert crc16(data) == crc16_bitwise(data)
    assert crc16(data[split:], crc16(data[:split])) == crc16(data)
    # Residue: a block followed by its own CRC (low byte first) checks to zero.
    assert crc16(data + crc16_bytes(data)) == 0


def test_header_layout_bytes():
    wire = encode_frame(DataFrame(num=5, resp=3, payload=b"\x01\x02\x03", addr=1, qsync=True))
    assert wire[0] == SOH
    assert int.from_bytes(wire[1:3], "little") == 3 | 0x4000
    assert (wire[3], wire[4], wire[5]) == (3, 5, 1)  # RESP, NUM, ADDR
    assert int.from_bytes(wire[6:8], "little") == crc16(wire[:6])
    assert wire[8:11] == b"\x01\x02\x03"
    assert int.from_bytes(wire[11:13], "little") == crc16(b"\x01\x02\x03")
    assert len(wire) == 13
    n = encode_frame(nak(7, NakReason.DATA_CRC))
    assert (n[0], n[1], n[2] & 0x3F, n[3], n[4], n[5]) == (ENQ, 2, 2, 7, 0, 1)
    assert len(n) == 8
    assert encode_frame(rep(9))[4] == 9
    assert encode_frame(ack(200))[3] == 200
    assert encode_frame(strt())[1] == 6 and encode_frame(stack())[1] == 7


@FAST
@given(frames)
def test_frame_round_trip(frame):
    assert decode_frame(encode_frame(frame)) == frame


@FAST
@given(st.lists(frames, min_size=1, max_size=8), st.lists(st.integers(1, 30), max_size=20))
def test_decoder_any_chunking_gives_the_same_frames(frame_list, cuts):
    wire = b"".join(encode_frame(f) for f in frame_list)
    decoder = DdcmpDecoder(max_data_bytes=80)
    got, pos = [], 0
    for cut in cuts:
        got += decoder.feed(wire[pos : pos + cut])
        pos += cut
    got += decoder.feed(wire[pos:])
    assert got == frame_list
    assert decoder.pending_bytes == 0


@FAST
@given(st.lists(frames, min_size=1, max_size=5), st.binary(max_size=30))
def test_decoder_resyncs_after_leading_garbage(frame_list, garbage):
    wire = b"".join(encode_frame(f) for f in frame_list)
    items = DdcmpDecoder(max_data_bytes=80).feed(garbage + wire)
    good = [i for i in items if not isinstance(i, FrameError)]
    # The genuine frames all come out, last ones intact (garbage may at most spoof extra).
    assert good[-len(frame_list) :] == frame_list


def test_header_crc_error_then_resync_to_next_frame():
    a = bytearray(encode_frame(DataFrame(1, 0, b"abc")))
    a[4] ^= 0x10  # corrupt NUM: header CRC fails
    b = encode_frame(ack(1))
    items = DdcmpDecoder().feed(bytes(a) + b)
    assert items[0] == FrameError(FrameErrorReason.HEADER_CRC, 1, "class 0x81")
    assert items[-1] == ack(1)
    assert not any(isinstance(i, DataFrame) for i in items)


def test_data_crc_error_reported_and_next_frame_found():
    a = bytearray(encode_frame(DataFrame(1, 0, b"abcdef")))
    a[9] ^= 0x01
    b = encode_frame(DataFrame(2, 0, b"xyz"))
    items = DdcmpDecoder().feed(bytes(a) + b)
    assert items[0].reason is FrameErrorReason.DATA_CRC
    assert items[-1] == DataFrame(2, 0, b"xyz")


def test_lost_bytes_inside_a_frame_do_not_hide_the_next_one():
    a = encode_frame(DataFrame(1, 0, b"0123456789"))
    b = encode_frame(DataFrame(2, 0, b"abcdefghij"))
    decoder = DdcmpDecoder()
    items = decoder.feed(a[:12] + b)  # a lost its tail: a's count swallows b's start
    items += decoder.feed(encode_frame(rep(2)))  # more traffic completes the bad frame
    assert DataFrame(2, 0, b"abcdefghij") in items
    assert rep(2) in items
    assert any(isinstance(i, FrameError) and i.reason is FrameErrorReason.DATA_CRC for i in items)


def test_too_long_and_zero_count_and_unknown_type_are_errors():
    long = encode_frame(DataFrame(1, 0, bytes(100)))
    items = DdcmpDecoder(max_data_bytes=64).feed(long)
    assert items[0].reason is FrameErrorReason.MESSAGE_TOO_LONG
    assert not any(isinstance(i, DataFrame) for i in items)
    head = bytes([SOH, 0, 0, 0, 1, 1])
    items = DdcmpDecoder().feed(head + crc16_bytes(head))
    assert items[0].reason is FrameErrorReason.HEADER_FORMAT
    head = bytes([ENQ, 4, 0, 0, 0, 1])  # type 4 is not defined
    items = DdcmpDecoder().feed(head + crc16_bytes(head))
    assert items[0].reason is FrameErrorReason.HEADER_FORMAT
    head = bytes([ENQ, 1, 0, 3, 9, 1])  # ACK with SNDR != 0
    assert DdcmpDecoder().feed(head + crc16_bytes(head))[0].reason is FrameErrorReason.HEADER_FORMAT


def test_garbage_only_is_reported_and_not_kept():
    decoder = DdcmpDecoder()
    items = decoder.feed(b"\x00\x11\x22hello")
    assert items == [FrameError(FrameErrorReason.GARBAGE, 8, "no SOH/ENQ")]
    assert decoder.pending_bytes == 0


def test_decode_frame_is_strict():
    wire = encode_frame(ack(3))
    with pytest.raises(FrameDecodeError):
        decode_frame(wire + b"\x00")
    with pytest.raises(FrameDecodeError):
        decode_frame(wire[:-1])
    with pytest.raises(FrameDecodeError):
        decode_frame(wire + wire)


def test_frame_fields_are_validated():
    with pytest.raises(ValueError):
        DataFrame(256, 0, b"x")
    with pytest.raises(ValueError):
        DataFrame(0, 0, b"")
    with pytest.raises(TypeError):
        DataFrame(0, 0, "text")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        ControlFrame(ControlType.NAK)  # a NAK needs a reason
    with pytest.raises(ValueError):
        ControlFrame(ControlType.STRT, rcvr=1)
    with pytest.raises(ValueError):
        ControlFrame(99)  # type: ignore[arg-type]
    assert nak(0, NakReason.HEADER_CRC).nak_reason is NakReason.HEADER_CRC
    assert ack(0).nak_reason is None


def test_protocol_md_examples_are_what_the_encoders_produce():
    from humanpt.robot_gateway.links.alter.messages import (
        ControllerStatus,
        Correction,
        CorrectionFlags,
        StatusBits,
        encode_correction,
        encode_status,
    )

    def hx(s: str) -> bytes:
        return bytes.fromhex(s.replace("|", " "))

    assert encode_frame(strt()) == hx("05 06 c0 00 00 01 75 95")
    assert encode_frame(stack()) == hx("05 07 c0 00 00 01 48 55")
    assert encode_frame(ack(5)) == hx("05 01 00 05 00 01 ec 54")
    assert encode_frame(nak(4, NakReason.DATA_CRC)) == hx("05 02 02 04 00 01 f8 2c")
    assert encode_frame(rep(5)) == hx("05 03 00 00 05 01 86 c5")
    status = ControllerStatus(
        1000, StatusBits.ALTER_ACTIVE | StatusBits.ARM_POWER, 65000, 19000, 72500, 0, 0, 18000
    )
    assert encode_frame(DataFrame(5, 4, encode_status(status))) == hx(
        "81 1f 00 04 05 01 08 82 | 53 e8 03 00 00 09 00 e8 fd 00 00 38 4a 00 00 34 1b 01 00"
        "00 00 00 00 00 00 00 00 50 46 00 00 | 4b fc"
    )
    corr = Correction(1000, CorrectionFlags(0), 120, -35, 0, 0, 0, 10)
    assert encode_frame(DataFrame(5, 5, encode_correction(corr))) == hx(
        "81 13 00 05 05 01 49 43 | 43 e8 03 00 00 00 00 78 00 dd ff 00 00 00 00 00 00 0a 00 | 62 48"
    )
