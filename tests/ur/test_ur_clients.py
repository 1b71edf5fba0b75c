"""The simulated UR serves every RTDE client at once, as a UR does (sim_robot as a component,
in memory): a second client is refused the registers the first holds (IN_USE), each client
gets its own answers, a closed client's registers are free again, and a client sending
bytes that are not RTDE is dropped (an empty serial_tx chunk to it: the server closes it)."""

from __future__ import annotations

from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.ur import CLOSED, UrSimRobotCore

GATEWAY, OTHER = "127.0.0.1:40001", "127.0.0.1:40002"


def _chunk(client: str, data: bytes) -> pb.SerialChunk:
    return pb.SerialChunk(header=header(0, frame_id=client), data=data)


def _replies(outs, client: str) -> list[rtde.Packet]:
    framer = rtde.Framer()
    return [p for topic, m in outs if topic == "serial_tx" and m.header.frame_id == client
            for p in framer.feed(bytes(m.data))]


def _setup_inputs(core, client: str) -> tuple[int, tuple[str, ...]]:
    outs = core._on_rtde(0, _chunk(client, rtde.encode_setup_inputs(("input_int_register_24",))))
    (reply,) = _replies(outs, client)
    return rtde.decode_setup_reply(reply.payload, "input setup")


def test_two_clients_at_once_and_a_closed_one_frees_its_registers():
    core = UrSimRobotCore.create(SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000))
    for c in (GATEWAY, OTHER):
        core._on_rtde(0, _chunk(c, b""))  # the server's marks: two connections
    assert _setup_inputs(core, GATEWAY) == (1, ("INT32",))
    assert _setup_inputs(core, OTHER) == (0, ("IN_USE",))  # held by the gateway's session
    # Each client's answers go to it: the version request of one is answered to that one only.
    outs = core._on_rtde(0, _chunk(OTHER, rtde.encode_version_request()))
    assert len(_replies(outs, OTHER)) == 1 and _replies(outs, GATEWAY) == []
    core._on_rtde(0, _chunk(GATEWAY + CLOSED, b""))  # the gateway's connection closed
    assert core.robot.input_owner == {}
    assert _setup_inputs(core, OTHER) == (1, ("INT32",))


def test_a_client_sending_what_is_not_rtde_is_dropped_the_others_kept():
    core = UrSimRobotCore.create(SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000))
    for c in (GATEWAY, OTHER):
        core._on_rtde(0, _chunk(c, b""))
    _setup_inputs(core, GATEWAY)
    outs = core._on_rtde(0, _chunk(OTHER, b"\xff\xff\xffjunk"))
    assert [(t, m.header.frame_id, m.data) for t, m in outs if t == "serial_tx"] == [("serial_tx", OTHER, b"")]
    assert "bad_rtde" in [m.code for t, m in outs if t == "sim_robot/events"]
    assert set(core.clients) == {"", GATEWAY} and core.robot.input_owner  # the gateway's session kept
