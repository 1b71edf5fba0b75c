"""sim_robot core (pure): a simulated Puma controller at the far end of the ALTER link.

Its own cycle (``tick`` every cycle of the link, 28 ms as on the Puma over ALTER). At each cycle
boundary, in this order:

1. apply the most recent valid correction received during the cycle (the controller end
   of the codec delivers only in-sequence, fresh, never-repeated corrections): world mode
   ``base_T_flange' = [dR R, p + dp]`` (a step about the flange origin, base frame);
   tool mode ``base_T_flange' = base_T_flange @ [dR, dp]``; then inverse kinematics on the
   branch closest to the current joints. An unreachable pose or a joint step faster than
   ``max_joint_speed_deg_s`` faults the controller, as a real one would: FAULT set, ALTER
   stopped, the arm stays where it is, an event. No correction at all: the arm stays put
   and the next STATUS carries CORRECTION_MISSED;
2. the joints move towards their setpoint (at once, or with the first-order lag of
   ``lag_time_constant_ms``); count the cycle and send STATUS (cycle, status bits,
   base_T_flange from the nominal forward kinematics of the joints, quantised by the
   codec to 0.01 mm and 0.01 deg);
3. publish ``sim_robot/truth``: the true world_T_flange (the world's arm: nominal unless
   ``joint_offsets_deg`` / ``link_length_errors_mm`` are set), exact, stamp = the cycle
   time. It is where the flange is at that instant; between two cycles the flange moves on
   the straight line / geodesic between them (the camera renders from that trajectory).

A HOLD correction does not move; ALTER_OFF leaves ALTER after the cycle. ALTER comes back
(and a FAULT clears) with ``console/command`` {component: sim_robot, verb: alter_on}, as
an operator would restart it at the controller; ``alter_off`` stops it.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from humanpt.geometry.arm import UnreachableError
from humanpt.robot_gateway.links.alter import (
    ControllerConfig,
    ControllerEndpoint,
    ControllerStatus,
    Correction,
    CorrectionFlags,
    CorrectionReceived,
    FrameError,
    LinkConfig,
    LinkDown,
    LinkUp,
    MessageRejected,
    StatusBits,
    Transmit,
)
from humanpt.runtime.core import Core, Output, Port, command_operator
from humanpt.runtime.limiter import EventLimiter, SerialLinkCoreMixin
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import pose
from humanpt.sim_robot.arm import ArmViews, JointStepError, SimArm, corrected_joints, lag_gain
from humanpt.sim_robot.config import SimRobotConfig

__all__ = ["TRUTH", "JointStepError", "SimRobotCore", "corrected_joints"]

TRUTH = "sim_robot/truth"
# Status bits as plain ints (IntFlag arithmetic is slow on this hot path).
_ARM_POWER, _CUMULATIVE, _ALTER_ACTIVE, _TOOL_MODE, _FAULT, _CORRECTION_MISSED = (
    int(b)
    for b in (
        StatusBits.ARM_POWER,
        StatusBits.CUMULATIVE,
        StatusBits.ALTER_ACTIVE,
        StatusBits.TOOL_MODE,
        StatusBits.FAULT,
        StatusBits.CORRECTION_MISSED,
    )
)


class SimRobotCore(ArmViews, SerialLinkCoreMixin, Core):
    name = "sim_robot"
    realtime = True  # a robot link's cycle: see runtime.tuning.tune_realtime
    config_type = SimRobotConfig
    ports = (
        Port("tick", pb.Tick, "_on_cycle"),
        Port("serial_rx", pb.SerialChunk, "_on_serial"),
        Port("console/command", pb.Command, "_on_console"),
    )
    # Snapshots (runtime/snapshot.py): the corrections applied are kept for benches and tests
    # only; a correction waiting for its cycle is a Correction (with its CorrectionFlags).
    not_frozen = frozenset({"applied"})
    state_types = (Correction, CorrectionFlags)

    @classmethod
    def create(cls, config: SimRobotConfig, rig=None) -> Core:
        """The simulated controller of ``config.protocol``: this core over ALTER,
        ``humanpt.sim_robot.rsi.RsiSimRobotCore`` over RSI, ``humanpt.sim_robot.egm.EgmSimRobotCore``
        over EGM, ``humanpt.sim_robot.ur.UrSimRobotCore`` over RTDE."""
        if cls is SimRobotCore and config.protocol == "rsi":
            from humanpt.sim_robot.rsi import RsiSimRobotCore  # (rsi imports this module)

            return RsiSimRobotCore.create(config, rig)
        if cls is SimRobotCore and config.protocol == "rtde":
            from humanpt.sim_robot.ur import UrSimRobotCore  # (ur imports this module)

            return UrSimRobotCore.create(config, rig)
        if cls is SimRobotCore and config.protocol == "egm":
            from humanpt.sim_robot.egm import EgmSimRobotCore  # (egm imports this module)

            return EgmSimRobotCore.create(config, rig)
        return super().create(config, rig)

    def __init__(self, config: SimRobotConfig):
        if config.protocol != "alter":
            raise ValueError(f"sim_robot: protocol {config.protocol!r} is not this core's (ALTER); "
                             "SimRobotCore.create builds the RSI one (humanpt.sim_robot.rsi.RsiSimRobotCore)")
        super().__init__(config)
        self.arm = SimArm(config)  # the arm, its joints (encoders) and where it is mounted
        self.q_setpoint_rad = self.arm.q_rad.copy()  # where the corrections put them
        # First-order lag: per cycle the joints cover this fraction of the way to the setpoint.
        self.lag_gain = lag_gain(config.cycle_ms, config.lag_time_constant_ms)
        cycle_ns = config.cycle_period_ns
        self._ctrl = ControllerEndpoint(
            ControllerConfig(
                link=LinkConfig(rep_timeout_ns=3 * cycle_ns),
                max_correction_age_cycles=config.max_correction_age_cycles,
            )
        )
        self._limiter = EventLimiter(round(config.event_interval_ms * 1e6))
        self._started = False
        self.cycle = 0  # the last cycle number issued (the first STATUS is cycle 1)
        self.alter_active = config.alter_on_start
        self.fault: str | None = None
        self._pending: tuple[Correction, int] | None = None  # (correction, age at delivery)
        self._sent_status = False  # a STATUS went out since the link came up
        self._missed = False  # CORRECTION_MISSED for the next STATUS
        self._tx = bytearray()
        self.counters: dict[str, int] = dict.fromkeys(
            (
                "cycles",
                "applied",
                "applied_on_time",
                "applied_late",
                "missed",
                "overwritten",
                "rejected",
                "ignored",
                "link_down",
                "faults",
            ),
            0,
        )
        # (cycle the correction was applied at, the correction) for tests and benches.
        self.applied: deque[tuple[int, Correction]] = deque(maxlen=100_000)

    def tick_period_ns(self) -> int | None:
        return self.config.cycle_period_ns

    # -- state: the arm's (humanpt.sim_robot.arm.SimArm), through ArmViews ---------------------
    def _base_T_flange(self) -> np.ndarray:
        """Forward kinematics of q, once per joint position. Shared: do not modify."""
        return self.arm.forward()

    @property
    def link_running(self) -> bool:
        return self._ctrl.link.is_running

    def status_bits(self) -> StatusBits:
        bits = _ARM_POWER | _CUMULATIVE
        if self.alter_active:
            bits |= _ALTER_ACTIVE
        if self.config.alter_mode == "tool":
            bits |= _TOOL_MODE
        if self.fault is not None:
            bits |= _FAULT
        if self._missed:
            bits |= _CORRECTION_MISSED
        return StatusBits(bits)

    # -- inputs (SerialLinkCoreMixin._bind: each sends what it wrote as one serial_tx) -------
    def _on_serial(self, t_ns: int, msg: pb.SerialChunk, outs: list[Output]) -> None:
        if self._started:
            self._link(self._ctrl.receive(bytes(msg.data), t_ns), t_ns, outs)

    def _link(self, events, t_ns: int, outs: list[Output]) -> None:
        for e in events:
            if isinstance(e, Transmit):
                self._tx += e.data
            elif isinstance(e, CorrectionReceived):
                if self._pending is not None:
                    self.counters["overwritten"] += 1  # two in one cycle: the most recent wins
                self._pending = (e.correction, e.age_cycles)
            elif isinstance(e, LinkUp):
                self._sent_status = False
                self._ev(outs, t_ns, pb.SEVERITY_INFO, "link_up", "ALTER link up", limited=False)
            elif isinstance(e, LinkDown):
                self.counters["link_down"] += 1
                self._pending = None
                self._ev(
                    outs,
                    t_ns,
                    pb.SEVERITY_ERROR,
                    "link_down",
                    f"ALTER link down: {e.reason}; holding position",
                    limited=False,
                )
            elif isinstance(e, FrameError | MessageRejected):
                self.counters["rejected"] += 1
                self._ev(outs, t_ns, pb.SEVERITY_WARNING, "link_error", f"ALTER link: {e}")

    def _on_console(self, t_ns: int, msg: pb.Command, outs: list[Output]) -> None:
        if msg.component != self.name:
            return
        who = command_operator(msg)
        if msg.verb in ("alter_on", "alter_off") and not who:
            self._ev(outs, t_ns, pb.SEVERITY_WARNING, "bad_console_command",
                     f"{msg.verb} refused: it needs the operator's name (humanpt console alter on|off)",
                     limited=False)
        elif msg.verb == "alter_on":
            was = self.fault
            self.fault = None
            self.alter_active = True
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_INFO,
                "alter_on",
                f"ALTER on by {who}" + (f" (fault cleared: {was})" if was else ""),
                limited=False,
            )
        elif msg.verb == "alter_off":
            self.alter_active = False
            self._ev(
                outs, t_ns, pb.SEVERITY_INFO, "alter_off", f"ALTER off by {who} (console)", limited=False
            )
        else:
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_WARNING,
                "bad_console_command",
                f"unknown verb {msg.verb!r} (known: alter_on, alter_off)",
            )

    # -- the cycle --------------------------------------------------------------------------
    def _on_cycle(self, t_ns: int, msg: pb.Tick, outs: list[Output]) -> None:
        if not self._started:
            self._started = True
            self._link(self._ctrl.start(t_ns), t_ns, outs)
        else:
            self._link(self._ctrl.poll(t_ns), t_ns, outs)
        self._apply_pending(t_ns, outs)
        if self.lag_gain == 1.0:
            self.q_rad = self.q_setpoint_rad
        else:
            self.q_rad = self.q_rad + self.lag_gain * (self.q_setpoint_rad - self.q_rad)
        self.cycle = (self.cycle + 1) & 0xFFFFFFFF
        self.counters["cycles"] += 1
        status = ControllerStatus.from_pose(self.cycle, self.status_bits(), self._base_T_flange())
        events = self._ctrl.send_status(status, t_ns)  # counts as issued even if the link is down
        self._link(events, t_ns, outs)
        if self.link_running:
            self._sent_status = True
        outs.append((TRUTH, pb.Truth(header=self.next_header(TRUTH, t_ns, "world"),
                                     world_T_flange=pose(self.arm.true_world_T_flange_m()))))

    def _apply_pending(self, t_ns: int, outs: list[Output]) -> None:
        pending, self._pending = self._pending, None
        self._missed = False
        if pending is None:
            if self.alter_active and self.fault is None and self.link_running and self._sent_status:
                self._missed = True
                self.counters["missed"] += 1
                self._ev(
                    outs,
                    t_ns,
                    pb.SEVERITY_WARNING,
                    "correction_missed",
                    f"no correction in time for cycle {self.cycle}: holding position",
                )
            return
        c, age = pending
        if not self.alter_active or self.fault is not None:
            if any(c.deltas):
                self.counters["ignored"] += 1
                self._ev(
                    outs,
                    t_ns,
                    pb.SEVERITY_WARNING,
                    "correction_ignored",
                    f"correction for cycle {c.echo_cycle} ignored: ALTER is "
                    + ("faulted" if self.fault else "off"),
                )
            return
        if CorrectionFlags.HOLD not in c.flags:
            self._move(c, t_ns, outs)
        self.counters["applied"] += 1
        self.counters["applied_on_time" if age == 0 else "applied_late"] += 1
        if CorrectionFlags.ALTER_OFF in c.flags:
            self.alter_active = False
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_WARNING,
                "alter_off",
                f"ALTER off at the host's request (correction for cycle {c.echo_cycle})",
                limited=False,
            )

    def _move(self, c: Correction, t_ns: int, outs: list[Output]) -> None:
        # The correction moves the setpoint (ALTER accumulates onto the commanded path),
        # in the controller's nominal kinematics.
        T = self._base_T_flange() if self.lag_gain == 1.0 else self.kin.forward(self.q_setpoint_rad)
        try:
            q = self.arm.corrected(T, c.delta_T_mm(), self.config.alter_mode, self.q_setpoint_rad)
        except (UnreachableError, JointStepError) as e:
            self._fault(t_ns, f"correction for cycle {c.echo_cycle} {e}", outs)
            return
        self.q_setpoint_rad = q
        self.applied.append((self.cycle, c))

    def _fault(self, t_ns: int, reason: str, outs: list[Output]) -> None:
        self.fault = reason
        self.alter_active = False
        self.counters["faults"] += 1
        self._ev(
            outs,
            t_ns,
            pb.SEVERITY_ERROR,
            "fault",
            f"controller FAULT: {reason}; ALTER stopped",
            limited=False,
        )
