"""The gateway in a live shell over real TCP to the simulated UR's RTDE server: set-up,
answers every cycle (the program's watchdog never trips while the gateway runs), a dropped
connection set up again, and the watchdog stopping the arm once the gateway is gone."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.ur.shell import adapters
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.live import LiveShell
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.ur import RtdeServer, UrRobot
from tests.conftest import wait_for

pytestmark = pytest.mark.live


def test_the_gateway_holds_the_simulated_ur_over_tcp_and_sets_up_again_after_a_drop(router):
    port, _ = router
    robot = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=8.0)  # a CB3 at 125 Hz (the gentler rate on a loaded machine)
    server = RtdeServer(robot, "127.0.0.1:0").start()
    start = robot.base_T_flange_mm
    host, rport = server.address
    # (a silence watchdog of 250 cycles = 2 s: a loaded machine's pause is not the robot gone)
    cfg = gateway_config("ur", rtde_address=f"{host}:{rport}", cycle_period_ms=8.0, status_timeout_cycles=250)
    ads = adapters(cfg)
    core = GatewayCore(cfg)
    shell = LiveShell(core, RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",), listen=(), record=False),
                      adapters=ads)
    worker = threading.Thread(target=shell.run, daemon=True)
    worker.start()
    try:
        assert shell.ready.wait(30)
        wait_for(lambda: robot.followed_seq >= 50, 60.0, "50 answers followed by the program")
        assert robot.counters["watchdog_stops"] == 0 and core.link.counters["sessions"] == 1
        server.disconnect_all()  # the controller drops the client (a reboot, a cable)
        wait_for(lambda: core.link.counters["sessions"] >= 2, 60.0, "a second session after the drop")
        seq = robot.followed_seq
        wait_for(lambda: robot.followed_seq >= seq + 50, 60.0, "50 more answers")
    finally:
        shell.stop.set()
        worker.join(10)
    assert ads[0].connections >= 2
    # No controller on the bus: every answer is the session's first target (the arm stays).
    np.testing.assert_allclose(robot.base_T_flange_mm, start, atol=1e-9)
    assert core.counters["fresh"] == 0 and core.counters["zero"] >= 100
    # The gateway is gone: the program's watchdog stops the arm.
    wait_for(lambda: robot.counters["watchdog_stops"] >= 1, 30.0, "the watchdog's stop")
    server.close()
    assert robot.counters["malformed"] == 0
