"""The simulated EGM controller and the gateway over real UDP sockets, each checked against an
EGM client no one here wrote (ABBRobotEGM's EGM: its own egm_pb2 from ABB's definition)."""

from __future__ import annotations

import socket
import threading

import numpy as np
import pytest
from ABBRobotEGM import EGM
from ABBRobotEGM._egm_protobuf import egm_pb2 as abb

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.abb.protocol import pos_quat
from humanpt.robot_gateway.links.abb.shell import adapters
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.live import LiveShell
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.egm import EgmRobot
from humanpt.sim_robot.rsi import RsiRobotServer as UdpRobotServer
from tests.conftest import wait_for

pytestmark = pytest.mark.live


def test_abbs_egm_client_reads_the_simulated_robot_and_guides_it():
    robot = EgmRobot(SimRobotConfig(model="irb1600"), comm_timeout_s=2.0)
    start = robot.base_T_flange_mm
    egm = EGM(port=0)
    port = egm.socket.getsockname()[1]
    server = UdpRobotServer(robot, gateway=f"127.0.0.1:{port}").start()
    try:
        ok, state = egm.receive_from_robot(timeout=10.0)
        assert ok and state.header.mtype == abb.EgmHeader.MSGTYPE_DATA and state.mci_state == abb.EgmMCIState.MCI_RUNNING and state.motors_on
        p = state.cartesian.pos
        np.testing.assert_allclose([p.x, p.y, p.z], start[:3, 3], atol=1e-9)
        q = state.cartesian.orient
        np.testing.assert_allclose([q.u0, q.u1, q.u2, q.u3], pos_quat(start)[1], atol=1e-12)
        target = start[:3, 3] + np.array([5.0, -3.0, 2.0])
        quat = np.array(pos_quat(start)[1])

        def guided() -> bool:  # ABBRobotEGM answers each message with the target
            ok, _ = egm.receive_from_robot(timeout=1.0)
            if ok:
                egm.send_to_robot_cart(target, quat)
            return float(np.linalg.norm(robot.base_T_flange_mm[:3, 3] - target)) < 0.01
        wait_for(guided, 30.0, "the robot at the target ABBRobotEGM sent", poll_s=0.0)
        ok, state = egm.receive_from_robot(timeout=1.0)
        p = state.cartesian.pos
        np.testing.assert_allclose([p.x, p.y, p.z], target, atol=0.02)  # what it reads is where the arm is
        # The client goes silent: EGM stops after its communication timeout, the arm stays.
        at = robot.base_T_flange_mm[:3, 3].copy()
        wait_for(lambda: robot.stopped is not None, 30.0, "EGM stopped by its communication timeout")
        assert "communication timeout" in robot.stopped
        np.testing.assert_allclose(robot.base_T_flange_mm[:3, 3], at, atol=0.01)
    finally:
        server.stop()
        server.join(5)
        egm.close()
    assert robot.counters["malformed"] == 0 and robot.counters["answers"] >= 10


def test_the_gateway_in_a_live_shell_holds_the_robot_and_abbs_definition_reads_its_answers(router):
    """No controller on the bus: every EgmRobot is answered with the session's first target
    (the robot stays); the answers, captured on their way, parse with ABB's definition."""
    port, _ = router
    cfg = gateway_config("abb", udp_bind="127.0.0.1:0")
    ads = adapters(cfg)
    core = GatewayCore(cfg)
    shell = LiveShell(core, RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",), listen=(), record=False),
                      adapters=ads)
    seen: list[bytes] = []
    write = ads[0].write
    ads[0].write = lambda topic, msg: (seen.append(msg.data), write(topic, msg))[1]
    worker = threading.Thread(target=shell.run, daemon=True)
    worker.start()
    robot = EgmRobot(SimRobotConfig(model="irb1600"), comm_timeout_s=5.0)
    start = robot.base_T_flange_mm
    try:
        assert shell.ready.wait(30)
        gw_port = ads[0].address[1]
        server = UdpRobotServer(robot, gateway=f"127.0.0.1:{gw_port}", cycles=300).start()
        wait_for(lambda: len(seen) >= 50, 60.0, "50 answers from the gateway")
        server.stop()
        server.join(10)
    finally:
        shell.stop.set()
        worker.join(10)
    assert core.counters["fresh"] == core.counters["reused"] == 0 and core.counters["zero"] >= 50
    for data in seen:
        m = abb.EgmSensor.FromString(data)
        assert m.header.mtype == abb.EgmHeader.MSGTYPE_CORRECTION
        c = m.planned.cartesian.pos
        np.testing.assert_allclose([c.x, c.y, c.z], start[:3, 3], atol=1e-9)
    np.testing.assert_allclose(robot.base_T_flange_mm, start, atol=1e-9)  # holds only: the arm stayed
    assert robot.stopped is None


def test_another_senders_egm_messages_get_no_answer():
    # (a relock only after 4 s of silence: a loaded machine's pause is not the robot gone)
    ads = adapters(gateway_config("abb", udp_bind="127.0.0.1:0", udp_robot="127.0.0.1", status_timeout_cycles=1000))
    got: list = []
    a = ads[0]
    a.start(lambda topic, msg: got.append(msg))
    robot_sock, other = (socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2))
    try:
        for s in (robot_sock, other):
            s.bind(("127.0.0.1", 0))
        robot_port = robot_sock.getsockname()[1]
        r = EgmRobot(SimRobotConfig(model="irb1600"))
        other.sendto(b"\x08\x01junk", a.address)  # not an EgmRobot: never locks
        robot_sock.sendto(r.cycle(0), a.address)
        wait_for(lambda: len(got) >= 1, 10.0, "the robot's message taken")
        other.sendto(r.cycle(4_000_000), a.address)  # a valid one, from another port: dropped
        robot_sock.sendto(r.cycle(8_000_000), a.address)
        wait_for(lambda: len(got) >= 2, 10.0, "the robot's second message taken")
    finally:
        a.close()
        robot_sock.close()
        other.close()
    assert {m.header.frame_id for m in got} == {f"127.0.0.1:{robot_port}"}
    assert a.lock.counters["invalid"] == 1 and a.peer == ("127.0.0.1", robot_port)
