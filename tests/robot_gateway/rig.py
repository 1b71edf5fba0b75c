"""A gateway core wired, in memory and instantly, to a pure ControllerEndpoint (a fake robot)."""

from __future__ import annotations

import numpy as np

from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.alter import (
    ControllerEndpoint,
    ControllerStatus,
    Correction,
    CorrectionReceived,
    StatusBits,
    Transmit,
)
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, vector3

MS = 1_000_000
CYCLE_NS = 28 * MS
# The sim_robot's default start: flange down at (786, 190, -296) mm.
START_X = np.array([786.0, 190.0, -296.0, 0.0, 0.0, 180.0])
ACTIVE = StatusBits.ALTER_ACTIVE | StatusBits.ARM_POWER | StatusBits.CUMULATIVE


class Rig:
    """Drive an GatewayCore with scripted statuses, commands, ticks and liveliness.

    ``corrections``: (cycle, Correction) the fake robot received (validated by the real
    controller endpoint). ``outs``: every gateway output. Bytes cross instantly.
    """

    def __init__(self, config: AlterConfig | None = None, **kw):
        self.gw = GatewayCore(config or AlterConfig(**kw))
        self.robot = ControllerEndpoint()
        self.t_ns = 0
        self.cycle = 0
        self.base_T_flange = transform_from_x(START_X)
        self.bits = ACTIVE
        self.outs: list = []
        self.corrections: list[tuple[int, Correction]] = []
        self.robot_connected = True
        self.seq = 0  # the controller session's header.seq: +1 per command
        self._to_gw: list[bytes] = []
        self._deliver(self.robot.start(0))
        self.step("tick", pb.Tick(header=header(0)))

    # -- plumbing ---------------------------------------------------------------------
    def step(self, topic: str, msg) -> list:
        outs = self.gw.step(self.t_ns, topic, msg)
        self.outs += outs
        for t, m in outs:
            if t == "serial_tx" and self.robot_connected:
                self._deliver(self.robot.receive(m.data, self.t_ns))
        while self._to_gw:
            data = self._to_gw.pop(0)
            outs += self.step("serial_rx", pb.SerialChunk(header=header(self.t_ns), data=data))
        return outs

    def _deliver(self, events) -> None:
        for e in events:
            if isinstance(e, Transmit):
                if self.robot_connected:
                    self._to_gw.append(e.data)
            elif isinstance(e, CorrectionReceived):
                self.corrections.append((e.correction.echo_cycle, e.correction))

    # -- scripting ----------------------------------------------------------------------
    def advance(self, dt_ns: int, tick_ns: int = 2 * MS) -> list:
        """Let time pass, ticking the gateway every ``tick_ns``."""
        outs = []
        end = self.t_ns + dt_ns
        while self.t_ns + tick_ns <= end:
            self.t_ns += tick_ns
            outs += self.step("tick", pb.Tick(header=header(self.t_ns)))
        self.t_ns = end
        return outs

    def status(self, bits: StatusBits | None = None, cycle: int | None = None) -> list:
        """The robot sends STATUS for its next cycle (now)."""
        self.cycle = self.cycle + 1 if cycle is None else cycle
        st = ControllerStatus.from_pose(
            self.cycle, self.bits if bits is None else bits, self.base_T_flange
        )
        self._deliver(self.robot.send_status(st, self.t_ns))
        outs = []
        while self._to_gw:
            outs += self.step(
                "serial_rx", pb.SerialChunk(header=header(self.t_ns), data=self._to_gw.pop(0))
            )
        return outs

    def command(
        self,
        cycle: int | None = None,
        dp_mm=(0, 0, 0),
        rv_deg=(0, 0, 0),
        frame: str = "world",
        mode=pb.CONTROL_MODE_TRACK,
        alter_off: bool = False,
    ) -> list:
        cycle = self.cycle if cycle is None else cycle
        cmd = pb.FlangeCommand(
            header=header(self.stamp_for(cycle), self.seq, frame),
            cycle=cycle,
            d_translation_m=vector3(np.asarray(dp_mm, float) / 1000.0),
            d_rotation_rad=vector3(np.radians(np.asarray(rv_deg, float))),
            mode=mode,
            request_alter_off=alter_off,
        )
        self.seq += 1
        return self.step("controller/command", cmd)

    def stamp_for(self, cycle: int) -> int:
        """What a controller stamps its command for ``cycle`` with: the stamp of the
        gateway's last robot_state, + one cycle per cycle ahead (now, before any state)."""
        states = self.states()
        if not states:
            return self.t_ns
        last = states[-1]
        return last.header.stamp_ns + (cycle - last.cycle) * CYCLE_NS

    def liveliness(self, alive: bool) -> list:
        return self.step(
            "liveliness",
            pb.Liveliness(header=header(self.t_ns), component="controller", alive=alive),
        )

    def cycle_with_command(self, dp_mm=(0, 0, 0), rv_deg=(0, 0, 0), **kw) -> list:
        """STATUS, then the command for it at once, then the rest of the cycle."""
        outs = self.status()
        outs += self.command(dp_mm=dp_mm, rv_deg=rv_deg, **kw)
        outs += self.advance(CYCLE_NS)
        return outs

    # -- reading -------------------------------------------------------------------------
    def events(self, outs=None) -> list[pb.Event]:
        return [m for t, m in (self.outs if outs is None else outs) if t == "robot_gateway/events"]

    def codes(self, outs=None) -> list[str]:
        return [e.code for e in self.events(outs)]

    def states(self) -> list[pb.RobotState]:
        return [m for t, m in self.outs if t == "robot_gateway/robot_state"]

    def last_correction(self) -> Correction:
        return self.corrections[-1][1]
