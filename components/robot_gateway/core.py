"""The gateway (pure): the last line of safety between the controller and a robot link.

One implementation of the safety rules for every link protocol. A :class:`Link` turns what
the robot sends into a :class:`CycleState` per robot cycle and encodes the gateway's answer
(a correction or a hold) into bytes; :class:`GatewayCore` decides that answer:

1. robot cycle k arrives: publish ``robot_gateway/robot_state`` (world_T_flange, stamp =
   receive time - ``status_delay_ms``) and account for the previous cycle (missed or not);
2. answer cycle k from the controller's command for k (``FlangeCommand.cycle == k``),
   waiting for it until ``reply_deadline_ms``; then the freshest command no older than
   ``stale_cycles``, else zero (``stale_command``);
3. every step is clamped (norm to ``max_speed_mm_s`` x cycle, angle to
   ``max_angular_speed_deg_s`` x cycle), cut to the workspace box (so that the step and
   the repeats the robot may add on its own when answers are late, RSI's HOLDON up to
   ``robot_late_limit``, stay inside: :meth:`GatewayCore.late_repeat_cycles`), changed to the robot's
   correction frame (base or tool: ``CycleState.tool_mode``) and handed to the link, which
   quantises it to its wire within the limits.

Zero (hold) instead: no usable command (stale), the controller's liveliness token is gone,
the command says HOLD/IDLE or asks ALTER off, the robot reports FAULT, the gateway is
faulted, two command streams. ``fault_after_missed`` consecutive missed cycles (no fresh
command at the deadline, the robot reporting a late correction, cycles lost on the line)
while commands come raise a latched fault: hold, plus ALTER_OFF (if ``alter_off_on_fault``)
until the robot shows correction mode off; it clears when the robot re-activates it (a new
ALTER session, started by the operator at the controller) or on ``console/command``
{component: robot_gateway, verb: reset_fault}. The miss watchdog arms with the first fresh
command, and disarms while the controller is gone (then the gateway just holds and waits).
Every such action is an event on ``robot_gateway/events``, rate-limited per code to one per
``event_interval_ms``. See README.md for every rule and event.

Links (``links.LINKS``, chosen by ``config.link``): ALTER (``links.alter.link.AlterLink``:
STATUS k on ``serial_rx``, a CORRECTION echoing k quantised to 0.01 mm / 0.01 deg on
``serial_tx``, the TOOL_MODE bit choosing the frame) and KUKA RSI-style UDP/XML
(``links.rsi.link.RsiLink``: ``udp_rx``, ``udp_tx``). The component is ``robot_gateway``
with the same topics and events whatever the link.

Frames: ``world`` (the cell), ``base`` (the robot base, placed by ``world_T_base_mm_deg``),
``tool`` (the flange). A FlangeCommand's header.frame_id says whether its step is in
``world`` (default) or ``tool``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.link import (
    CycleReceived,
    CycleState,
    Link,
    LinkDown,
    LinkError,
    LinkUp,
    RepSent,
    SendRejected,
    Transmit,
)
from humanpt.robot_gateway.links import LINKS, link_kind
from humanpt.robot_gateway.safety import (
    clamp_norm,
    clip_to_envelope,
    rotation_angle_deg,
    safe_norm,
)
from humanpt.runtime.config import current_name
from humanpt.runtime.core import Core, Output, Port, UndeclaredInputError, command_operator
from humanpt.runtime.limiter import EventLimiter, SerialLinkCoreMixin
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import pose

_CYCLE_MOD = 1 << 32

# Commands further ahead than this (cycles) are refused: the controller's cycle count is off.
MAX_LEAD_CYCLES = 64
# A controller session's commands count header.seq up by one each (gaps: messages lost);
# a jump further than this, or back, is another stream.
MAX_SEQ_GAP = 100_000
# Command modes that mean "do not move".
_ZERO_MODES = (pb.CONTROL_MODE_HOLD, pb.CONTROL_MODE_IDLE)

ROBOT_STATE = "robot_gateway/robot_state"
EVENTS = "robot_gateway/events"


def cycles_after(a: int, b: int) -> int:
    """a - b in uint32 cycle arithmetic, signed."""
    d = (a - b) % _CYCLE_MOD
    return d - _CYCLE_MOD if d >= _CYCLE_MOD // 2 else d


@dataclass(frozen=True)
class Command:
    """A parsed FlangeCommand: per-cycle step in ``frame`` (mm, rotation vector rad)."""

    cycle: int
    frame: str  # "world" or "tool"
    dp_mm: np.ndarray
    rv_rad: np.ndarray
    zero: bool  # HOLD / IDLE mode or ALTER off requested: no motion
    alter_off: bool


@dataclass(frozen=True)
class Sent:
    """One correction the gateway sent (for benches and tests; not an output).

    ``correction`` is the link's wire object (``links.alter.messages.Correction`` for ALTER,
    ``links.rsi.protocol.RsiCorrection`` for RSI); ``step`` the decided step before the
    link quantised it: (dp_mm (3,), rv_rad (3,)) in the robot's correction frame (base or
    tool), None for a hold."""

    t_ns: int
    cycle: int
    correction: Any
    source: str  # "fresh", "reused", "stale", "gone", "fault", "robot_fault", "hold", "conflict"
    command_cycle: int | None
    step: tuple[np.ndarray, np.ndarray] | None = None


WATCH = ("controller",)  # the liveliness the gateway watches


def gateway_ports(*rx_topics: str) -> tuple[Port, ...]:
    """The gateway's inputs with the links' receive topics (``serial_rx``, ``udp_rx``)."""
    return (
        Port("tick", pb.Tick, "_on_tick"),
        *(Port(t, pb.SerialChunk, "_on_rx") for t in rx_topics),
        Port("controller/command", pb.FlangeCommand, "_on_command", queue=8),
        Port("liveliness", pb.Liveliness, "_on_liveliness"),
        Port("console/command", pb.Command, "_on_console", queue=8),
        Port("clock_step", pb.Event, "_on_clock_step"),
    )


# Every registered link's receive topic is a port; a gateway reads its own link's only.
_RX_TOPICS = tuple(sorted({link_kind(name).rx_topic for name in LINKS}))


class GatewayCore(SerialLinkCoreMixin, Core):
    """The gateway's safety rules over the :class:`Link` its config names (``config.link``,
    made by the link registry ``links.LINKS``): one core for every link."""

    name = "robot_gateway"
    config_type = GatewayConfig
    ports = gateway_ports(*_RX_TOPICS)
    watch = WATCH
    realtime = True  # a robot link's cycle: see runtime.tuning.tune_realtime
    # Snapshots (runtime/snapshot.py): the corrections sent are kept for benches and tests only;
    # the commands held are Commands, the robot's last cycle a CycleState.
    not_frozen = frozenset({"sent"})
    state_types = (Command, CycleState)

    def __init__(self, config: GatewayConfig):
        kind = link_kind(config.link) if isinstance(config, GatewayConfig) else None
        if kind is not None:
            # The link first: which receive port is this gateway's (_bind) depends on it.
            self.link: Link = kind.make(config)
            self.rx_topic = kind.rx_topic
        super().__init__(config)  # (TypeError for a config that is not a GatewayConfig)
        # How many times the robot may repeat a correction on its own when answers are late
        # (RSI with HOLDON on: up to its late limit); the envelope keeps them all inside.
        self.late_repeats = kind.late_repeats(config)
        self._limiter = EventLimiter(round(config.event_interval_ms * 1e6))
        self._world_T_base = transform_from_x(np.asarray(config.world_T_base_mm_deg, dtype=float))
        self._started = False
        self._commands: dict[int, Command] = {}
        self._status: CycleState | None = None
        self._status_t_ns: int | None = None  # when the last STATUS arrived
        # (status, its base_T_flange, world_T_flange): both read once per STATUS, mm.
        self._status_pose: tuple[CycleState, np.ndarray, np.ndarray] | None = None
        self._pending: tuple[int, int] | None = None  # (cycle, deadline_ns) awaiting an answer
        self._prev_cycle: int | None = None  # last STATUS cycle of this link session
        self._prev_fresh: bool | None = (
            None  # was it answered with its own command? None: not answered
        )
        self._missed = 0  # consecutive missed cycles
        self._armed = False  # the miss watchdog: armed by a fresh command
        self._armed_from: int | None = None  # ... for the cycles from the one it commanded
        self._fault: str | None = None  # latched fault reason
        self._fault_alter_off_seen = False  # the controller showed ALTER off since the fault
        self._controller_gone = False
        self._stale = False  # in a stale episode (sending zero for want of a command)
        self._silent = False  # in a silence episode (link up, no STATUS)
        self._link_down = False
        # Stamp of the last robot_state (gateway time): what the controller stamps its
        # answer with; and of the last few cycles, to check a command's stamp against.
        self._status_stamp_ns: int | None = None
        self._cycle_stamps: dict[int, int] = {}
        # The bound controller session's command stream (header.seq), per liveliness episode.
        self._seq_last: int | None = None
        self._seq_t_ns: int | None = None  # when its last command came
        self._foreign_last: int | None = None  # the last seq of a second stream
        self._conflict_until_ns = -1  # hold until then: a second stream was seen
        self._in_conflict = False
        self._last_command_ns: int | None = None  # when the last accepted command came
        self._starved_since: int | None = None  # starvation hold: since when no command
        self._tx = bytearray()
        self.sent: deque[Sent] = deque(maxlen=100_000)
        self.counters: dict[str, int] = dict.fromkeys(
            (
                "statuses",
                "fresh",
                "reused",
                "zero",
                "clamped",
                "envelope",
                "deadline_missed",
                "robot_missed",
                "status_lost",
                "commands",
                "commands_dropped",
                "link_errors",
                "link_down",
                "faults",
                "reps",
                "late_commands",
                "stamp_mismatch",
                "foreign_commands",
                "starvations",
            ),
            0,
        )

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def _bind(self, port: Port):
        if port.handler == "_on_rx" and port.topic != self.rx_topic:
            def other_link(t_ns: int, msg: Any) -> list[Output]:
                raise UndeclaredInputError(f"{port.topic!r} is another link's; this gateway's {self.link.name} "
                                           f"link reads {self.rx_topic!r}")
            return other_link
        return super()._bind(port)

    @property
    def fault(self) -> str | None:
        return self._fault

    @property
    def missed_cycles(self) -> int:
        return self._missed

    @property
    def link_running(self) -> bool:
        return self.link.is_running

    # -- inputs (SerialLinkCoreMixin._bind): the first input of any kind starts the link -----
    def _begin(self, t_ns: int) -> list[Output]:
        outs: list[Output] = []
        if not self._started:
            self._started = True
            self._link(self.link.start(t_ns), t_ns, outs)
        return outs

    def _on_rx(self, t_ns: int, msg: pb.SerialChunk, outs: list[Output]) -> None:
        rx_ns = msg.header.stamp_ns or t_ns
        self._link(self.link.receive(bytes(msg.data), t_ns), rx_ns, outs)

    def _flush_tx(self, t_ns: int, outs: list) -> None:
        if self._tx:
            topic = self.link.tx_topic
            outs.append((topic, pb.SerialChunk(header=self.next_header(topic, t_ns, self.link.name.lower()),
                                               data=bytes(self._tx), outgoing=True)))
            self._tx.clear()

    # -- link -------------------------------------------------------------------------------
    def _link(self, events, t_ns: int, outs: list[Output]) -> None:
        """Act on the endpoint's events; ``t_ns`` is when the bytes arrived."""
        for e in events:
            if isinstance(e, Transmit):
                self._tx += e.data
            elif isinstance(e, CycleReceived):
                self._on_status(e.state, t_ns, outs, e.age_ns)
            elif isinstance(e, LinkUp):
                self._new_session()
                if self._link_down:
                    self._link_down = False
                    self._ev(
                        outs,
                        t_ns,
                        pb.SEVERITY_INFO,
                        "link_up",
                        self.link.up_text,
                        limited=False,
                    )
            elif isinstance(e, LinkDown):
                self.counters["link_down"] += 1
                self._link_down = True
                self._new_session()
                self._ev(
                    outs,
                    t_ns,
                    pb.SEVERITY_ERROR,
                    "link_down",
                    f"{self.link.name} link down: {e.reason} ({e.unacked} corrections unacknowledged); "
                    "the robot gets no corrections (holds) until it is back",
                    limited=False,
                )
            elif isinstance(e, LinkError):
                self.counters["link_errors"] += 1
                self._ev(outs, t_ns, pb.SEVERITY_WARNING, "link_error", e.text)
            elif isinstance(e, SendRejected):
                self._ev(
                    outs,
                    t_ns,
                    pb.SEVERITY_WARNING,
                    "send_rejected",
                    f"correction not sent: {e.why}",
                )
            elif isinstance(e, RepSent):
                self.counters["reps"] += 1

    def _new_session(self) -> None:
        """A link (re)start: cycle numbers and held commands of the old session are void."""
        self._pending = None
        self._prev_cycle = None
        self._prev_fresh = None
        self._commands.clear()
        self._status = None
        self._status_t_ns = None
        self._status_stamp_ns = None
        self._cycle_stamps.clear()
        self._silent = False
        self._missed = 0
        # Cycle numbers restart: the watchdog re-arms with the first command of this session
        # (it still holds the robot meanwhile, as before any command).
        self._armed = False
        self._armed_from = None

    def _on_tick(self, t_ns: int, msg: pb.Tick, outs: list[Output]) -> None:
        events = self.link.poll(t_ns)
        if events:
            self._link(events, t_ns, outs)
        if self._pending is not None and t_ns >= self._pending[1]:
            cycle = self._pending[0]
            self.counters["deadline_missed"] += 1
            if self._judged(cycle) and not self._controller_gone and self._fault is None:
                self._ev(
                    outs,
                    t_ns,
                    pb.SEVERITY_WARNING,
                    "deadline_missed",
                    f"no command for cycle {cycle} within {self.config.reply_deadline_ms} ms of its status",
                )
            self._answer(cycle, t_ns, outs)
        if (
            self._status_t_ns is not None
            and not self._silent
            and t_ns - self._status_t_ns
            > self.config.status_timeout_cycles * self.config.cycle_period_ns
            and self.link.is_running
        ):
            self._silent = True
            self._pending = None
            self.counters["link_down"] += 1
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_ERROR,
                "link_down",
                f"no STATUS from the controller for {(t_ns - self._status_t_ns) / 1e6:.0f} ms; "
                f"the robot gets no corrections (holds); restarting the {self.link.name} link",
                limited=False,
            )
            # Whatever silenced it (a cut line, a peer stuck in start-up), a restart is the
            # way back: the link_up event says when it is.
            self._link_down = True
            self._link(self.link.start(t_ns), t_ns, outs)

    # -- controller side ----------------------------------------------------------------------
    def _on_clock_step(self, t_ns: int, msg: pb.Event, outs: list[Output]) -> None:
        """The wall clock stepped by ``msg.text`` ns (the live shell, runtime/clock.py): the
        watchdogs' times move with it, so that the step is neither a silence (STATUS
        timeout, link_down) nor a burst of expiries (reply deadline, the link's timers).
        Stamps already given (robot states, the cycles' stamps commands echo) stay as they
        were: they name the instants they were taken at."""
        try:
            step = int(msg.text)
        except ValueError:
            self._ev(outs, t_ns, pb.SEVERITY_WARNING, "bad_input", f"clock_step {msg.text[:40]!r} is not a "
                     "step in ns: ignored")
            return
        moved = lambda t: None if t is None else t + step  # noqa: E731
        self._status_t_ns = moved(self._status_t_ns)
        if self._pending is not None:
            self._pending = (self._pending[0], self._pending[1] + step)
        self._seq_t_ns = moved(self._seq_t_ns)
        if self._conflict_until_ns >= 0:
            self._conflict_until_ns += step
        self._last_command_ns = moved(self._last_command_ns)
        self._starved_since = moved(self._starved_since)
        self._limiter.shift(step)
        shift = getattr(self.link, "shift_time", None)  # a link with timers of its own
        if shift is not None:
            shift(step)
        self._ev(outs, t_ns, pb.SEVERITY_INFO, "clock_step",
                 f"the wall clock stepped by {step / 1e9:+.3f} s: the watchdogs keep their time", limited=False)

    def _on_command(self, t_ns: int, msg: pb.FlangeCommand, outs: list[Output]) -> None:
        self.counters["commands"] += 1
        if self._controller_gone:
            self.counters["commands_dropped"] += 1
            return  # its token is gone: nothing from it moves the robot until it is back
        frame = msg.header.frame_id or "world"
        dt, dr = msg.d_translation_m, msg.d_rotation_rad
        step = (dt.x * 1000.0, dt.y * 1000.0, dt.z * 1000.0, dr.x, dr.y, dr.z)
        dp_mm, rv_rad = np.array(step[:3]), np.array(step[3:])
        if frame not in ("world", "tool") or not all(map(math.isfinite, step)):
            self._bad_command(
                outs,
                t_ns,
                f"command for cycle {msg.cycle} dropped: frame {frame!r}, step {dp_mm} mm, {rv_rad} rad "
                "(need frame world or tool and finite values)",
            )
            return
        cfg = self.config
        ref = self._prev_cycle
        if ref is not None:
            lead = cycles_after(msg.cycle, ref)
            if lead < -cfg.stale_cycles:
                # Late (a partition's backlog, a slow link): never acted on.
                self.counters["commands_dropped"] += 1
                self.counters["late_commands"] += 1
                self._ev(outs, t_ns, pb.SEVERITY_WARNING, "late_command",
                         f"command for cycle {msg.cycle} arrived {-lead} cycles after it (robot at cycle "
                         f"{ref}): dropped, never acted on")
                return
            if lead > MAX_LEAD_CYCLES:
                self._bad_command(
                    outs,
                    t_ns,
                    f"command for cycle {msg.cycle} is {lead} cycles ahead of the robot (cycle {ref}); dropped",
                )
                return
            # The controller stamps its answer with the stamp of the robot_state it answers
            # (this gateway's time, + one cycle per cycle ahead): clock-free, exact.
            stamp = msg.header.stamp_ns
            expected = self._cycle_stamps.get(msg.cycle)
            if expected is None and self._status_stamp_ns is not None:
                expected = self._status_stamp_ns + lead * cfg.cycle_period_ns
            if expected is not None and abs(stamp - expected) > cfg.stamp_tolerance_ms * 1e6:
                self.counters["commands_dropped"] += 1
                self.counters["stamp_mismatch"] += 1
                self._ev(outs, t_ns, pb.SEVERITY_WARNING, "stamp_mismatch",
                         f"command for cycle {msg.cycle} stamped {(stamp - expected) / 1e6:+.1f} ms from that "
                         f"cycle's robot_state (tolerance {cfg.stamp_tolerance_ms:g} ms): not an answer to "
                         "this gateway's cycle; dropped")
                return
        if not self._in_stream(t_ns, msg.header.seq, msg.cycle, outs):
            return
        cmd = Command(
            msg.cycle,
            frame,
            dp_mm,
            rv_rad,
            msg.mode in _ZERO_MODES or msg.request_alter_off,
            msg.request_alter_off,
        )
        self._commands[msg.cycle] = cmd
        self._last_command_ns = t_ns
        if (
            len(self._commands) > 2 * MAX_LEAD_CYCLES
        ):  # bound the store (no status to prune against)
            del self._commands[min(self._commands, key=lambda c: cycles_after(c, msg.cycle))]
        if not self._armed and self._fault is None:
            self._armed = True
            # A controller that commands ahead starts with the NEXT cycle: the ones before
            # its first command are not its misses.
            self._armed_from = msg.cycle
        if self._pending is not None and self._pending[0] == msg.cycle:
            self._answer(msg.cycle, t_ns, outs)

    def _bad_command(self, outs: list[Output], t_ns: int, text: str) -> None:
        self.counters["commands_dropped"] += 1
        self._ev(outs, t_ns, pb.SEVERITY_WARNING, "bad_command", text)

    def _in_stream(self, t_ns: int, seq: int, cycle: int, outs: list[Output]) -> bool:
        """Whether a command (header ``seq``) continues the bound controller session's
        stream. The first command after the controller's token came binds its stream; a
        command that does not continue it (seq back or far ahead: a second controller
        session, a replay, a forger) is dropped and holds the robot for
        ``conflict_hold_ms`` (``controller_conflict``). A second stream that goes on alone
        for that long (the bound one silent: a controller restarted before its old token
        expired) becomes the bound one (``controller_rebound``)."""
        hold_ns = round(self.config.conflict_hold_ms * 1e6)
        last = self._seq_last
        if last is None or 0 < seq - last <= MAX_SEQ_GAP:
            self._seq_last, self._seq_t_ns = seq, t_ns
            return True
        f = self._foreign_last
        if (f is not None and 0 < seq - f <= MAX_SEQ_GAP
                and (self._seq_t_ns is None or t_ns - self._seq_t_ns >= hold_ns)):
            # The bound stream fell silent while this one went on: it is the controller now.
            self._ev(outs, t_ns, pb.SEVERITY_WARNING, "controller_rebound",
                     f"the command stream bound to (seq {last}) is silent for "
                     f"{(t_ns - (self._seq_t_ns or t_ns)) / 1e6:.0f} ms and another one goes on alone "
                     f"(seq {seq}, cycle {cycle}): bound to it", limited=False)
            self._seq_last, self._seq_t_ns, self._foreign_last = seq, t_ns, None
            self._conflict_until_ns = -1
            self._in_conflict = False
            return True
        self._foreign_last = seq
        self.counters["commands_dropped"] += 1
        self.counters["foreign_commands"] += 1
        self._conflict_until_ns = t_ns + hold_ns
        self._commands.clear()  # hold: nothing queued moves the robot while two streams speak
        if not self._in_conflict:
            self._in_conflict = True
            self._ev(outs, t_ns, pb.SEVERITY_ERROR, "controller_conflict",
                     f"a command (seq {seq}, cycle {cycle}) that does not continue the controller session's "
                     f"stream (last seq {last}): a second controller session, a replay or a forger; holding "
                     f"the robot until it is quiet for {self.config.conflict_hold_ms:g} ms", limited=False)
        else:
            self._ev(outs, t_ns, pb.SEVERITY_WARNING, "foreign_command",
                     f"command seq {seq} (cycle {cycle}) is not the bound stream's (last seq {last}): dropped")
        return False

    def _reset_stream(self) -> None:
        self._seq_last = self._seq_t_ns = self._foreign_last = None
        self._conflict_until_ns = -1
        self._in_conflict = False

    def _on_liveliness(self, t_ns: int, msg: pb.Liveliness, outs: list[Output]) -> None:
        if msg.component != "controller":
            return
        if not msg.alive and not self._controller_gone:
            self._controller_gone = True
            self._armed = False
            self._commands.clear()
            self._reset_stream()
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_WARNING,
                "controller_gone",
                "the controller's liveliness token is gone: holding the robot (zero corrections)",
                limited=False,
            )
            if self._pending is not None:
                self._answer(self._pending[0], t_ns, outs)
        elif msg.alive and self._controller_gone:
            self._controller_gone = False
            self._missed = 0
            self._reset_stream()  # a new session (or the same after a partition): bind anew
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_INFO,
                "controller_back",
                "the controller is back; its commands move the robot again",
                limited=False,
            )

    def _on_console(self, t_ns: int, msg: pb.Command, outs: list[Output]) -> None:
        if current_name(msg.component) != self.name:  # a script's old name (alter_gateway) too
            return
        if msg.verb == "reset_fault":
            who = command_operator(msg)
            if not who:
                self._ev(outs, t_ns, pb.SEVERITY_WARNING, "bad_console_command",
                         "reset_fault refused: it needs the operator's name (humanpt console reset-fault)",
                         limited=False)
            elif self._fault is None:
                self._ev(outs, t_ns, pb.SEVERITY_INFO, "no_fault", f"reset_fault by {who}: no fault to reset",
                         limited=False)
            else:
                self._clear_fault(t_ns, f"reset by {who} (console)", outs)
        else:
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_WARNING,
                "bad_console_command",
                f"unknown verb {msg.verb!r} (known: reset_fault)",
            )

    # -- robot side ---------------------------------------------------------------------------
    def _on_status(self, status: CycleState, rx_ns: int, outs: list[Output], age_ns: int = 0) -> None:
        cfg = self.config
        k = status.cycle
        self.counters["statuses"] += 1
        prev_status = self._status
        if self._silent:
            self._silent = False
            self._ev(
                outs, rx_ns, pb.SEVERITY_INFO, "link_up", f"STATUS again (cycle {k})", limited=False
            )
        if self._pending is not None:  # a new STATUS overtook an unanswered one
            self._prev_fresh = False
            self._pending = None
        # Account for the previous cycle (and any lost in between).
        if (
            self._prev_cycle is not None
            and self._judged(self._prev_cycle)
            and self._fault is None
            and not self._controller_gone
        ):
            lost = cycles_after(k, self._prev_cycle) - 1
            robot_missed = status.correction_missed and self._prev_fresh is not None
            missed = lost + (1 if (self._prev_fresh is False or robot_missed) else 0)
            if lost > 0:
                self.counters["status_lost"] += lost
                self._ev(
                    outs,
                    rx_ns,
                    pb.SEVERITY_WARNING,
                    "status_lost",
                    f"{lost} STATUS message(s) lost before cycle {k}",
                )
            if robot_missed:
                self.counters["robot_missed"] += 1
                self._ev(
                    outs,
                    rx_ns,
                    pb.SEVERITY_WARNING,
                    "robot_missed",
                    f"the robot reports no correction in time for the cycle before {k}",
                )
            self._missed = self._missed + missed if missed else 0
            if self._missed >= cfg.fault_after_missed:
                quiet_ns = rx_ns - self._last_command_ns if self._last_command_ns is not None else None
                # (one cycle of slack: statuses jitter)
                if quiet_ns is None or quiet_ns >= (self._missed - 1) * cfg.cycle_period_ns:
                    self._starve(rx_ns, k, quiet_ns, outs)
                else:
                    self._raise_fault(
                        rx_ns, f"{self._missed} consecutive missed cycles (at cycle {k})", outs
                    )
        # Robot-side transitions. ALTER_OFF is requested until the controller shows ALTER
        # off; ALTER on again after that is a new session started at the controller.
        if self._fault is not None:
            if not status.corrections_on:
                self._fault_alter_off_seen = True
            elif self._fault_alter_off_seen:
                self._clear_fault(rx_ns, f"{self.link.name} re-activated at the controller (cycle {k})", outs)
        if status.fault and (prev_status is None or not prev_status.fault):
            self._ev(
                outs,
                rx_ns,
                pb.SEVERITY_ERROR,
                "robot_fault",
                f"the controller reports FAULT at cycle {k}; holding",
                limited=False,
            )
        self._status = status
        self._status_t_ns = rx_ns
        # The state's stamp: when the robot sampled it (its age in a read of several states),
        # less the configured status delay.
        self._status_stamp_ns = max(0, rx_ns - age_ns - round(cfg.status_delay_ms * 1e6))
        self._cycle_stamps[k] = self._status_stamp_ns
        if len(self._cycle_stamps) > cfg.stale_cycles + 2:
            del self._cycle_stamps[next(iter(self._cycle_stamps))]
        self._prev_cycle = k
        self._prev_fresh = None
        for c in [c for c in self._commands if cycles_after(c, k) < -cfg.stale_cycles]:
            del self._commands[c]
        outs.append(self._robot_state(status, self._status_stamp_ns))
        if k in self._commands or self._must_hold(status) is not None:
            self._answer(k, rx_ns, outs)
        else:
            self._pending = (k, rx_ns + round(cfg.reply_deadline_ms * 1e6))

    def _pose(self, status: CycleState) -> tuple[np.ndarray, np.ndarray]:
        """(base_T_flange, world_T_flange) of a cycle's state, mm; computed once. Do not modify."""
        if self._status_pose is None or self._status_pose[0] is not status:
            base_T_flange = status.base_T_flange_mm
            self._status_pose = (status, base_T_flange, self._world_T_base @ base_T_flange)
        return self._status_pose[1:]

    def _robot_state(self, status: CycleState, stamp: int) -> Output:
        """The cycle's robot_state, stamped ``stamp`` (when the robot sampled it: _on_status)."""
        world_T_flange = self._pose(status)[1].copy()
        world_T_flange[:3, 3] /= 1000.0
        return ROBOT_STATE, pb.RobotState(
            header=self.next_header(ROBOT_STATE, stamp, "world"),
            world_T_flange=pose(world_T_flange),
            status=pb.AlterStatus(
                alter_active=status.corrections_on,
                tool_mode=status.tool_mode,
                cumulative=status.cumulative,
                arm_power=status.arm_power,
                fault=status.fault,
            ),
            cycle=status.cycle,
            missed_cycles=self._missed,
            cycle_period_ns=self.config.cycle_period_ns,  # the cell's one cycle (runtime/cycle.py)
        )

    def _must_hold(self, status: CycleState) -> str | None:
        """Why cycle ``status`` must get a zero correction regardless of commands, or None."""
        if self._fault is not None:
            return "fault"
        if self._controller_gone:
            return "gone"
        if status.fault:
            return "robot_fault"
        return None

    # -- the answer -------------------------------------------------------------------------
    def _judged(self, k: int) -> bool:
        """Whether cycle ``k`` counts for the miss watchdog: armed, and not before the cycle
        of the command that armed it."""
        return self._armed and (self._armed_from is None or cycles_after(k, self._armed_from) >= 0)

    def _answer(self, k: int, t_ns: int, outs: list[Output]) -> None:
        """Send the correction for cycle ``k`` (the last STATUS) and close its wait."""
        self._pending = None
        if self._armed_from is not None and cycles_after(k, self._armed_from) >= 0:
            self._armed_from = None  # reached: every cycle counts from now on (also past a wrap)
        status = self._status
        if status is None or status.cycle != k:
            return
        cfg = self.config
        hold = self._must_hold(status)
        if hold is None and self._in_conflict:
            if t_ns < self._conflict_until_ns:
                hold = "conflict"
            else:
                self._in_conflict = False
                self._ev(outs, t_ns, pb.SEVERITY_INFO, "conflict_cleared",
                         f"no foreign command for {cfg.conflict_hold_ms:g} ms: the bound controller session's "
                         "commands move the robot again", limited=False)
        cmd = self._commands.get(k)
        source = "fresh"
        if hold is None and cmd is None:
            older = [c for c in self._commands if -cfg.stale_cycles <= cycles_after(c, k) < 0]
            if older:
                cmd = self._commands[max(older, key=lambda c: cycles_after(c, k))]
                source = "reused"
            else:
                source = "stale"
        # A servo cycle is on time when its own command answered it; holding for a fault
        # or an absent controller is not a servo cycle and is not counted (None).
        self._prev_fresh = None if hold is not None else source == "fresh"
        if source == "stale" and hold is None:
            text = (
                f"no command for cycle {k} or the {cfg.stale_cycles} before it: zero correction"
                if self._judged(k)
                else f"no command from the controller yet (cycle {k}): zero correction"
            )
            if not self._stale:
                self._limiter.reset("stale_command")
            # Waiting for a controller that never commanded is normal at start-up: INFO.
            severity = pb.SEVERITY_WARNING if self._judged(k) else pb.SEVERITY_INFO
            self._ev(outs, t_ns, severity, "stale_command", text)
            self._stale = True
        elif self._stale and hold is None:
            self._stale = False
            text = f"commands again from cycle {k}"
            if self._starved_since is not None:
                text += (f" after {(t_ns - self._starved_since) / 1e6:.0f} ms without any: resumed by itself "
                         "(policy: a silent controller is held, not faulted; no reset needed)")
                self._starved_since = None
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_INFO,
                "command_resumed",
                text,
                limited=False,
            )
        off = hold == "fault" and cfg.alter_off_on_fault and not self._fault_alter_off_seen
        step = None
        if hold is not None or cmd is None or cmd.zero:
            if cmd is not None and cmd.alter_off and hold is None:
                off = True
            correction = self.link.hold(k, off)
            source = hold or ("hold" if cmd is not None else "stale")
        else:
            step = self._safe_step(k, status, cmd, t_ns, outs)
            if step is None:
                correction = self.link.hold(k, False)
            else:
                correction = self.link.correction(k, step[0], step[1], cfg.max_step_mm, cfg.max_step_deg)
        self.counters[
            "fresh" if source == "fresh" else "reused" if source == "reused" else "zero"
        ] += 1
        self.sent.append(Sent(t_ns, k, correction, source, cmd.cycle if cmd is not None else None, step))
        self._link(self.link.send(correction, t_ns), t_ns, outs)

    def _safe_step(
        self, k: int, status: CycleState, cmd: Command, t_ns: int, outs: list[Output]
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Clamp, keep inside the envelope, change to the robot's correction frame:
        (dp_mm (3,), rv_rad (3,)), or None (hold) if that is not finite."""
        cfg = self.config
        base_T_flange, world_T_flange = self._pose(status)
        world_R_base = self._world_T_base[:3, :3]
        dp, rv = cmd.dp_mm, cmd.rv_rad
        max_mm, max_deg = cfg.max_step_mm, cfg.max_step_deg
        # Clamp before any frame change: a rotation keeps the norm, and a huge (finite) step
        # would overflow to NaN in it.
        dp_c, t_clamped = clamp_norm(dp, max_mm)
        rv_c, r_clamped = clamp_norm(rv, math.radians(max_deg))
        if cmd.frame == "tool":  # to world: a step about the flange origin
            world_R_flange = world_R_base @ base_T_flange[:3, :3]
            dp_c, rv_c = world_R_flange @ dp_c, world_R_flange @ rv_c
        if t_clamped or r_clamped:
            self.counters["clamped"] += 1
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_WARNING,
                "clamped",
                f"cycle {k}: step {safe_norm(dp):.3f} mm / {rotation_angle_deg(rv):.3f} deg "
                f"clamped to {max_mm:.3f} mm / {max_deg:.3f} deg per cycle "
                f"({cfg.max_speed_mm_s:g} mm/s, {cfg.max_angular_speed_deg_s:g} deg/s)",
            )
        p_world = world_T_flange[:3, 3]
        repeats = self.late_repeats
        dp_e, clipped = clip_to_envelope(
            p_world, dp_c, np.asarray(cfg.envelope_min_mm), np.asarray(cfg.envelope_max_mm), repeats
        )
        if clipped:
            self.counters["envelope"] += 1
            held = (f" (with the {repeats} repeats the robot may add if answers are late: "
                    f"{np.round(p_world + (1 + repeats) * dp_c, 2).tolist()} mm)") if repeats else ""
            self._ev(
                outs,
                t_ns,
                pb.SEVERITY_WARNING,
                "envelope",
                f"cycle {k}: step to {np.round(p_world + dp_c, 2).tolist()} mm{held} cut at the workspace "
                f"envelope {list(cfg.envelope_min_mm)}..{list(cfg.envelope_max_mm)} mm",
            )
        # World -> the robot's correction frame (base or tool).
        dp_b, rv_b = world_R_base.T @ dp_e, world_R_base.T @ rv_c
        if status.tool_mode:
            R = base_T_flange[:3, :3]
            dp_b, rv_b = R.T @ dp_b, R.T @ rv_b
        if not (np.all(np.isfinite(dp_b)) and np.all(np.isfinite(rv_b))):
            # Cannot happen after the clamp; if it ever does, the robot holds, nothing raises.
            self._bad_command(outs, t_ns, f"cycle {k}: the correction is not finite after the frame "
                                          f"changes ({dp_b} mm, {rv_b} rad): zero correction")
            return None
        return dp_b, rv_b

    # -- starvation and fault -------------------------------------------------------------------
    def _starve(self, t_ns: int, k: int, quiet_ns: int | None, outs: list[Output]) -> None:
        """No command at all for ``fault_after_missed`` cycles: the controller is cut off
        (a partition) or stalled. Policy: hold (zero corrections, ALTER stays on), no
        latched fault; the watchdog disarms and re-arms with the next accepted command,
        which resumes the robot by itself. Misses while commands keep coming (late
        commands, the robot missing corrections, statuses lost) still latch a fault."""
        self._armed = False
        self._armed_from = None
        self._missed = 0
        self.counters["starvations"] += 1
        self._starved_since = (t_ns - quiet_ns) if quiet_ns is not None else t_ns
        quiet = f"{quiet_ns / 1e6:.0f} ms" if quiet_ns is not None else "ever"
        self._ev(outs, t_ns, pb.SEVERITY_WARNING, "controller_silent",
                 f"no command for {quiet} ({self.config.fault_after_missed} cycles, at cycle {k}): "
                 "holding (zero corrections, ALTER stays on); resumes by itself with the controller's next "
                 "in-sequence, fresh command (no reset needed)", limited=False)

    def _raise_fault(self, t_ns: int, reason: str, outs: list[Output]) -> None:
        if self._fault is not None:
            return
        self._fault = reason
        self._fault_alter_off_seen = False
        self._armed = False
        self.counters["faults"] += 1
        action = "HOLD and ALTER off requested" if self.config.alter_off_on_fault else "HOLD"
        action += ("; latched: the robot moves again only after ALTER is re-activated at the controller or "
                   "the operator resets (humanpt console reset-fault)")
        self._ev(
            outs,
            t_ns,
            pb.SEVERITY_ERROR,
            "fault",
            f"gateway fault: {reason}; {action}",
            limited=False,
        )

    def _clear_fault(self, t_ns: int, why: str, outs: list[Output]) -> None:
        if self._fault is None:
            return
        self._ev(
            outs,
            t_ns,
            pb.SEVERITY_INFO,
            "fault_cleared",
            f"gateway fault cleared: {why}",
            limited=False,
        )
        self._fault = None
        self._missed = 0
        self._commands.clear()
