"""One test rig for any link: a gateway core wired, in memory and instantly, to a scripted
robot that speaks the core's link (its robot side, :data:`ROBOTS`; the real codecs on both
ends: ALTER's controller endpoint validates what it receives, RSI's answers are decoded).

A link's robot side: ``begin(t_ns)`` the bytes the robot sends at start; ``send(cycle,
base_T_flange_mm, bits, t_ns)`` the bytes of its state for ``cycle``; ``take(data, t_ns)``
-> (bytes back to the gateway, [(cycle, correction)] the robot accepted); ``fields``: what
the link's config needs in a test (a free UDP port...)."""

from __future__ import annotations

import numpy as np

from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.abb.protocol import EgmState, decode_sensor, encode_robot, pos_quat
from humanpt.robot_gateway.links.alter import (
    ControllerEndpoint,
    ControllerStatus,
    Correction,
    CorrectionReceived,
    StatusBits,
    Transmit,
)
from humanpt.robot_gateway.links.rsi.protocol import RobState, decode_sen, encode_rob
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, vector3

MS = 1_000_000
CYCLE_NS = 28 * MS  # ALTER's default cycle
# The sim_robot's default start: flange down at (786, 190, -296) mm.
START_X = np.array([786.0, 190.0, -296.0, 0.0, 0.0, 180.0])
ACTIVE = StatusBits.ALTER_ACTIVE | StatusBits.ARM_POWER | StatusBits.CUMULATIVE


class AlterRobot(ControllerEndpoint):
    """ALTER's robot side: the codec's controller end (DDCMP, STATUS out, CORRECTION in)."""

    fields: dict = {}

    def __init__(self, config=None):
        super().__init__()

    def begin(self, t_ns: int) -> list[bytes]:
        return [e.data for e in self.start(t_ns) if isinstance(e, Transmit)]

    def send(self, cycle: int, base_T_flange_mm: np.ndarray, bits, t_ns: int) -> list[bytes]:
        st = ControllerStatus.from_pose(cycle, bits, base_T_flange_mm)
        return [e.data for e in self.send_status(st, t_ns) if isinstance(e, Transmit)]

    def take(self, data: bytes, t_ns: int) -> tuple[list[bytes], list[tuple[int, Correction]]]:
        events = self.receive(data, t_ns)
        return ([e.data for e in events if isinstance(e, Transmit)],
                [(e.correction.echo_cycle, e.correction) for e in events if isinstance(e, CorrectionReceived)])


class RsiRobot:
    """RSI's robot side: a <Rob> datagram per cycle (IPOC = cycle x cycle time, ``rist`` the
    flange X, Y, Z mm, A, B, C deg; ``delay`` its late-answer count), <Sen> answers decoded."""

    fields = {"udp_bind": "127.0.0.1:0"}

    def __init__(self, config):
        self.cycle_ms = int(config.cycle_period_ms)
        self.rist = tuple(float(v) for v in START_X)
        self.delay = 0

    def begin(self, t_ns: int) -> list[bytes]:
        return []  # RSI has no handshake

    def send(self, cycle: int, base_T_flange_mm: np.ndarray, bits, t_ns: int) -> list[bytes]:
        return [encode_rob(RobState(cycle * self.cycle_ms, self.rist, (0.0,) * 6, self.delay))]

    def take(self, data: bytes, t_ns: int) -> tuple[list[bytes], list]:
        c = decode_sen(data)
        return [], [(c.ipoc // self.cycle_ms, c)]


class AbbRobot:
    """ABB EGM's robot side: an EgmRobot per cycle (seqno = cycle, the fed-back pose), each
    EgmSensor decoded (its target, for the cycle last sent)."""

    fields = {"udp_bind": "127.0.0.1:0"}

    def __init__(self, config):
        self.cycle = 0

    def begin(self, t_ns: int) -> list[bytes]:
        return []  # EGM has no handshake

    def send(self, cycle: int, base_T_flange_mm: np.ndarray, bits, t_ns: int) -> list[bytes]:
        self.cycle = cycle
        pos, quat = pos_quat(base_T_flange_mm)
        return [encode_robot(EgmState(cycle, t_ns // MS, pos, quat))]

    def take(self, data: bytes, t_ns: int) -> tuple[list[bytes], list]:
        return [], [(self.cycle, decode_sensor(data))]


class UrRigRobot:
    """UR RTDE's robot side: the simulated controller's RTDE session (the set-up answered as
    a controller does), a data package per cycle (timestamp = cycle x cycle, the fed-back
    pose as actual_TCP_pose, a running program), each input package decoded."""

    fields: dict = {}

    def __init__(self, config):
        from humanpt.sim_robot.config import SimRobotConfig
        from humanpt.sim_robot.ur import UrRobot

        self.sim = UrRobot(SimRobotConfig(), register_base=config.register_base)
        self.sim.rate_hz = 1000.0 / config.cycle_period_ms  # (the rig's cycle, whatever it is)
        self.session = self.sim.connect()
        self.cycle_s = config.cycle_period_ms / 1000.0
        self.cycle = 0

    def begin(self, t_ns: int) -> list[bytes]:
        return [b""]  # the adapter's mark of a new connection

    def send(self, cycle: int, base_T_flange_mm: np.ndarray, bits, t_ns: int) -> list[bytes]:
        from humanpt.robot_gateway.links.ur.protocol import ur_pose_from_transform

        self.cycle = cycle
        s = self.session
        if not s.started:
            return []
        values = self.sim.outputs()
        values.update(timestamp=cycle * self.cycle_s, actual_TCP_pose=ur_pose_from_transform(base_T_flange_mm))
        values[f"output_int_register_{self.sim.b}"] = cycle  # the program's heartbeat
        return [s.outputs.encode({n: values[n] for n in s.outputs.names})]

    def take(self, data: bytes, t_ns: int) -> tuple[list[bytes], list]:
        before = self.sim.counters["input_packages"]
        back = self.session.feed(data, t_ns)
        got = []
        if self.sim.counters["input_packages"] > before:
            got.append((self.cycle, dict(self.sim.inputs)))
        return ([back] if back else []), got


# link name -> its robot side (a test of a new link adds its own).
ROBOTS: dict[str, type] = {"alter": AlterRobot, "rsi": RsiRobot, "abb": AbbRobot, "ur": UrRigRobot}


class Rig:
    """Drive a GatewayCore over any link with scripted robot cycles, commands, ticks and
    liveliness. ``Rig(config)`` or ``Rig(link="rsi", **fields)`` (default ALTER).

    ``robot``: the link's robot side (``ROBOTS``); ``corrections``: (cycle, correction) the
    robot received; ``outs``: every gateway output. Bytes cross instantly; with
    ``robot_connected`` False they are lost both ways."""

    def __init__(self, config=None, **kw):
        if config is None:
            link = kw.setdefault("link", "alter")
            config = gateway_config(**{**ROBOTS[link].fields, **kw})
        self.gw = GatewayCore(config)
        self.robot = ROBOTS[config.link](config)
        self.rx_topic, self.tx_topic = self.gw.rx_topic, self.gw.link.tx_topic
        self.cycle_ns = config.cycle_period_ns
        self.t_ns = 0
        self.cycle = 0
        self.base_T_flange = transform_from_x(START_X)
        self.bits = ACTIVE
        self.outs: list = []
        self.corrections: list = []
        self.robot_connected = True
        self.seq = 0  # the controller session's header.seq: +1 per command
        self._to_gw: list[bytes] = list(self.robot.begin(0))
        self.step("tick", pb.Tick(header=header(0)))

    # -- plumbing ---------------------------------------------------------------------
    def step(self, topic: str, msg) -> list:
        outs = self.gw.step(self.t_ns, topic, msg)
        self.outs += outs
        for t, m in outs:
            if t == self.tx_topic and self.robot_connected:
                back, got = self.robot.take(m.data, self.t_ns)
                self._to_gw += back
                self.corrections += got
        while self._to_gw:
            outs += self.from_robot(self._to_gw.pop(0))
        return outs

    def from_robot(self, data: bytes) -> list:
        """Bytes from the robot (any: a malformed datagram, a forged frame) reach the gateway now."""
        return self.step(self.rx_topic, pb.SerialChunk(header=header(self.t_ns), data=data))

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
        """The robot sends its state for its next cycle (now); ``bits``: ALTER's status bits."""
        self.cycle = self.cycle + 1 if cycle is None else cycle
        sent = self.robot.send(self.cycle, self.base_T_flange, self.bits if bits is None else bits, self.t_ns)
        outs = []
        if self.robot_connected:
            for data in sent:
                outs += self.from_robot(data)
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
        return last.header.stamp_ns + (cycle - last.cycle) * self.cycle_ns

    def liveliness(self, alive: bool) -> list:
        return self.step(
            "liveliness",
            pb.Liveliness(header=header(self.t_ns), component="controller", alive=alive),
        )

    def cycle_with_command(self, dp_mm=(0, 0, 0), rv_deg=(0, 0, 0), **kw) -> list:
        """The robot's state, then the command for it at once, then the rest of the cycle."""
        outs = self.status()
        outs += self.command(dp_mm=dp_mm, rv_deg=rv_deg, **kw)
        outs += self.advance(self.cycle_ns)
        return outs

    # -- reading -------------------------------------------------------------------------
    def events(self, outs=None) -> list[pb.Event]:
        return [m for t, m in (self.outs if outs is None else outs) if t == "robot_gateway/events"]

    def codes(self, outs=None) -> list[str]:
        return [e.code for e in self.events(outs)]

    def states(self) -> list[pb.RobotState]:
        return [m for t, m in self.outs if t == "robot_gateway/robot_state"]

    def last_correction(self):
        return self.corrections[-1][1]

