"""The ABB EGM link (pure): sequence, absolute targets with a bounded lead, holds; the
gateway over it in virtual time against the simulated EGM controller: the arm goes where the
steps add up to, and a silent gateway leaves it at most the lead further."""

from __future__ import annotations

import math

import numpy as np
import pytest

from humanpt.geometry.transforms import rotation_angle_rad, transform_from_x
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.link import CycleReceived, LinkError, LinkUp
from humanpt.robot_gateway.links import gateway_config, link_kind
from humanpt.robot_gateway.links.abb.link import MAX_GAP_CYCLES, AbbLink
from humanpt.robot_gateway.links.abb.protocol import EgmState, decode_sensor, encode_robot, pos_quat
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, vector3
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.egm import EgmRobot

START = transform_from_x(np.array([786.0, 190.0, -296.0, 0.0, 0.0, 180.0]))
MS = 1_000_000


def rob(seqno: int, T=START) -> bytes:
    pos, quat = pos_quat(T)
    return encode_robot(EgmState(seqno, seqno * 4, pos, quat))


def cycles(events) -> list[int]:
    return [e.state.cycle for e in events if isinstance(e, CycleReceived)]


def test_the_sequence_duplicates_gaps_and_a_restart():
    link = AbbLink()
    ev = link.receive(rob(100), 0)
    assert isinstance(ev[0], LinkUp) and cycles(ev) == [100]
    assert link.receive(rob(100), 0) == []  # a duplicate: dropped
    assert cycles(link.receive(rob(103), 0)) == [103]  # two lost: a gap the gateway counts
    ev = link.receive(rob(90), 0)  # back: out of sequence, dropped
    assert isinstance(ev[0], LinkError) and "out of sequence" in ev[0].text
    assert cycles(link.receive(rob(104), 0)) == [104]  # the session went on: it was nothing
    far = 104 + MAX_GAP_CYCLES + 1
    assert isinstance(link.receive(rob(far), 0)[0], LinkError)
    ev = link.receive(rob(far + 1), 0)  # continues it: the robot restarted EGM
    assert isinstance(ev[0], LinkUp) and cycles(ev) == [far + 1]
    assert link.counters["sessions"] == 2


def test_steps_add_to_an_absolute_target_whose_lead_is_bounded():
    link = AbbLink(max_lead_mm=2.0, max_lead_deg=1.0)
    link.receive(rob(1), 0)
    for _ in range(3):  # the robot has not moved: the target runs ahead 0.8, 1.6, then 2.0 mm
        target = link.correction(1, np.array([0.8, 0.0, 0.0]), np.zeros(3), 10.0, 10.0)
    np.testing.assert_allclose(np.array(target.pos_mm) - START[:3, 3], [2.0, 0.0, 0.0], atol=1e-9)
    assert link.counters["lead_limited"] == 1
    t = link.correction(1, np.zeros(3), np.radians([0.0, 0.0, 3.0]), 10.0, 10.0)
    R = decode_sensor(link.send(t, 0)[0].data).base_T_target_mm()[:3, :3]
    assert math.degrees(float(rotation_angle_rad(START[:3, :3].T @ R))) == pytest.approx(1.0, abs=1e-6)


def test_a_hold_keeps_the_target_and_a_fault_hold_stops_where_the_robot_is():
    link = AbbLink()
    link.receive(rob(1), 0)
    link.correction(1, np.array([1.0, 0.0, 0.0]), np.zeros(3), 10.0, 10.0)
    held = link.hold(2, corrections_off=False)
    np.testing.assert_allclose(np.array(held.pos_mm) - START[:3, 3], [1.0, 0.0, 0.0], atol=1e-9)
    stop = link.hold(3, corrections_off=True)
    np.testing.assert_allclose(stop.pos_mm, START[:3, 3], atol=1e-9)


def test_a_tool_frame_step_moves_along_the_flanges_axes():
    link = AbbLink(correction_frame="tool")
    link.receive(rob(1), 0)
    t = link.correction(1, np.array([0.0, 0.0, 1.0]), np.zeros(3), 10.0, 10.0)  # +z of the flange
    np.testing.assert_allclose(np.array(t.pos_mm) - START[:3, 3], START[:3, 2] * 1.0, atol=1e-9)


def _loop(gw: GatewayCore, robot: EgmRobot, n: int, step_mm=(0.2, 0.0, 0.0), command=True):
    """n EGM cycles in virtual time: the robot's message, a command for its cycle (the
    test as the controller), the gateway's answer back to the robot."""
    cycle_ns = round(robot.cycle_ms * MS)
    t = robot._started_ns or 0
    for _ in range(n):
        t += cycle_ns
        data = robot.cycle(t)
        if data is None:
            return t
        outs = gw.step(t, "udp_rx", pb.SerialChunk(header=header(t), data=data))
        state = [m for topic, m in outs if topic == "robot_gateway/robot_state"]
        if command and state:
            outs += gw.step(t, "controller/command", pb.FlangeCommand(
                header=header(state[-1].header.stamp_ns, state[-1].cycle), cycle=state[-1].cycle,
                d_translation_m=vector3(np.asarray(step_mm) / 1000.0), d_rotation_rad=vector3((0.0, 0.0, 0.0)),
                mode=pb.CONTROL_MODE_TRACK))
        outs += gw.step(t + cycle_ns // 2, "tick", pb.Tick(header=header(t + cycle_ns // 2)))
        for topic, m in outs:
            if topic == "udp_tx":
                robot.receive(m.data, t + cycle_ns // 2)
    return t


def test_the_arm_goes_where_the_steps_add_up_and_a_silent_gateway_leaves_it_within_the_lead():
    cfg = gateway_config("abb", udp_bind="127.0.0.1:0", max_lead_mm=3.0)
    gw = GatewayCore(cfg)
    robot = EgmRobot(SimRobotConfig(model="irb1600"), time_constant_s=0.02)
    p0 = robot.base_T_flange_mm[:3, 3].copy()
    t = _loop(gw, robot, 200)  # 200 x 0.2 mm commanded, in the base frame's +x
    sent = [s for s in gw.sent if s.source == "fresh"]
    commanded = sum(float(s.step[0][0]) for s in sent)
    assert len(sent) >= 150 and commanded == pytest.approx(0.2 * len(sent), rel=1e-9)
    target_x = gw.link.target[0, 3] - p0[0]
    assert target_x == pytest.approx(commanded, abs=1e-6)  # no step lost on the way to the target
    lag = target_x - (robot.base_T_flange_mm[0, 3] - p0[0])
    assert 0 <= lag <= cfg.max_lead_mm + 1e-9
    # The gateway goes silent: the arm converges to the last target and no further; then EGM stops.
    before = robot.base_T_flange_mm[:3, 3].copy()
    while robot.cycle(t := t + 4 * MS) is not None:
        pass
    moved = robot.base_T_flange_mm[:3, 3] - before
    assert np.linalg.norm(moved) <= cfg.max_lead_mm + 1e-6
    assert robot.base_T_flange_mm[0, 3] - p0[0] == pytest.approx(target_x, abs=1e-3)
    assert robot.stopped and "communication timeout" in robot.stopped
    assert link_kind("abb").late_repeats(cfg) == math.floor(3.0 / cfg.max_step_mm)
