"""The RSI gateway and the simulated RSI controller as cores in the lock-step shell
(UDP paths with a 0.1 ms delivery delay, the robot's 4 ms clock as its tick) with a
scripted controller: deterministic (two runs, one digest), every cycle answered in time,
and both recordings replay exactly."""

from __future__ import annotations

import pytest

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.replay import replay
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import RsiSimRobotCore
from humanpt.testing.harness import ScriptedControllerConfig, ScriptedControllerCore

SECONDS = 2


def _run(run_dir):
    sim = RsiSimRobotCore(SimRobotConfig(protocol="rsi", cycle_period_ns=4_000_000))
    gw = GatewayCore(RsiConfig(udp_bind="127.0.0.1:0", cycle_period_ms=4.0))
    # Steps within the 0.4 mm / 0.24 deg per cycle limits at 4 ms.
    ctl = ScriptedControllerCore(ScriptedControllerConfig(amplitude_mm=0.2, amplitude_deg=0.1))
    with Lockstep([sim, gw, ctl], run_dir=run_dir) as ls:
        ls.connect_udp("sim_robot", "robot_gateway")
        ls.run_until(SECONDS * 1_000_000_000)
        return ls.digest(), sim.robot


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("rsi-lockstep")
    return d, _run(d / "a"), _run(None)


def test_two_runs_are_identical_and_every_cycle_is_answered_in_time(runs):
    _, (digest_a, robot), (digest_b, _) = runs
    assert digest_a == digest_b
    cycles = SECONDS * 1000 // 4
    assert robot.stopped is None and robot.counters["cycles"] >= cycles
    assert robot.counters["late"] == 0 and robot.counters["on_time"] == robot.counters["cycles"] - 1
    assert robot.counters["applied"] > 0.9 * cycles  # the scripted steps moved the arm


def test_the_recordings_replay_exactly(runs):
    d, _, _ = runs
    for comp in ("sim_robot", "robot_gateway"):
        res = replay(d / "a" / f"{comp}.mcap")
        assert res.match and res.compared > 400, res.report()
