"""A simulated KUKA RSI-style controller: sim_robot's arm behind an RSI link (UDP/XML).

:class:`RsiRobot` is the controller (pure: times are given). Every RSI cycle (4 or 12 ms,
the link's cycle, ``cycle_period_ns``) :meth:`RsiRobot.cycle`:

0. until the client's first datagram arrives, sends ``<Rob>`` without judging (``waiting``
   cycles: RSI_ON comes once the sensor side is up, so a gateway that takes a while to
   start is not ``rsi_late_limit`` late replies before the run begins); then
   ``client_answered`` and every cycle is judged;
1. judges the answer to the previous ``<Rob>``: an in-time ``<Sen>`` echoing its IPOC is
   applied (a relative correction, RKorr, through the same kinematics as the ALTER sim:
   :func:`humanpt.sim_robot.core.corrected_joints`; ``alter_mode`` world = base frame,
   tool = flange frame). None in time (late, lost, a wrong IPOC, malformed XML) is a
   *late reply*: the ``<Delay>`` counter grows, HOLDON (``rsi_holdon``) repeats the last
   correction or applies zero, and ``rsi_late_limit`` late replies in a row stop RSI
   (``rsi_stopped``: no more datagrams, the arm stays);
2. sends the next ``<Rob>``: IPOC + cycle time, RIst (the flange in the base frame from
   the nominal forward kinematics), AIPos (joints), Delay.

An RKorr beyond ``rsi_max_correction_mm`` / ``rsi_max_correction_deg`` (the robot's own
RSI limits) or one the arm cannot follow (unreachable, joint speed) stops RSI as well.
Every such thing is an event (:attr:`RsiRobot.events`). :class:`RsiRobotServer` runs it
over a real UDP socket on a thread of its own with a monotonic deadline per cycle.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from humanpt.geometry.arm import UnreachableError
from humanpt.geometry.transforms import x_from_transform
from humanpt.robot_gateway.links.rsi.config import parse_address
from humanpt.robot_gateway.links.rsi.protocol import (
    RobState,
    RsiCorrection,
    RsiProtocolError,
    decode_sen,
    encode_rob,
)
from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import pose
from humanpt.sim_robot.arm import ArmViews, JointStepError, SimArm
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import TRUTH

FIRST_IPOC = 1_000_000  # the IPOC of the first <Rob> (ms)
# Reply latency histogram (send of <Rob> -> valid <Sen>) bucket upper edges, ms; the last
# bucket is "late" (after the cycle boundary, or never).
LATENCY_EDGES_MS = (0.25, 0.5, 1.0, 2.0, 4.0, 12.0)


def latency_histogram(latencies_ns, late: int) -> dict[str, int]:
    """Replies per latency bucket (``<=E ms`` for each of LATENCY_EDGES_MS; a reply beyond
    the last edge is counted in none) and ``late``: the benches of both links share it."""
    edges_ns = [e * 1e6 for e in LATENCY_EDGES_MS]
    hist = {f"<={e:g} ms": 0 for e in LATENCY_EDGES_MS}
    for lat in latencies_ns:
        for e, key in zip(edges_ns, hist, strict=True):
            if lat <= e:
                hist[key] += 1
                break
    hist["late"] = late
    return hist


@dataclass(frozen=True, slots=True)
class SimEvent:
    t_ns: int
    severity: str  # "info", "warning", "error"
    code: str
    text: str


class RsiRobot(ArmViews):
    """The simulated RSI controller (pure). ``events``, ``counters``, ``applied``
    (IPOC, RsiCorrection) and ``latency_ns`` (per answered cycle) are for tests and benches."""

    def __init__(self, config: SimRobotConfig):
        self.config = config
        self.cycle_ms = int(config.cycle_ms)
        self.arm = SimArm(config)  # the arm (the set-up every simulated controller shares)
        self.ipoc: int | None = None  # IPOC of the last <Rob> sent
        self._sent_ns = 0
        self._answer: RsiCorrection | None = None  # the in-time answer to self.ipoc
        self._last: RsiCorrection | None = None  # the last applied (HOLDON)
        self.delay = 0  # late replies so far (<Delay D>)
        self.late_run = 0  # late replies in a row
        self.client_seen = False  # a datagram came from the client: cycles are judged from then on
        self.judging = False
        self.stopped: str | None = None
        self.events: list[SimEvent] = []
        self.counters = dict.fromkeys(
            ("cycles", "waiting", "on_time", "late", "late_arrivals", "wrong_ipoc", "malformed", "overwritten",
             "after_stop", "applied"), 0)
        self.applied: deque[tuple[int, RsiCorrection]] = deque(maxlen=100_000)
        self.latency_ns: deque[int] = deque(maxlen=1_000_000)

    # -- events -------------------------------------------------------------------------------
    def _event(self, t_ns: int, severity: str, code: str, text: str) -> None:
        self.events.append(SimEvent(t_ns, severity, code, text))

    # -- the cycle ----------------------------------------------------------------------------
    def cycle(self, t_ns: int) -> bytes | None:
        """A cycle boundary at ``t_ns``: judge and apply the answer to the last <Rob>, then
        the next <Rob> (None once RSI stopped)."""
        if self.stopped is not None:
            return None
        if self.ipoc is not None:
            self._judge(t_ns)
            if self.stopped is not None:
                return None
        self.ipoc = FIRST_IPOC if self.ipoc is None else self.ipoc + self.cycle_ms
        self._sent_ns = t_ns
        self.counters["cycles"] += 1
        rist = tuple(float(v) for v in x_from_transform(self.base_T_flange_mm))
        aipos = tuple(math.degrees(v) for v in self.q_rad.tolist())
        return encode_rob(RobState(self.ipoc, rist, aipos, self.delay))

    def finish(self, t_ns: int) -> None:
        """The end of the run at ``t_ns``: judge the answer to the last <Rob>."""
        if self.ipoc is not None and self.stopped is None:
            self._judge(t_ns)

    def _judge(self, t_ns: int) -> None:
        if not self.judging:
            if not self.client_seen:
                self.counters["waiting"] += 1  # before the client's first word: not judged
                return
            self.judging = True
            self._event(t_ns, "info", "client_answered",
                        f"the client answers (IPOC {self.ipoc}, after {self.counters['waiting']} cycles waiting); "
                        "every cycle is judged from now on")
        answer, self._answer = self._answer, None
        if answer is not None:
            self.counters["on_time"] += 1
            if self.late_run:
                self._event(t_ns, "info", "reply_in_time",
                            f"answers in time again from IPOC {self.ipoc} after {self.late_run} late")
            self.late_run = 0
            self._apply(answer, t_ns)
            return
        self.counters["late"] += 1
        self.delay += 1
        self.late_run += 1
        limit = self.config.rsi_late_limit
        hold = "repeating the last correction (HOLDON=1)" if self.config.rsi_holdon else "zero correction (HOLDON=0)"
        if self.late_run == 1:
            self._event(t_ns, "warning", "late_reply",
                        f"no answer to IPOC {self.ipoc} within the {self.cycle_ms} ms cycle: {hold}; "
                        f"late {self.late_run} in a row (RSI stops at {limit})")
        if self.late_run >= limit:
            self._stop(t_ns, "rsi_stopped", f"RSI stopped: {self.late_run} late answers in a row "
                       f"(limit {limit}, at IPOC {self.ipoc}); the robot holds, restart RSI at the robot")
            return
        if self.config.rsi_holdon and self._last is not None and any(self._last.rkorr):
            self._apply(self._last, t_ns, repeat=True)

    def _apply(self, c: RsiCorrection, t_ns: int, repeat: bool = False) -> None:
        if not repeat:
            self._last = c
        if not any(c.rkorr):
            return
        try:
            self.arm.step(c.delta_T_mm(), self.config.alter_mode)
        except (UnreachableError, JointStepError) as e:
            self._stop(t_ns, "fault", f"RSI stopped: correction for IPOC {c.ipoc} {e}")
            return
        self.counters["applied"] += 1
        self.applied.append((self.ipoc, c))

    def _stop(self, t_ns: int, code: str, text: str) -> None:
        self.stopped = text
        self._event(t_ns, "error", code, text)

    # -- answers --------------------------------------------------------------------------------
    def receive(self, data: bytes, t_ns: int, arrived_ns: int | None = None) -> None:
        """A datagram from the client, handled at ``t_ns``; ``arrived_ns`` is when it reached
        the robot's socket (default ``t_ns``). An answer is in time if it arrived within one
        cycle of its <Rob>'s sending, as a controller on a hard real-time clock judges it: a
        simulated controller that handles it later (a busy process) does not make it late."""
        arrived_ns = t_ns if arrived_ns is None else arrived_ns
        self.client_seen = True  # whatever it says: the client is up
        if self.stopped is not None:
            self.counters["after_stop"] += 1
            return
        try:
            c = decode_sen(data)
        except RsiProtocolError as e:
            self.counters["malformed"] += 1
            self._event(t_ns, "warning", "bad_reply", f"answer dropped: {e}")
            return
        if c.ipoc != self.ipoc:
            if self.ipoc is not None and c.ipoc < self.ipoc and (self.ipoc - c.ipoc) % self.cycle_ms == 0:
                self.counters["late_arrivals"] += 1  # an answer to an earlier cycle: late
                return
            self.counters["wrong_ipoc"] += 1
            self._event(t_ns, "warning", "wrong_ipoc",
                        f"answer with IPOC {c.ipoc} while the cycle is IPOC {self.ipoc}: ignored")
            return
        mm = float(np.linalg.norm(c.translation_mm))
        deg = c.angle_deg()
        cfg = self.config
        if mm > cfg.rsi_max_correction_mm or deg > cfg.rsi_max_correction_deg:
            self._stop(t_ns, "correction_limit",
                       f"RSI stopped: RKorr of {mm:.3f} mm / {deg:.3f} deg for IPOC {c.ipoc} exceeds the "
                       f"robot's limits ({cfg.rsi_max_correction_mm:g} mm, {cfg.rsi_max_correction_deg:g} deg "
                       "per cycle)")
            return
        if arrived_ns - self._sent_ns > self.cycle_ms * 1_000_000:
            self.counters["late_arrivals"] += 1  # after its cycle's end: late, whenever handled
            return
        if self._answer is not None:
            self.counters["overwritten"] += 1
        else:
            self.latency_ns.append(arrived_ns - self._sent_ns)
        self._answer = c

    def latency_histogram(self) -> dict[str, int]:
        """Answers per latency bucket (ms upper edges) and the late ones."""
        return latency_histogram(self.latency_ns, self.counters["late"])


class RsiRobotServer:
    """:class:`RsiRobot` over a real UDP socket, its cycle on a thread of its own (a
    monotonic deadline per cycle; answers are read until the next deadline).

    ``lose(n)``: a hook for tests, True to drop the n-th <Rob> (1-based) on the floor, as
    a lost datagram. ``after_send(n, rob)``: a hook for tests and benches, called on the
    robot's thread right after the n-th <Rob> (``rob``, its bytes) went out: the datagrams
    it returns are sent to the gateway from the robot's own socket (a network that
    duplicates, replays or reorders, or a spoofer with the robot's address); it may also act
    on its own (an attacker on another port that knows the next IPOC). Stops after
    ``cycles`` cycles (None: until :meth:`stop`) or when RSI stops."""

    def __init__(self, robot: RsiRobot, *, gateway: str | None = None, bind: str = "127.0.0.1:0",
                 cycles: int | None = None, lose: Callable[[int], bool] | None = None,
                 after_send: Callable[[int, bytes], list[bytes]] | None = None):
        self.robot = robot
        self.gateway = parse_address(gateway or robot.config.rsi_gateway)
        self.cycles = cycles
        self.lose = lose
        self.after_send = after_send
        host, port = parse_address(bind)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.overruns = 0  # cycles that started later than their deadline + 1 ms

    def start(self) -> RsiRobotServer:
        self._thread = threading.Thread(target=self._run, name="sim-rsi", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        robot, sock = self.robot, self.sock
        period = robot.cycle_ms * 1_000_000
        deadline = time.monotonic_ns()
        n = 0
        try:
            while not self._stop.is_set() and (self.cycles is None or n < self.cycles):
                now = time.monotonic_ns()
                if now - deadline > 1_000_000:
                    self.overruns += 1
                data = robot.cycle(now)
                if data is None:
                    return  # RSI stopped
                n += 1
                if self.lose is None or not self.lose(n):
                    sock.sendto(data, self.gateway)
                if self.after_send is not None:
                    for extra in self.after_send(n, data):
                        sock.sendto(extra, self.gateway)
                deadline += period
                while (remaining := deadline - time.monotonic_ns()) > 0:
                    sock.settimeout(remaining / 1e9)
                    try:
                        reply, _ = sock.recvfrom(65536)
                    except TimeoutError:
                        break
                    robot.receive(reply, time.monotonic_ns())
            robot.finish(time.monotonic_ns())
        finally:
            self.sock.close()

    def stop(self) -> None:
        self._stop.set()

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)


# -- as the sim_robot component (``[sim_robot] protocol = "rsi"``) ----------------------------
_SEVERITY = {"info": pb.SEVERITY_INFO, "warning": pb.SEVERITY_WARNING, "error": pb.SEVERITY_ERROR}


class RsiSimRobotCore(Core):
    """sim_robot over RSI (pure): :class:`RsiRobot` on the component's ``tick`` (every
    cycle of the link, 4 or 12 ms). Inputs ``tick``, ``udp_rx`` (the gateway's ``<Sen>``,
    humanpt.SerialChunk); outputs ``udp_tx`` (the ``<Rob>`` of each cycle; the live shell's
    UDP adapter sends it to ``rsi_gateway``), ``sim_robot/truth`` (world_T_flange, m, after
    each cycle, as over ALTER) and ``sim_robot/events`` (RsiRobot's events). Built by
    ``SimRobotCore.create`` for ``protocol = "rsi"``."""

    name = "sim_robot"
    realtime = True  # a robot link's cycle: see runtime.tuning.tune_realtime
    config_type = SimRobotConfig
    ports = (
        Port("tick", pb.Tick, "_on_cycle"),
        Port("udp_rx", pb.SerialChunk, "_on_udp"),
    )
    # Snapshots (runtime/snapshot.py): the corrections applied are kept for benches and tests
    # only; the last correction and the one to answer with are RsiCorrections, its events
    # SimEvents.
    not_frozen = frozenset({"robot.applied"})
    state_types = (RsiCorrection, SimEvent)

    def __init__(self, config: SimRobotConfig):
        super().__init__(config)
        self.robot = self.make_robot(config)
        self._events_sent = 0

    def make_robot(self, config: SimRobotConfig) -> RsiRobot:
        """The simulated controller this core runs (EgmSimRobotCore: the EGM one)."""
        return RsiRobot(config)

    @property
    def counters(self) -> dict[str, int]:
        return self.robot.counters

    def tick_period_ns(self) -> int | None:
        return self.config.cycle_period_ns

    def recording_metadata(self, shell: str, **extra: Any) -> dict[str, Any]:
        # The registry's entry (SimRobotCore) rebuilds this core from the recorded config.
        from humanpt.runtime.registry import class_path
        from humanpt.sim_robot.core import SimRobotCore

        return super().recording_metadata(shell, **extra) | {"core": class_path(SimRobotCore)}

    def _flush_events(self, outs: list[Output]) -> None:
        for e in self.robot.events[self._events_sent:]:
            outs.append(self.event(e.t_ns, _SEVERITY[e.severity], e.code, e.text))
        self._events_sent = len(self.robot.events)

    def _on_udp(self, t_ns: int, msg: pb.SerialChunk) -> list[Output]:
        # The adapter stamps a datagram when it reads it (lock-step: when it arrives).
        self.robot.receive(msg.data, t_ns, msg.header.stamp_ns or t_ns)
        outs: list[Output] = []
        self._flush_events(outs)
        return outs

    def _on_cycle(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        outs: list[Output] = []
        data = self.robot.cycle(t_ns)
        self._flush_events(outs)
        if data is not None:
            outs.append(("udp_tx", pb.SerialChunk(header=self.next_header("udp_tx", t_ns), data=data)))
        outs.append((TRUTH, pb.Truth(header=self.next_header(TRUTH, t_ns, "world"),
                                     world_T_flange=pose(self.robot.arm.true_world_T_flange_m()))))
        return outs
