"""A simulated ABB controller running EGM position guidance: sim_robot's arm behind an EGM
link (UDP protobuf), for the twin and the tests.

:class:`EgmRobot` is the controller (pure: times are given). Every EGM cycle (4 ms, or a
multiple) :meth:`EgmRobot.cycle`:

1. moves the arm toward the last target a sensor sent (``EgmSensor.planned.cartesian``):
   EGM's position controller as a first-order response of time constant
   ``time_constant_s`` (the fraction 1 - exp(-cycle / tau) of the way each cycle), through
   the same kinematics and joint-speed limit as the other simulated links
   (:func:`humanpt.sim_robot.core.corrected_joints`); before any target it stays;
2. stops EGM when no ``EgmSensor`` came for ``comm_timeout_s`` (the RAPID program's
   EGMRunPose ``\\CommTimeout``; counted from the start too: the sensor must answer);
   the arm then stays where it is, no more messages;
3. sends the next ``EgmRobot``: seqno + 1, tm (ms), the flange in the base frame from the
   nominal forward kinematics, motors on, MCI running, RAPID running.

Humanpt's assumption (no controller here to check it): the convergence is first order and
the timeout stops the motion at once; a real controller also filters the target
(``\\LpFilter``) and ramps down (``\\RampOutTime``). Unlike RSI, EGM gives the sensor no
count of late answers: a late answer is just an older target. The simulated controller
counts them all the same (``counters``: ``on_time``, ``late``; ``latency_ns``), for the
benches: a cycle is answered in time when an ``EgmSensor`` arrived before its end.

:class:`EgmSimRobotCore` is the sim_robot component over EGM (``[sim_robot] protocol =
"egm"``), as :class:`humanpt.sim_robot.rsi.RsiSimRobotCore` is over RSI.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from humanpt.geometry.arm import UnreachableError
from humanpt.robot_gateway.links.abb.protocol import (
    EgmProtocolError,
    EgmState,
    decode_sensor,
    encode_robot,
    pos_quat,
)
from humanpt.sim_robot.arm import ArmViews, JointStepError, SimArm, lag_gain
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import RsiSimRobotCore, SimEvent, latency_histogram


class EgmRobot(ArmViews):
    """The simulated EGM controller (pure). ``events``, ``counters`` and ``targets`` (the
    targets taken) are for tests and benches."""

    def __init__(self, config: SimRobotConfig, *, cycle_ms: float = 4.0, comm_timeout_s: float = 1.0,
                 time_constant_s: float = 0.02, wait_for_sensor: bool = False):
        """``wait_for_sensor``: the communication timeout runs from the sensor's first
        answer, not from the start (the RAPID program started once humanpt is up)."""
        if not (cycle_ms >= 4.0 and abs(cycle_ms / 4.0 - round(cycle_ms / 4.0)) < 1e-9):
            raise ValueError(f"EGM's cycle is a multiple of 4 ms, got {cycle_ms}")
        if not (comm_timeout_s > 0 and time_constant_s > 0):
            raise ValueError("comm_timeout_s and time_constant_s must be > 0")
        self.config = config
        self.cycle_ms = cycle_ms
        self.comm_timeout_ns = round(comm_timeout_s * 1e9)
        self.alpha = lag_gain(cycle_ms, time_constant_s * 1000.0)
        self.arm = SimArm(config, cycle_ms)  # the arm (the set-up every simulated controller shares)
        self.wait_for_sensor = wait_for_sensor
        self.seqno = 0
        self.target: np.ndarray | None = None
        self.stopped: str | None = None
        self._started_ns: int | None = None
        self._last_answer_ns: int | None = None
        self.events: list[SimEvent] = []
        self.targets: deque[np.ndarray] = deque(maxlen=100_000)
        self.counters = dict.fromkeys(("cycles", "answers", "malformed", "after_stop", "moved", "waiting",
                                       "on_time", "late"), 0)
        self.latency_ns: deque[int] = deque(maxlen=1_000_000)
        self._sent_ns: int | None = None  # when the last EgmRobot went out
        self._answered = False  # an EgmSensor arrived within the cycle of the last EgmRobot

    @classmethod
    def from_config(cls, config: SimRobotConfig) -> EgmRobot:
        """The controller as ``[sim_robot]`` sets it up: the link's cycle, ``egm_comm_timeout_s``,
        ``egm_time_constant_ms``; the timeout from the sensor's first answer."""
        return cls(config, cycle_ms=config.cycle_ms, comm_timeout_s=config.egm_comm_timeout_s,
                   time_constant_s=config.egm_time_constant_ms / 1000.0, wait_for_sensor=True)

    def _stop(self, t_ns: int, code: str, text: str) -> None:
        self.stopped = text
        self.events.append(SimEvent(t_ns, "error", code, text))

    def cycle(self, t_ns: int) -> bytes | None:
        """A cycle boundary at ``t_ns``: move toward the target, then the next EgmRobot (None
        once EGM stopped)."""
        if self.stopped is not None:
            return None
        if self._started_ns is None:
            self._started_ns = t_ns
        self._judge()
        heard = self._last_answer_ns if self._last_answer_ns is not None else self._started_ns
        waiting = self.wait_for_sensor and self._last_answer_ns is None
        if not waiting and t_ns - heard > self.comm_timeout_ns:
            self._stop(t_ns, "egm_stopped", f"EGM stopped: no EgmSensor for {(t_ns - heard) / 1e9:.3f} s (the "
                       f"communication timeout {self.comm_timeout_ns / 1e9:g} s); the robot holds")
            return None
        if self.target is not None:
            self._move(t_ns)
            if self.stopped is not None:
                return None
        self.seqno += 1
        self.counters["cycles"] += 1
        self._sent_ns = t_ns
        pos, quat = pos_quat(self.base_T_flange_mm)
        return encode_robot(EgmState(self.seqno, (t_ns // 1_000_000) % (1 << 32), pos, quat))

    def _judge(self) -> None:
        """Count the cycle of the last EgmRobot: answered in time or late (before the
        sensor's first answer: waiting, not judged)."""
        if self._sent_ns is None:
            return
        if self._answered:
            self.counters["on_time"] += 1
        elif self._last_answer_ns is None:
            self.counters["waiting"] += 1
        else:
            self.counters["late"] += 1
        self._answered = False

    def _move(self, t_ns: int) -> None:
        try:
            moved = self.arm.servo(self.target, self.alpha)
        except (UnreachableError, JointStepError) as e:
            self._stop(t_ns, "fault", f"EGM stopped: the target {e}")
            return
        if moved:
            self.counters["moved"] += 1

    def receive(self, data: bytes, t_ns: int, arrived_ns: int | None = None) -> None:
        """An EgmSensor from the sensor, handled at ``t_ns``, arrived at ``arrived_ns``
        (default ``t_ns``): its target is taken (whenever it comes: EGM goes to the latest
        target it has); it answers the cycle in time if it arrived within the cycle of the
        last EgmRobot."""
        arrived_ns = t_ns if arrived_ns is None else arrived_ns
        if self.stopped is not None:
            self.counters["after_stop"] += 1
            return
        try:
            t = decode_sensor(data)
        except EgmProtocolError as e:
            self.counters["malformed"] += 1
            self.events.append(SimEvent(t_ns, "warning", "bad_sensor_message", f"dropped: {e}"))
            return
        self.target = t.base_T_target_mm()
        self.targets.append(self.target)
        self.counters["answers"] += 1
        self._last_answer_ns = t_ns
        if (self._sent_ns is not None and not self._answered
                and arrived_ns - self._sent_ns <= round(self.cycle_ms * 1e6)):
            self._answered = True
            self.latency_ns.append(arrived_ns - self._sent_ns)

    def finish(self, t_ns: int) -> None:
        """The end of the run at ``t_ns``: count the last cycle (EGM itself judges nothing)."""
        if self.stopped is None:
            self._judge()
            self._sent_ns = None

    def latency_histogram(self) -> dict[str, int]:
        """Answers per latency bucket (ms upper edges) and the late cycles, as over RSI."""
        return latency_histogram(self.latency_ns, self.counters["late"])


class EgmSimRobotCore(RsiSimRobotCore):
    """sim_robot over EGM (pure): :class:`EgmRobot` (:meth:`EgmRobot.from_config`) on the
    component's ``tick`` (every cycle of the link). The same ports, outputs and events as
    over RSI (:class:`humanpt.sim_robot.rsi.RsiSimRobotCore`): ``udp_rx`` (the gateway's
    EgmSensor), ``udp_tx`` (the EgmRobot of each cycle; the live shell's UDP adapter sends it
    to ``egm_gateway``), ``sim_robot/truth``, ``sim_robot/events``. Built by
    ``SimRobotCore.create`` for ``protocol = "egm"``."""

    # Snapshots: the targets taken are kept for benches and tests only.
    not_frozen = frozenset({"robot.targets"})
    state_types = (SimEvent,)

    def make_robot(self, config: SimRobotConfig) -> EgmRobot:
        return EgmRobot.from_config(config)
