"""RSI messages: the wire format round trip, KUKA's angle convention (checked against
scipy), the limits held after rounding, and clear errors for what is not RSI."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.robot_gateway.links.rsi.protocol import (
    RobState,
    RsiCorrection,
    RsiProtocolError,
    decode_rob,
    decode_sen,
    encode_rob,
    encode_sen,
    rsi_correction,
)


def test_rob_and_sen_round_trip_at_four_decimals():
    rob = RobState(123456, (786.0, 190.12346, -296.0, 10.0, -20.0, 179.99), (1, 2, 3, 4, 5, 6), 7)
    back = decode_rob(encode_rob(rob))
    assert back.ipoc == 123456 and back.delay == 7 and back.aipos == (1, 2, 3, 4, 5, 6)
    assert back.rist == (786.0, 190.1235, -296.0, 10.0, -20.0, 179.99)
    sen = encode_sen(RsiCorrection(42, (0.1, -0.2, 0.0, 0.01, 0.0, -0.0)))
    assert sen == (b'<Sen Type="ImFree"><RKorr X="0.1000" Y="-0.2000" Z="0.0000" A="0.0100" '
                   b'B="0.0000" C="0.0000"/><IPOC>42</IPOC></Sen>')
    assert decode_sen(sen) == RsiCorrection(42, (0.1, -0.2, 0.0, 0.01, 0.0, 0.0))


def test_rkorr_angles_are_kukas_a_b_c_rotations_about_z_y_x():
    rv = np.radians([0.3, -0.2, 0.5])
    c = rsi_correction(1, np.zeros(3), rv, 1.0, 2.0)
    expected = Rotation.from_rotvec(rv).as_euler("ZYX", degrees=True)  # intrinsic Z, Y', X''
    np.testing.assert_allclose(c.rkorr[3:], np.round(expected, 4), atol=1e-12)
    R = c.delta_T_mm()[:3, :3]
    np.testing.assert_allclose(R, Rotation.from_euler("ZYX", c.rkorr[3:], degrees=True).as_matrix(), atol=1e-12)


def test_a_step_at_the_limits_stays_within_them_after_rounding():
    rng = np.random.default_rng(7)
    max_mm, max_deg = 0.4, 0.24  # 100 mm/s and 60 deg/s at 4 ms
    for _ in range(200):
        d = rng.normal(size=3)
        r = rng.normal(size=3)
        c = rsi_correction(1, d / np.linalg.norm(d) * max_mm, r / np.linalg.norm(r) * np.radians(max_deg),
                           max_mm, max_deg)
        assert np.linalg.norm(c.translation_mm) <= max_mm + 1e-12
        assert c.angle_deg() <= max_deg + 1e-9
        assert np.linalg.norm(c.translation_mm) > max_mm - 5e-4  # and not shrunk more than needed


@pytest.mark.parametrize("data, why", [
    (b"<Rob><RIst X=", "malformed XML"),
    (b"<Sen/>", "<Rob> was expected"),
    (b'<Rob><AIPos A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/><IPOC>1</IPOC></Rob>', "no <RIst>"),
    (b'<Rob><RIst X="0" Y="0" Z="0" A="0" B="0"/><IPOC>1</IPOC></Rob>', "lacks attribute C"),
    (b'<Rob><RIst X="0" Y="0" Z="0" A="0" B="0" C="x"/><IPOC>1</IPOC></Rob>', "<RIst>"),
    (b'<Rob><RIst X="0" Y="0" Z="0" A="0" B="0" C="0"/><AIPos A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/>'
     b"<IPOC>-3</IPOC></Rob>", "no valid <IPOC>"),
    (b'<!DOCTYPE r [<!ENTITY a "aaaa">]><Rob/>', "DOCTYPE"),
    (b"<Rob>" + b" " * 5000 + b"</Rob>", "datagram of"),
])
def test_what_is_not_an_rsi_message_is_a_clear_error(data, why):
    with pytest.raises(RsiProtocolError, match=why.replace("<", ".").replace(">", ".")):
        decode_rob(data)
