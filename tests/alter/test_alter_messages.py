"""STATUS and CORRECTION payloads: layout, round trips, validation, units."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from humanpt.robot_gateway.links.alter.budget import ALTER_CYCLE_NS
from humanpt.robot_gateway.links.alter.messages import (
    CORRECTION_PAYLOAD_BYTES,
    INT16_MAX,
    STATUS_PAYLOAD_BYTES,
    ControllerStatus,
    Correction,
    CorrectionFlags,
    MessageError,
    StatusBits,
    decode_correction,
    decode_message,
    decode_status,
    encode_correction,
    encode_status,
)

FAST = settings(max_examples=150, deadline=None, derandomize=True)

i32 = st.integers(-(2**31), 2**31 - 1)
i16 = st.integers(-(2**15), 2**15 - 1)
u32 = st.integers(0, 2**32 - 1)
statuses = st.builds(
    ControllerStatus,
    cycle=u32,
    bits=st.integers(0, 0x3F).map(StatusBits),
    x_10um=i32,
    y_10um=i32,
    z_10um=i32,
    yaw_cdeg=st.integers(-18000, 18000),
    pitch_cdeg=st.integers(-9000, 9000),
    roll_cdeg=st.integers(-18000, 18000),
)
corrections = st.builds(
    Correction,
    echo_cycle=u32,
    flags=st.sampled_from([CorrectionFlags(0), CorrectionFlags.ALTER_OFF]),
    dx_10um=i16,
    dy_10um=i16,
    dz_10um=i16,
    drx_cdeg=i16,
    dry_cdeg=i16,
    drz_cdeg=i16,
)


def test_sizes_and_layout():
    assert STATUS_PAYLOAD_BYTES == 31
    assert CORRECTION_PAYLOAD_BYTES == 19
    s = ControllerStatus(0x01020304, StatusBits.ALTER_ACTIVE | StatusBits.FAULT, 1, -1, 2, 3, -4, 5)
    wire = encode_status(s)
    assert wire[0] == 0x53
    assert wire[1:5] == bytes([4, 3, 2, 1])  # little-endian cycle
    assert wire[5:7] == bytes([0x11, 0])
    assert wire[7:11] == (1).to_bytes(4, "little", signed=True)
    assert wire[11:15] == (-1).to_bytes(4, "little", signed=True)
    c = Correction(7, CorrectionFlags.ALTER_OFF, -2, 0, 0, 0, 0, 300)
    wire = encode_correction(c)
    assert wire[0] == 0x43 and wire[1:5] == bytes([7, 0, 0, 0]) and wire[5:7] == bytes([1, 0])
    assert wire[7:9] == (-2).to_bytes(2, "little", signed=True)
    assert wire[17:19] == (300).to_bytes(2, "little", signed=True)


@FAST
@given(statuses)
def test_status_round_trip(status):
    assert decode_status(encode_status(status)) == status
    assert decode_message(encode_status(status)) == status


@FAST
@given(corrections)
def test_correction_round_trip(correction):
    assert decode_correction(encode_correction(correction)) == correction
    assert decode_message(encode_correction(correction)) == correction


@FAST
@given(st.binary(max_size=40))
def test_decoders_never_raise_anything_but_message_error(payload):
    for decode in (decode_status, decode_correction, decode_message):
        try:
            msg = decode(payload)
        except MessageError:
            continue
        # Whatever decodes must re-encode to exactly the input.
        enc = encode_status if isinstance(msg, ControllerStatus) else encode_correction
        assert enc(msg) == payload


def test_decoders_validate():
    good = encode_correction(Correction(1, CorrectionFlags(0), 1, 2, 3, 4, 5, 6))
    with pytest.raises(MessageError):
        decode_correction(good[:-1])
    with pytest.raises(MessageError):
        decode_correction(good + b"\x00")
    with pytest.raises(MessageError):
        decode_status(good)
    bad_flags = bytearray(good)
    bad_flags[5] = 0x80  # undefined flag bit
    with pytest.raises(MessageError, match="undefined"):
        decode_correction(bytes(bad_flags))
    hold_nonzero = bytearray(good)
    hold_nonzero[5] = int(CorrectionFlags.HOLD)
    with pytest.raises(MessageError, match="HOLD"):
        decode_correction(bytes(hold_nonzero))
    s = bytearray(encode_status(ControllerStatus(1, StatusBits(0), 0, 0, 0, 0, 0, 0)))
    s[23:27] = (9001).to_bytes(4, "little", signed=True)  # pitch beyond 90 deg
    with pytest.raises(MessageError, match="pitch"):
        decode_status(bytes(s))
    with pytest.raises(MessageError):
        decode_message(b"")
    with pytest.raises(MessageError):
        decode_message(b"\x00" * 19)


def test_hold_is_zero():
    c = Correction.hold(5)
    assert c.deltas == (0,) * 6 and CorrectionFlags.HOLD in c.flags
    assert np.allclose(c.delta_T_mm(), np.eye(4))


def test_per_cycle_safety_limits_fit_int16_with_margin():
    cycle_s = ALTER_CYCLE_NS / 1e9
    step_10um = 100.0 * cycle_s / 0.01  # 100 mm/s
    step_cdeg = 60.0 * cycle_s / 0.01  # 60 deg/s
    assert round(step_10um) == 280 and round(step_cdeg) == 168
    assert 100 * step_10um < INT16_MAX  # even 100x the default limit fits
    c = Correction.from_mm_deg(1, [2.8, -2.8, 0.0], [1.68, 0.0, -1.68])
    assert c.deltas == (280, -280, 0, 168, 0, -168)


def test_from_mm_deg_rounds_and_refuses_to_clip():
    c = Correction.from_mm_deg(1, [0.004, 0.006, -0.016], [0.0, 0.0, 0.0])
    assert c.deltas[:3] == (0, 1, -2)
    with pytest.raises(ValueError, match="outside"):
        Correction.from_mm_deg(1, [327.68, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="finite"):
        Correction.from_mm_deg(1, [np.nan, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError):
        Correction(2**32, CorrectionFlags(0), 0, 0, 0, 0, 0, 0)


@FAST
@given(
    st.lists(st.floats(-1500, 1500), min_size=3, max_size=3),
    st.integers(0, 2**31),
)
def test_status_from_pose_quantises_within_half_a_unit(p_mm, seed):
    R = Rotation.random(random_state=seed)
    ypr = R.as_euler("ZYX", degrees=True)
    if abs(ypr[1]) > 89.0:  # gimbal lock: yaw/roll not unique
        return
    T = np.eye(4)
    T[:3, :3] = R.as_matrix()
    T[:3, 3] = p_mm
    s = ControllerStatus.from_pose(9, StatusBits.ALTER_ACTIVE, T)
    back = s.base_T_flange_mm()
    assert np.max(np.abs(back[:3, 3] - p_mm)) <= 0.005 + 1e-9
    angle_err = (Rotation.from_matrix(back[:3, :3]).inv() * R).magnitude()
    assert np.degrees(angle_err) < 0.01  # three 0.005 deg roundings
    assert s.cycle == 9 and s.bits == StatusBits.ALTER_ACTIVE


def test_correction_delta_T_uses_zyx():
    c = Correction.from_mm_deg(1, [1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    T = c.delta_T_mm()
    expected = Rotation.from_euler("ZYX", [3.0, 2.0, 1.0], degrees=True).as_matrix()
    assert np.allclose(T[:3, :3], expected)
    assert np.allclose(T[:3, 3], [1.0, 2.0, 3.0])
