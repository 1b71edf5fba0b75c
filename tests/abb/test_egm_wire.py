"""Issue 34 item 2: humanpt's EGM definition (links/abb/humanpt_egm.proto, written for
humanpt) is wire-compatible with ABB's: checked against the egm_pb2 that the PyPI package
ABBRobotEGM (Apache-2.0, written by others from ABB's RobotWare egm.proto) ships, field by
field and message by message both ways; the committed generated code is fresh."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from ABBRobotEGM._egm_protobuf import egm_pb2 as abb
from google.protobuf import descriptor_pb2

from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.links.abb import humanpt_egm_pb2 as ours
from humanpt.robot_gateway.links.abb.protocol import (
    EgmProtocolError,
    EgmState,
    EgmTarget,
    decode_robot,
    decode_sensor,
    encode_robot,
    encode_sensor,
    pos_quat,
)

PROTO = Path(ours.__file__).with_name("humanpt_egm.proto")


def test_the_generated_code_is_fresh(tmp_path):
    out = tmp_path / "set.pb"
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", f"-I{PROTO.parent}", f"--descriptor_set_out={out}",
                    str(PROTO)], check=True)
    fresh = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()).file[0]
    committed = descriptor_pb2.FileDescriptorProto()
    ours.DESCRIPTOR.CopyToProto(committed)
    for fdp in (fresh, committed):
        for m in fdp.message_type:
            for f in m.field:
                f.ClearField("json_name")
    assert committed.SerializeToString(deterministic=True) == fresh.SerializeToString(deterministic=True), (
        "humanpt_egm_pb2.py is stale: cd components/robot_gateway/links/abb && "
        "python -m grpc_tools.protoc -I. --python_out=. humanpt_egm.proto")


@pytest.mark.parametrize("name", sorted(ours.DESCRIPTOR.message_types_by_name))
def test_every_field_has_abbs_number_type_and_label(name):
    mine, theirs = ours.DESCRIPTOR.message_types_by_name[name], abb.DESCRIPTOR.message_types_by_name[name]
    for f in mine.fields:
        t = theirs.fields_by_name[f.name]
        assert (f.number, f.type, f.is_repeated, f.is_required) == (t.number, t.type, t.is_repeated, t.is_required), f.name
        if f.message_type is not None:
            assert f.message_type.name == t.message_type.name
        if f.enum_type is not None:
            assert {v.name: v.number for v in f.enum_type.values} == {v.name: v.number for v in t.enum_type.values}


def test_the_robots_message_as_abbs_definition_reads_it_and_back():
    T = transform_from_x(np.array([786.0, 190.0, -296.0, 10.0, 20.0, 170.0]))
    pos, quat = pos_quat(T)
    data = encode_robot(EgmState(41, 1234, pos, quat))
    m = abb.EgmRobot.FromString(data)
    assert (m.header.seqno, m.header.tm, m.header.mtype) == (41, 1234, abb.EgmHeader.MSGTYPE_DATA)
    c = m.feedBack.cartesian
    assert (c.pos.x, c.pos.y, c.pos.z) == pos and (c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3) == quat
    assert m.mciState.state == abb.EgmMCIState.MCI_RUNNING and m.motorState.state == abb.EgmMotorState.MOTORS_ON
    # ABB's own message (with fields humanpt does not define) decodes with ours
    m.utilizationRate = 12.5
    back = decode_robot(m.SerializeToString())
    assert back.seqno == 41 and np.allclose(back.base_T_flange_mm(), T, atol=1e-9)


def test_the_sensors_message_as_abbs_definition_reads_it_and_back():
    T = transform_from_x(np.array([700.0, 0.0, 100.0, 0.0, 90.0, 0.0]))
    pos, quat = pos_quat(T)
    m = abb.EgmSensor.FromString(encode_sensor(EgmTarget(7, 99, pos, quat)))
    assert m.header.mtype == abb.EgmHeader.MSGTYPE_CORRECTION and m.header.seqno == 7
    assert (m.planned.cartesian.pos.x, m.planned.cartesian.pos.y, m.planned.cartesian.pos.z) == pos
    assert np.allclose(decode_sensor(m.SerializeToString()).base_T_target_mm(), T, atol=1e-9)


@pytest.mark.parametrize("data, why", [
    (b"", "empty"),
    (b"\xff" * 10, "not an EgmRobot"),
    (b"x" * 5000, "longer than"),
    (abb.EgmRobot(mciConvergenceMet=True).SerializeToString(), "without header.seqno"),
])
def test_what_is_not_a_robots_message_is_refused_with_its_reason(data, why):
    with pytest.raises(EgmProtocolError, match=why):
        decode_robot(data)


def test_a_pose_that_is_not_a_pose_is_refused():
    m = abb.EgmRobot()
    m.header.seqno, m.header.mtype = 1, abb.EgmHeader.MSGTYPE_DATA
    c = m.feedBack.cartesian
    c.pos.x, c.pos.y, c.pos.z = 1.0, 2.0, float("nan")
    c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = 1.0, 0.0, 0.0, 0.0
    with pytest.raises(EgmProtocolError, match="not finite"):
        decode_robot(m.SerializeToString())
    c.pos.z = 3.0
    c.orient.u0 = 2.0
    with pytest.raises(EgmProtocolError, match="not a unit quaternion"):
        decode_robot(m.SerializeToString())
    m.feedBack.ClearField("cartesian")
    with pytest.raises(EgmProtocolError, match="feedBack.cartesian"):
        decode_robot(m.SerializeToString())
    s = abb.EgmSensor()  # a sensor's message sent back at the gateway is not the robot's
    s.header.seqno, s.header.mtype = 3, abb.EgmHeader.MSGTYPE_CORRECTION
    with pytest.raises(EgmProtocolError, match="not DATA"):
        decode_robot(s.SerializeToString())
