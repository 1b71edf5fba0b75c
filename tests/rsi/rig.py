"""An RSI gateway core wired in memory, instantly, to a scripted RSI robot (encoded <Rob>
datagrams in, decoded <Sen> answers out): the RSI twin of tests/robot_gateway/rig.Rig."""

from __future__ import annotations

import numpy as np

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.protocol import RobState, RsiCorrection, decode_sen, encode_rob
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, vector3
from tests.robot_gateway.rig import MS, START_X


class RsiRig:
    """Drive an GatewayCore with scripted <Rob> datagrams, commands, ticks, liveliness.
    ``corrections``: (cycle, RsiCorrection) the robot received; ``outs``: every output."""

    def __init__(self, config: RsiConfig | None = None, **kw):
        kw.setdefault("udp_bind", "127.0.0.1:0")
        self.gw = GatewayCore(config or RsiConfig(**kw))
        self.cycle_ms = int(self.gw.config.cycle_period_ms)
        self.t_ns = 0
        self.cycle = 0
        self.rist = tuple(float(v) for v in START_X)
        self.delay = 0
        self.outs: list = []
        self.corrections: list[tuple[int, RsiCorrection]] = []
        self.seq = 0
        self.step("tick", pb.Tick(header=header(0)))

    def step(self, topic: str, msg) -> list:
        outs = self.gw.step(self.t_ns, topic, msg)
        self.outs += outs
        for t, m in outs:
            if t == "udp_tx":
                c = decode_sen(m.data)
                self.corrections.append((c.ipoc // self.cycle_ms, c))
        return outs

    def advance(self, dt_ns: int, tick_ns: int = 2 * MS) -> list:
        outs = []
        end = self.t_ns + dt_ns
        while self.t_ns + tick_ns <= end:
            self.t_ns += tick_ns
            outs += self.step("tick", pb.Tick(header=header(self.t_ns)))
        self.t_ns = end
        return outs

    def datagram(self, data: bytes) -> list:
        return self.step("udp_rx", pb.SerialChunk(header=header(self.t_ns), data=data))

    def status(self, cycle: int | None = None) -> list:
        """The robot sends the <Rob> of its next cycle (IPOC = cycle x cycle time), now."""
        self.cycle = self.cycle + 1 if cycle is None else cycle
        return self.datagram(encode_rob(RobState(self.cycle * self.cycle_ms, self.rist, (0.0,) * 6, self.delay)))

    def command(self, cycle: int | None = None, dp_mm=(0, 0, 0), rv_deg=(0, 0, 0), frame: str = "world",
                mode=pb.CONTROL_MODE_TRACK) -> list:
        cycle = self.cycle if cycle is None else cycle
        states = self.states()
        stamp = states[-1].header.stamp_ns + (cycle - states[-1].cycle) * self.cycle_ms * MS if states else self.t_ns
        cmd = pb.FlangeCommand(
            header=header(stamp, self.seq, frame), cycle=cycle,
            d_translation_m=vector3(np.asarray(dp_mm, float) / 1000.0),
            d_rotation_rad=vector3(np.radians(np.asarray(rv_deg, float))), mode=mode)
        self.seq += 1
        return self.step("controller/command", cmd)

    def liveliness(self, alive: bool) -> list:
        return self.step("liveliness", pb.Liveliness(header=header(self.t_ns), component="controller", alive=alive))

    def events(self, outs=None) -> list[pb.Event]:
        return [m for t, m in (self.outs if outs is None else outs) if t == "robot_gateway/events"]

    def codes(self, outs=None) -> list[str]:
        return [e.code for e in self.events(outs)]

    def states(self) -> list[pb.RobotState]:
        return [m for t, m in self.outs if t == "robot_gateway/robot_state"]
