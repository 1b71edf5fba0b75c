"""A live RSI cell for the attack tests of issue 29: ``humanpt robot_gateway`` (link = "rsi",
12 ms) as a real process, a real Zenoh router, this test as the controller (liveliness token,
one constant command per robot state, as tests/rsi/test_rsi_processes.py), and the
simulated RSI controller on a thread of this process over real UDP on loopback
(``RsiRobotServer``, so that a test reads its pose and counters directly and hooks its
sending). The gateway's events are collected from the bus."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np

from humanpt.runtime.bus import liveliness_key
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import RsiRobot, RsiRobotServer
from tests.conftest import Procs, wait_for, write_config, zenoh_client

CYCLE_MS = 12


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LiveCell:
    """Start with :meth:`start_gateway`, :meth:`start_controller`, :meth:`start_robot`;
    ``events``: the gateway's events (pb.Event) as they came; ``close()`` stops what is left."""

    def __init__(self, procs: Procs, router_port: int, tmp_path: Path, step_mm=(0.48, 0.0, 0.0), **gateway):
        self.procs, self.port, self.tmp = procs, router_port, tmp_path
        self.udp = ("127.0.0.1", free_udp_port())
        self.step_mm = np.asarray(step_mm, dtype=float)
        self.gateway_keys = {"udp_robot": '"127.0.0.1"', **gateway}  # the demo's setting (host only)
        self.events: list[pb.Event] = []
        self.states = 0
        self.gw = None
        self.session = None
        self.robot: RsiRobot | None = None
        self.server: RsiRobotServer | None = None

    def start_gateway(self):
        keys = "".join(f"{k} = {v}\n" for k, v in self.gateway_keys.items())
        cfg = write_config(self.tmp / "rsi.toml", self.port, extra=(
            f'[robot_gateway]\nlink = "rsi"\ncycle_period_ms = {CYCLE_MS}.0\n'
            f'udp_bind = "{self.udp[0]}:{self.udp[1]}"\n{keys}'
            '[sim_robot]\nprotocol = "rsi"\n'))  # (the cell's one cycle is the link's)
        self.gw = self.procs.start("robot_gateway", "--config", str(cfg), "--run-dir", str(self.tmp / "run"))
        return self.gw

    def start_controller(self) -> None:
        s = self.session = zenoh_client(self.port)
        s.liveliness().declare_token(liveliness_key("test", "controller"))
        pub = s.declare_publisher("humanpt/test/controller/command")
        dt = self.step_mm / 1000.0

        def on_state(sample):
            st = pb.RobotState.FromString(sample.payload.to_bytes())
            self.states += 1
            pub.put(pb.FlangeCommand(
                header=header(st.header.stamp_ns, self.states, "world"), cycle=st.cycle,
                d_translation_m=pb.Vector3(x=dt[0], y=dt[1], z=dt[2]), mode=pb.CONTROL_MODE_TRACK,
            ).SerializeToString())

        def on_event(sample):
            self.events.append(pb.Event.FromString(sample.payload.to_bytes()))

        self._subs = [s.declare_subscriber("humanpt/test/robot_gateway/robot_state", on_state),
                      s.declare_subscriber("humanpt/test/robot_gateway/events", on_event)]

    def start_robot(self, after_send=None, **robot) -> RsiRobot:
        cfg = SimRobotConfig(**{"protocol": "rsi", "cycle_period_ns": CYCLE_MS * 1_000_000, **robot})
        self.robot = RsiRobot(cfg)
        self.server = RsiRobotServer(self.robot, gateway=f"{self.udp[0]}:{self.udp[1]}",
                                     after_send=after_send).start()
        return self.robot

    def wait_moving(self, applied: int = 30, timeout: float = 60.0) -> None:
        """Until the robot applied ``applied`` corrections (the loop runs: gateway up,
        controller answering)."""
        wait_for(lambda: (self.robot.counters["applied"] >= applied or self.robot.stopped is not None
                          or self.gw.poll() is not None), timeout, f"{applied} corrections applied by the robot")
        assert self.gw.poll() is None, self.procs.stop(self.gw)
        assert self.robot.stopped is None, self.robot.stopped

    @property
    def x_mm(self) -> float:
        return float(self.robot.base_T_flange_mm[0, 3])

    def codes(self) -> list[str]:
        return [e.code for e in list(self.events)]

    def close(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server.join(5.0)
        if self.session is not None:
            for sub in self._subs:
                sub.undeclare()
            self.session.close()
            self.session = None
