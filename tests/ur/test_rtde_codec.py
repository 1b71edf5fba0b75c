"""RTDE's wire as UR's RTDE guide gives it (uint16 size incl. the header, uint8 type, big
endian), cut from a stream in any pieces; what is not RTDE refused with one line."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.links.ur import protocol as rtde


def test_a_protocol_version_request_is_the_guides_bytes():
    # size 5 = 3 header bytes + uint16 version 2; type 'V' = 86
    assert rtde.encode_version_request() == bytes([0, 5, 86, 0, 2])
    assert rtde.pack(rtde.START) == b"\x00\x03S"


def test_an_output_setup_carries_the_frequency_as_a_big_endian_double():
    data = rtde.encode_setup_outputs(500.0, ("timestamp", "actual_TCP_pose"))
    assert data[:3] == struct.pack(">HB", len(data), ord("O"))
    assert data[3:11] == struct.pack(">d", 500.0)
    assert data[11:] == b"timestamp,actual_TCP_pose"
    (p,) = rtde.Framer().feed(data)
    assert rtde.decode_setup_outputs(p.payload) == (500.0, ("timestamp", "actual_TCP_pose"))


def test_a_recipe_packs_each_type_big_endian():
    r = rtde.Recipe(3, ("timestamp", "actual_TCP_pose", "robot_mode", "runtime_state", "output_bit_register_64"),
                    ("DOUBLE", "VECTOR6D", "INT32", "UINT32", "BOOL"))
    assert r.size == 8 + 48 + 4 + 4 + 1
    values = {"timestamp": 1.5, "actual_TCP_pose": (0.1, 0.2, 0.3, 0.0, 3.14, 0.0), "robot_mode": 7,
              "runtime_state": 2, "output_bit_register_64": True}
    data = r.encode(values)
    assert data[:4] == struct.pack(">HBB", 4 + r.size, ord("U"), 3)
    assert data[4:12] == struct.pack(">d", 1.5)
    assert data[-9:] == struct.pack(">iI?", 7, 2, True)
    (p,) = rtde.Framer().feed(data)
    assert r.decode(p.payload) == values


def test_the_framer_takes_packets_in_any_pieces():
    packets = [rtde.encode_version_request(), rtde.pack(rtde.START), rtde.encode_text("hello", "x", 1)]
    stream = b"".join(packets)
    for cut in range(1, len(stream)):
        f = rtde.Framer()
        got = f.feed(stream[:cut]) + f.feed(stream[cut:])
        assert [rtde.pack(p.type, p.payload) for p in got] == packets
        assert not f.errors


def test_a_bad_header_is_reported_and_the_framer_finds_the_next_data_package():
    r = rtde.Recipe(1, ("timestamp",), ("DOUBLE",))
    good = r.encode({"timestamp": 2.0})
    f = rtde.Framer()
    f.sync = good[:4]
    got = f.feed(b"\xff\xff\x00garbage" + good)
    assert len(f.errors) == 1 and "size 65535" in str(f.errors[0])
    assert [r.decode(p.payload) for p in got] == [{"timestamp": 2.0}]


@pytest.mark.parametrize("payload, what", [
    (b"\x01" + b"\x00" * 7, "payload of 8 bytes"),  # cut short
    (b"\x02" + struct.pack(">d", 1.0), "recipe 2, expected 1"),  # another recipe's
])
def test_a_data_package_that_is_not_the_recipes_is_refused(payload, what):
    r = rtde.Recipe(1, ("timestamp",), ("DOUBLE",))
    with pytest.raises(rtde.RtdeProtocolError, match=what):
        r.decode(payload)


def test_a_setup_reply_with_a_foreign_type_is_refused():
    with pytest.raises(rtde.RtdeProtocolError, match="not RTDE's"):
        rtde.decode_setup_reply(b"\x01DOUBLE,FLOAT128", "output setup")
    assert rtde.decode_setup_reply(b"\x00DOUBLE,IN_USE", "input setup") == (0, ("DOUBLE", "IN_USE"))


def test_a_ur_pose_is_metres_and_a_rotation_vector():
    # 180 deg about x: rotation vector (pi, 0, 0); 786 mm -> 0.786 m
    T = transform_from_x(np.array([786.0, 190.0, -296.0, 0.0, 0.0, 180.0]))
    pose = rtde.ur_pose_from_transform(T)
    np.testing.assert_allclose(pose[:3], (0.786, 0.190, -0.296), atol=1e-15)
    assert abs(np.linalg.norm(pose[3:]) - np.pi) < 1e-9
    np.testing.assert_allclose(rtde.transform_from_ur_pose(pose), T, atol=1e-12)
    with pytest.raises(rtde.RtdeProtocolError, match="6 finite numbers"):
        rtde.transform_from_ur_pose((0.1, 0.2, float("nan"), 0, 0, 0))
