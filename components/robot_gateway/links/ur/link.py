"""The gateway's Link over UR RTDE (pure: bytes and times are given).

The gateway is RTDE's client on a TCP stream (``serial_rx``/``serial_tx``: a byte stream as
ALTER's serial line). An EMPTY chunk on ``serial_rx`` is the adapter's mark of a new
connection (TCP never delivers an empty read as data): the stream starts afresh and the link
sets up a session: protocol version 2 ('V'), the controller's version ('v'), the outputs
('O': timestamp, actual_TCP_pose, robot_mode, safety_mode, runtime_state, and the program's
heartbeat and last taken sequence, ``output_int_register_<b>``, ``<b+1>``) at the cycle's
frequency, the inputs ('I': ``input_int_register_<b>`` the sequence, ``input_double_register_
<b>..<b+5>`` the target pose) and start ('S'), one request after the other's answer. A
refused step (a variable NOT_FOUND, a register IN_USE by another client, a refused version
or start) is a ``LinkError`` and the link stays down (the gateway's silence watchdog starts it
again). ``start`` (the gateway's restart) pauses ('P') and sets up afresh on the same stream.

Cycles: the controller's ``timestamp`` (s since it started) / the cycle (mod 2^32). A cycle
that is not ahead of the last (or more than ``MAX_GAP_CYCLES`` ahead) is dropped with a
``LinkError``: TCP neither loses nor reorders, so it is not the controller's stream.

State: ``corrections_on`` while the program runs (``runtime_state`` PLAYING) and its
heartbeat advanced within ``heartbeat_cycles`` cycles; ``arm_power``: ``robot_mode``
RUNNING; ``fault``: a safety mode other than NORMAL or REDUCED (a protective stop...).

Targets: as over ABB EGM (this class reuses :class:`~humanpt.robot_gateway.links.abb.link.
AbbLink`'s target keeping): the program servoes to ABSOLUTE poses; the link keeps the target
(the session's first fed-back pose, then + each step), within ``max_lead_mm`` /
``max_lead_deg`` of the fed-back pose; each answer is a data package with the next sequence
number (1, 2, ... 2^31 - 1, 1 ...: the program's watchdog counts cycles without a new one).
The fed-back pose is ``actual_TCP_pose``: the installation's TCP must be the flange (all 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from humanpt.robot_gateway.link import (
    CycleReceived,
    CycleState,
    LinkDown,
    LinkError,
    LinkUp,
    Transmit,
)
from humanpt.robot_gateway.links.abb.link import AbbLink
from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.robot_gateway.links.ur.config import UrConfig

MAX_GAP_CYCLES = 25
_MOD = 1 << 32
SEQ_MAX = (1 << 31) - 1  # the sequence register is an INT32; it wraps to 1 (0: never sent)


def output_names(register_base: int) -> tuple[str, ...]:
    b = register_base
    return ("timestamp", "actual_TCP_pose", "robot_mode", "safety_mode", "runtime_state",
            f"output_int_register_{b}", f"output_int_register_{b + 1}")


def input_names(register_base: int) -> tuple[str, ...]:
    b = register_base
    return (f"input_int_register_{b}", *(f"input_double_register_{b + i}" for i in range(6)))


@dataclass(frozen=True, slots=True)
class UrTarget:
    """One answer: ``seq`` (the sequence register), ``pose`` (m, rotation vector rad: the
    input doubles), ``echo`` (the robot cycle it answers; not on the wire)."""

    seq: int
    pose: tuple[float, ...]
    echo: int


class UrLink(AbbLink):
    name = "RTDE"
    rx_topic = "serial_rx"
    tx_topic = "serial_tx"
    SESSION_UP = "RTDE link up (session set up, the controller's first data package)"

    def __init__(self, correction_frame: str = "base", max_lead_mm: float = 5.0, max_lead_deg: float = 2.0, *,
                 cycle_period_ms: float = 2.0, register_base: int = 24, heartbeat_cycles: int = 25):
        super().__init__(correction_frame, max_lead_mm, max_lead_deg)
        self.cycle_ms = cycle_period_ms
        self.frequency_hz = 1000.0 / cycle_period_ms
        self.outputs = output_names(register_base)
        self.inputs = input_names(register_base)
        self.heartbeat_cycles = heartbeat_cycles
        self.framer = rtde.Framer()
        self._step: str | None = None  # the request awaiting its answer ('V', 'v', 'O', 'I', 'S')
        self._out: rtde.Recipe | None = None
        self._in: rtde.Recipe | None = None
        self.controller_version: tuple[int, int, int, int] | None = None
        self._heartbeat: int | None = None
        self._heartbeat_cycle = 0
        self._playing: bool | None = None  # the program's runtime_state PLAYING at the last state
        self._up_text = self.SESSION_UP
        self.counters.update(dict.fromkeys(("connections", "refused", "text_messages", "packets", "ignored",
                                            "program_stops"), 0))

    @property
    def up_text(self) -> str:
        """The link_up event's text (a session set up, or the program playing again)."""
        return self._up_text

    @classmethod
    def from_config(cls, config: UrConfig) -> UrLink:
        return cls(config.correction_frame, config.max_lead_mm, config.max_lead_deg,
                   cycle_period_ms=config.cycle_period_ms, register_base=config.register_base,
                   heartbeat_cycles=config.heartbeat_cycles)

    # -- session set-up -----------------------------------------------------------------------
    def start(self, t_ns: int) -> list:
        """(Re)start on the stream as it is: pause, then set up afresh (nothing before the
        adapter's first connection: the set-up starts with it)."""
        super().start(t_ns)
        self._out = self._in = None
        if not self.counters["connections"]:
            self._step = None
            return []
        self._step = "P"
        return [Transmit(rtde.pack(rtde.PAUSE))]

    def _connected(self) -> list:
        super().start(0)
        self.framer.reset()
        self.framer.sync = None
        self._out = self._in = None
        self.counters["connections"] += 1
        self._step = "V"
        return [Transmit(rtde.encode_version_request())]

    def _refused(self, why: str) -> list:
        self.counters["refused"] += 1
        self._step = None
        return [LinkError(f"RTDE link: {why}; the session is not set up (retried when the gateway restarts the "
                          "link)")]

    def _setup(self, p: rtde.Packet) -> list:
        step = self._step
        if p.type == rtde.PAUSE and step == "P":
            rtde.decode_u8(p.payload, "pause reply")  # (refused only when not started: either way, set up)
            self._step = "V"
            return [Transmit(rtde.encode_version_request())]
        if p.type == rtde.REQUEST_PROTOCOL_VERSION and step == "V":
            if rtde.decode_u8(p.payload, "protocol version reply") != 1:
                return self._refused(f"the controller refused RTDE protocol version {rtde.PROTOCOL_VERSION}")
            self._step = "v"
            return [Transmit(rtde.pack(rtde.GET_URCONTROL_VERSION))]
        if p.type == rtde.GET_URCONTROL_VERSION and step == "v":
            self.controller_version = rtde.decode_controller_version(p.payload)
            if self.controller_version[0] < 5 and self.frequency_hz > 125.0:
                return self._refused(f"a CB3 controller (version {self.controller_version[0]}) sends at most 125 Hz, "
                                     f"the cycle asks {self.frequency_hz:g} Hz (cycle_period_ms = 8 for a CB3)")
            self._step = "O"
            return [Transmit(rtde.encode_setup_outputs(self.frequency_hz, self.outputs))]
        if p.type == rtde.SETUP_OUTPUTS and step == "O":
            rid, types = rtde.decode_setup_reply(p.payload, "output setup")
            if rid == 0 or len(types) != len(self.outputs) or any(t not in rtde.TYPES for t in types):
                return self._refused(f"output setup refused: {dict(zip(self.outputs, types, strict=False))}")
            self._out = rtde.Recipe(rid, self.outputs, types)
            self._step = "I"
            return [Transmit(rtde.encode_setup_inputs(self.inputs))]
        if p.type == rtde.SETUP_INPUTS and step == "I":
            rid, types = rtde.decode_setup_reply(p.payload, "input setup")
            want = ("INT32",) + ("DOUBLE",) * 6
            if rid == 0 or types != want:
                return self._refused(f"input setup refused (IN_USE: another RTDE client writes them): "
                                     f"{dict(zip(self.inputs, types, strict=False))}")
            self._in = rtde.Recipe(rid, self.inputs, types)
            self._step = "S"
            return [Transmit(rtde.pack(rtde.START))]
        if p.type == rtde.START and step == "S":
            if rtde.decode_u8(p.payload, "start reply") != 1:
                return self._refused("the controller refused to start")
            self._step = "U"
            assert self._out is not None
            self.framer.sync = rtde.pack(rtde.DATA_PACKAGE, bytes([self._out.recipe_id]) + bytes(self._out.size))[:4]
            return []
        self.counters["malformed"] += 1
        return [LinkError(f"RTDE link: a {p.letter!r} packet while waiting for {step!r}: dropped")]

    # -- the stream ------------------------------------------------------------------------------
    def receive(self, data: bytes, t_ns: int) -> list:
        if not data:
            events: list = [LinkDown("a new RTDE connection")] if self._running else []
            self._running = False
            return events + self._connected()
        events = []
        stamped: list[tuple[int, float]] = []  # (index in events, controller timestamp) of each state
        packets = self.framer.feed(data)
        for err in self.framer.errors:
            self.counters["malformed"] += 1
            events.append(LinkError(f"RTDE link: {err}"))
        self.framer.errors.clear()
        for p in packets:
            self.counters["packets"] += 1
            try:
                if p.type == rtde.TEXT_MESSAGE:
                    text, source, level = rtde.decode_text(p.payload)
                    self.counters["text_messages"] += 1
                    events.append(LinkError(f"RTDE link: the controller says ({source}, level {level}): {text}"))
                elif p.type == rtde.DATA_PACKAGE:
                    if self._step == "U":
                        got, ts = self._data(p)
                        stamped += [(len(events) + i, ts) for i, e in enumerate(got)
                                    if isinstance(e, CycleReceived)]
                        events += got
                    else:
                        self.counters["ignored"] += 1  # (the last of a session being paused)
                else:
                    events += self._setup(p)
            except rtde.RtdeProtocolError as e:
                self.counters["malformed"] += 1
                events.append(LinkError(f"RTDE link: {e}; packet dropped ({self.counters['malformed']} so far)"))
        if len(stamped) > 1:
            # A read of several data packages (TCP coalesces a stalled stream): each state is
            # aged by the controller's own clock from the newest, which is the read's; they would
            # otherwise all carry the read's time, and the pose filter would see time stand still.
            newest = stamped[-1][1]
            for i, ts in stamped[:-1]:
                e = events[i]
                events[i] = CycleReceived(e.state, round((newest - ts) * 1e9))
        return events

    def _data(self, p: rtde.Packet) -> tuple[list, float]:
        """The events of one data package and the controller's timestamp in it (s)."""
        assert self._out is not None
        v = self._out.decode(p.payload)
        ts = float(v["timestamp"])
        if not (math.isfinite(ts) and ts >= 0):
            raise rtde.RtdeProtocolError(f"timestamp {ts} is not a time")
        base_T_flange = rtde.transform_from_ur_pose(v["actual_TCP_pose"])
        cycle = round(ts * 1000.0 / self.cycle_ms) % _MOD
        new = not self._running
        if not new:
            ahead = (cycle - self._last) % _MOD
            if ahead == 0 or ahead > MAX_GAP_CYCLES:
                self.counters["out_of_sequence"] += 1
                return [LinkError(f"RTDE link: cycle {cycle} (timestamp {ts:.4f} s) not after the last ({self._last})"
                                  f": dropped, no answer")], ts
        events: list = []
        self.feedback = base_T_flange
        heartbeat = int(v[self.outputs[5]])
        runtime = int(v["runtime_state"])
        playing = runtime == rtde.RUNTIME_PLAYING
        if new:
            self._running = True
            self.target = self.feedback.copy()
            self.counters["sessions"] += 1
            self._heartbeat, self._heartbeat_cycle = heartbeat, cycle
            self._playing = playing
            self._up_text = self.SESSION_UP
            events.append(LinkUp())
        elif heartbeat != self._heartbeat:
            self._heartbeat, self._heartbeat_cycle = heartbeat, cycle
        if not new and playing != self._playing:
            # The program stopped (Stop on the pendant or the Dashboard, a protective stop) or
            # plays again: read from RTDE's runtime_state, whoever stopped it. Stopped, the
            # link is down for the gateway (its link_down event; it holds); the target is the
            # arm (no old target waits in the registers); playing again, a new session from
            # where the arm is (link_up).
            self._playing = playing
            self.target = self.feedback.copy()
            name = rtde.RUNTIME_NAMES.get(runtime, str(runtime))
            if not playing:
                self.counters["program_stops"] += 1
                events.append(LinkDown(f"the robot's program stopped (runtime_state {name} at cycle {cycle}); "
                                       "the targets stay at the arm until it plays again"))
            else:
                self.counters["sessions"] += 1
                self._heartbeat, self._heartbeat_cycle = heartbeat, cycle
                self._up_text = (f"RTDE link up: the robot's program plays again (cycle {cycle}); the target "
                                 "starts at the arm")
                events.append(LinkUp())
        self._last = cycle
        alive = (cycle - self._heartbeat_cycle) % _MOD < self.heartbeat_cycles
        safety = int(v["safety_mode"])
        events.append(CycleReceived(CycleState(
            cycle=cycle,
            base_T_flange_mm=self.feedback,
            corrections_on=int(v["runtime_state"]) == rtde.RUNTIME_PLAYING and alive,
            tool_mode=self.tool_mode,
            cumulative=True,
            arm_power=int(v["robot_mode"]) == rtde.ROBOT_MODE_RUNNING,
            fault=safety not in (rtde.SAFETY_MODE_NORMAL, rtde.SAFETY_MODE_REDUCED),
            correction_missed=False,  # RTDE reports no late answers
        )))
        return events, ts

    # -- answers -----------------------------------------------------------------------------------
    def correction(self, cycle: int, dp_mm, rv_rad, max_step_mm: float, max_step_deg: float) -> UrTarget:
        """As over EGM; while the program is stopped a hold at the arm (the program reads no
        register: a step would wait there as an old target)."""
        if self._playing is False:
            return self.hold(cycle, True)
        return super().correction(cycle, dp_mm, rv_rad, max_step_mm, max_step_deg)

    def _message(self, cycle: int, t_ns: int) -> UrTarget:
        assert self.target is not None
        self._seq = self._seq % SEQ_MAX + 1
        return UrTarget(self._seq, rtde.ur_pose_from_transform(self.target), cycle)

    def send(self, correction: UrTarget, t_ns: int) -> list:
        if self._in is None or not self._running:
            return []
        values = {self.inputs[0]: correction.seq}
        values.update(zip(self.inputs[1:], correction.pose, strict=True))
        return [Transmit(self._in.encode(values))]
