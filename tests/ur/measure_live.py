"""Live figure for links/ur/README.md (not a test): the gateway (a live shell, no controller on
the bus: it holds) over TCP to the simulated UR's RTDE server, both in this one process; the
fraction of the program's cycles that saw a new sequence (answered in time).

    humanpt router --config CELL.toml &     # a router at tcp/127.0.0.1:PORT
    python -m tests.ur.measure_live CYCLE_MS SECONDS PORT
"""
import sys
import threading
import time

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.ur.shell import adapters
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.live import LiveShell
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.ur import RtdeServer, UrRobot

cycle_ms, seconds, port = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
robot = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=cycle_ms)
server = RtdeServer(robot, "127.0.0.1:0").start()
cfg = gateway_config("ur", rtde_address="{}:{}".format(*server.address), cycle_period_ms=cycle_ms)
core = GatewayCore(cfg)
shell = LiveShell(core, RuntimeConfig(cell="measure", connect=(f"tcp/127.0.0.1:{port}",), listen=(), record=False), adapters=adapters(cfg))
worker = threading.Thread(target=shell.run, daemon=True)
worker.start()
shell.ready.wait(30)
while robot.counters["new_sequence"] == 0:
    time.sleep(0.01)
with server.lock:
    c0, n0 = robot.counters["cycles"], robot.counters["new_sequence"]
time.sleep(seconds)
with server.lock:
    c1, n1 = robot.counters["cycles"], robot.counters["new_sequence"]
shell.stop.set()
worker.join(10)
server.close()
print(f"{cycle_ms:g} ms, {seconds:g} s: {n1 - n0}/{c1 - c0} program cycles with a new sequence = "
      f"{100.0 * (n1 - n0) / (c1 - c0):.2f} %; watchdog stops {robot.counters['watchdog_stops']}, "
      f"gateway sessions {core.link.counters['sessions']}, link errors {core.counters.get('link_errors')}")
