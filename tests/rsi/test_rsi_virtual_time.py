"""The RSI gateway and the simulated RSI controller wired in memory in virtual time (no
sockets, no clock): deterministic (two runs, identical), and the arm goes where the
commands say (the sum of the commanded steps, to the wire's 0.0001 mm per cycle)."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.bench.rsi import CommandAhead, circle_step
from humanpt.robot_gateway.core import ROBOT_STATE, GatewayCore
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import RsiRobot

pytestmark = pytest.mark.twin  # runs the lock-step twin for seconds

CYCLES = 400
MS = 1_000_000


def _run(cycle_ms: float):
    gw = GatewayCore(RsiConfig(udp_bind="127.0.0.1:0", cycle_period_ms=cycle_ms))
    robot = RsiRobot(SimRobotConfig(protocol="rsi", cycle_period_ns=round(cycle_ms * 1e6)))
    controller = CommandAhead(cycle_ms, circle_step(speed_mm_s=20.0, radius_mm=30.0))
    p0 = robot.base_T_flange_mm[:3, 3].copy()
    period = round(cycle_ms * MS)

    def step(t_ns, topic, msg):
        for out_topic, out in gw.step(t_ns, topic, msg):
            if out_topic == "udp_tx":
                robot.receive(out.data, t_ns + 100_000)  # 0.1 ms on the wire
            elif out_topic == ROBOT_STATE:
                step(t_ns + 50_000, "controller/command", controller.answer(out))

    t = period
    for _ in range(CYCLES):
        rob = robot.cycle(t)
        step(t + 100_000, "udp_rx", pb.SerialChunk(header=header(t + 100_000), data=rob))
        tick = t + 100_000 + gw.config.tick_period_ns
        while tick < t + period:  # the gateway's timer between datagrams
            step(tick, "tick", pb.Tick(header=header(tick)))
            tick += gw.config.tick_period_ns
        t += period
    robot.finish(t)
    return gw, robot, controller, p0


@pytest.fixture(scope="module", params=[4.0, 12.0])
def runs(request):
    return request.param, _run(request.param), _run(request.param)


def test_two_runs_are_identical(runs):
    _, (gw1, robot1, _, _), (gw2, robot2, _, _) = runs
    assert [(s.cycle, s.source, s.correction) for s in gw1.sent] == [(s.cycle, s.source, s.correction) for s in gw2.sent]
    np.testing.assert_array_equal(robot1.q_rad, robot2.q_rad)
    assert robot1.counters == robot2.counters


def test_every_cycle_is_answered_in_time_and_the_arm_follows_the_commands(runs):
    cycle_ms, (gw, robot, controller, p0), _ = runs
    assert robot.stopped is None and robot.counters["late"] == 0 and robot.counters["on_time"] == CYCLES
    # The first cycle has no command yet: held (at the reply deadline); the rest fresh.
    assert gw.counters["zero"] == 1 and gw.counters["fresh"] == CYCLES - 1
    # Every command the controller sent for cycles 2..CYCLES moved the arm (the answer to
    # cycle k is applied at the start of k + 1; the last one is judged at the end).
    step = circle_step(speed_mm_s=20.0, radius_mm=30.0)
    commanded = sum(step(n, cycle_ms) for n in range(CYCLES - 1))
    moved = robot.base_T_flange_mm[:3, 3] - p0
    # Each RKorr is rounded to 0.0001 mm, and IK/FK round trips add ~1e-9 mm per cycle.
    np.testing.assert_allclose(moved, commanded, atol=CYCLES * 0.5e-4)
    assert np.linalg.norm(commanded) > 5.0  # (a real motion: 20 mm/s for 1.6 s or 4.8 s)
