"""The simulated UR's live RTDE server (sim_robot/shell.py TcpServerAdapter, ``[sim_robot]
protocol = "rtde"``) over a real loopback TCP socket: each connection is marked by an empty
chunk (its end by one from "<peer> closed"), bytes cross both ways; the core starts a fresh RTDE
session on the mark (the old one's input registers freed)."""

from __future__ import annotations

import queue
import socket

import pytest

from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.shell import TcpServerAdapter, adapters
from humanpt.sim_robot.ur import CLOSED, DASHBOARD, UrSimRobotCore


def _get(q: queue.Queue) -> bytes:
    topic, msg = q.get(timeout=10)
    assert topic == "serial_rx"
    return bytes(msg.data)


def test_connections_are_marked_and_bytes_cross():
    server = TcpServerAdapter("127.0.0.1:0")
    q: queue.Queue = queue.Queue()
    server.start(lambda topic, msg: q.put((topic, msg)))
    try:
        a = socket.create_connection(server.address, timeout=10)
        a_name = a.getsockname()[:2]
        assert _get(q) == b""  # the new connection's mark
        a.sendall(b"abc")
        got = b""
        while len(got) < 3:
            got += _get(q)
        assert got == b"abc"
        server.write("serial_tx", pb.SerialChunk(data=b"xyz"))
        assert a.recv(16) == b"xyz"
        a.close()  # the gateway goes (its end marked); it reconnects: a fresh connection, marked again
        _, gone = q.get(timeout=10)
        assert gone.data == b"" and gone.header.frame_id == "{}:{}".format(*a_name) + CLOSED
        b = socket.create_connection(server.address, timeout=10)
        assert _get(q) == b""
        server.write("serial_tx", pb.SerialChunk(data=b"to b"))
        assert b.recv(16) == b"to b"
        b.close()
    finally:
        server.close()


def test_the_config_makes_the_server_and_a_taken_port_is_one_line():
    cfg = SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000, rtde_bind="127.0.0.1:0")
    (server,) = adapters(cfg)
    try:
        assert isinstance(server, TcpServerAdapter)
        with pytest.raises(OSError, match=r"cannot listen for RTDE at 127\.0\.0\.1:\d+"):
            TcpServerAdapter("{}:{}".format(*server.address))
    finally:
        server.close()
    with pytest.raises(ValueError):
        SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000, rtde_bind="nowhere")


def test_a_new_connection_starts_a_fresh_session():
    core = UrSimRobotCore.create(SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000))
    first = core.session
    # the first client holds an input register
    core._on_rtde(0, pb.SerialChunk(data=rtde.encode_version_request()))
    core._on_rtde(0, pb.SerialChunk(data=rtde.pack(rtde.SETUP_INPUTS, b"input_int_register_24")))
    assert core.robot.input_owner == {"input_int_register_24": first.sid}
    assert core._on_rtde(1, pb.SerialChunk(data=b"")) == []  # the server's mark: a new connection
    assert core.session is not first and core.session.sid == first.sid + 1
    assert core.robot.input_owner == {} and list(core.robot.sessions) == [core.session.sid]


def test_the_dashboard_port_is_served_by_the_same_adapter_and_marked_as_such():
    """The Dashboard server beside RTDE on one accept loop: its connections come as
    "dashboard <peer>" (marked, bytes, end), serial_tx to that frame_id reaches that client
    only; the config's default puts it at the RTDE port less 5 (29999 beside 30004)."""
    server = TcpServerAdapter("127.0.0.1:0", dashboard="127.0.0.1:0")
    q: queue.Queue = queue.Queue()
    server.start(lambda topic, msg: q.put((topic, msg)))
    try:
        rtde_client = socket.create_connection(server.address, timeout=10)
        _, mark = q.get(timeout=10)
        assert mark.header.frame_id == "{}:{}".format(*rtde_client.getsockname()[:2])
        dash = socket.create_connection(server.dashboard_address, timeout=10)
        who = DASHBOARD + "{}:{}".format(*dash.getsockname()[:2])
        _, mark = q.get(timeout=10)
        assert (mark.header.frame_id, mark.data) == (who, b"")
        dash.sendall(b"running\n")
        _, got = q.get(timeout=10)
        assert (got.header.frame_id, got.data) == (who, b"running\n")
        server.write("serial_tx", pb.SerialChunk(header=pb.Header(frame_id=who), data=b"Program running: true\n"))
        assert dash.recv(64) == b"Program running: true\n"
        server.write("serial_tx", pb.SerialChunk(data=b"rtde"))  # (no frame_id: the latest RTDE client's)
        assert rtde_client.recv(16) == b"rtde"
        server.write("serial_tx", pb.SerialChunk(header=pb.Header(frame_id=who)))  # the server drops it
        assert dash.recv(16) == b""
        _, gone = q.get(timeout=10)
        assert (gone.header.frame_id, gone.data) == (who + CLOSED, b"")
        dash.close()
        rtde_client.close()
        with pytest.raises(OSError, match=r"^sim_robot: cannot listen for Dashboard at 127\.0\.0\.1:\d+: "):
            TcpServerAdapter("127.0.0.1:0", dashboard="{}:{}".format(*server.dashboard_address))
    finally:
        server.close()
    assert SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000).dashboard_address == "127.0.0.1:29999"
    assert SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000, rtde_bind="127.0.0.1:0",
                          dashboard_bind="127.0.0.1:1234").dashboard_address == "127.0.0.1:1234"
    with pytest.raises(ValueError, match=r"^dashboard_bind: an address must be host:port"):
        SimRobotConfig(protocol="rtde", cycle_period_ns=2_000_000, dashboard_bind="nowhere")
