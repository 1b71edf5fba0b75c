"""DDCMP link state machine (pure): start-up, sequence numbers, ACK/NAK/REP.

Driven only by explicit inputs, each returning ``list[Event]``:

- ``start(now_ns)``, ``stop()``
- ``receive(data, now_ns)``: bytes read from the line
- ``poll(now_ns)``: the shell calls this at ``next_deadline_ns`` (or on any tick)
- ``send(payload, now_ns)``: queue one data message

It never reads a clock. Bytes to put on the line come back as ``Transmit`` events.

Sequence numbers (DDCMP, mod 256): R = last data NUM received in sequence, N = last NUM
sent, A = last NUM the peer acknowledged. A data message is accepted only if its NUM is
R + 1; anything else is discarded (duplicate or out of order) and never delivered.
Every data frame and ACK/NAK carries RESP = R, acknowledging everything up to R.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum
from functools import lru_cache

from humanpt.robot_gateway.links.alter.ddcmp import (
    DEFAULT_ADDRESS,
    ControlFrame,
    ControlType,
    DataFrame,
    DdcmpDecoder,
    FrameError,
    NakReason,
    ack,
    encode_frame,
    nak,
    rep,
    stack,
    strt,
)
from humanpt.robot_gateway.links.alter.events import (
    Acknowledged,
    DataReceived,
    Discarded,
    Event,
    LinkDown,
    LinkUp,
    NakReceived,
    RepSent,
    SendRejected,
    Transmit,
)

ALTER_CYCLE_NS = 28_000_000


class LinkState(Enum):
    HALTED = "halted"  # not started (or stopped): ignores the line
    ISTRT = "istrt"  # sent STRT, waiting for STRT or STACK
    ASTRT = "astrt"  # sent STACK, waiting for ACK(0), STACK or data with RESP 0
    RUNNING = "running"


@dataclass(frozen=True)
class LinkConfig:
    """Link parameters. Times in ns of the caller's time base.

    start_timeout_ns: STRT/STACK resend period during start-up.
    rep_timeout_ns: with data unacknowledged this long, send REP (default 3 cycles: the
        peer may piggyback its ACK on its next cycle's data).
    max_reps: REPs without any answer before the link is declared down and restarted; also
        the STACKs an end in start-up (ASTRT) resends before it starts over with STRT, so
        that two ends can never wait on each other for good.
    window: most data messages in flight unacknowledged (< 128 so mod-256 numbers stay
        unambiguous).
    ack_delay_ns: 0 acknowledges at the end of each ``receive``; > 0 waits that long for
        a data message to piggyback the ACK on (then ``poll`` sends a plain ACK).
    max_data_bytes: longest payload accepted or sent.
    """

    address: int = DEFAULT_ADDRESS
    start_timeout_ns: int = 100_000_000
    rep_timeout_ns: int = 3 * ALTER_CYCLE_NS
    max_reps: int = 4
    window: int = 8
    ack_delay_ns: int = 0
    max_data_bytes: int = 64

    def __post_init__(self) -> None:
        if not 0 <= self.address <= 0xFF:
            raise ValueError(f"address must be in [0, 255], got {self.address}")
        for name in ("start_timeout_ns", "rep_timeout_ns"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.ack_delay_ns < 0:
            raise ValueError(f"ack_delay_ns must be >= 0, got {self.ack_delay_ns}")
        if self.ack_delay_ns >= self.rep_timeout_ns:
            raise ValueError(
                "ack_delay_ns must be shorter than rep_timeout_ns (else the peer REPs)"
            )
        if self.max_reps < 1:
            raise ValueError(f"max_reps must be >= 1, got {self.max_reps}")
        if not 1 <= self.window <= 127:
            raise ValueError(f"window must be in [1, 127], got {self.window}")
        if not 1 <= self.max_data_bytes <= 0x3FFF:
            raise ValueError(f"max_data_bytes must be in [1, 16383], got {self.max_data_bytes}")


def _tx(*frames: DataFrame | ControlFrame) -> Transmit:
    return Transmit(b"".join(encode_frame(f) for f in frames))


@lru_cache(maxsize=1024)
def _control_tx(make, *args) -> Transmit:
    """``_tx(make(*args))`` for a control-frame constructor (ack, nak, rep, strt, stack):
    the same arguments give the same bytes, so each is built once (events are immutable)."""
    return _tx(make(*args))


class DdcmpLink:
    """One end of a DDCMP point-to-point link (both ends run the same machine)."""

    def __init__(self, config: LinkConfig | None = None) -> None:
        self.config = config or LinkConfig()
        self._decoder = DdcmpDecoder(self.config.max_data_bytes)
        self._state = LinkState.HALTED
        self._reset_sequence()

    # --- introspection -------------------------------------------------------------------

    @property
    def state(self) -> LinkState:
        return self._state

    @property
    def is_running(self) -> bool:
        return self._state is LinkState.RUNNING

    @property
    def can_send(self) -> bool:
        return self.is_running and len(self._outstanding) < self.config.window

    @property
    def last_received_num(self) -> int:
        """R: last data NUM received in sequence."""
        return self._r

    @property
    def last_sent_num(self) -> int:
        """N: last data NUM sent."""
        return self._n

    @property
    def last_acked_num(self) -> int:
        """A: last data NUM the peer acknowledged."""
        return self._a

    @property
    def unacked_count(self) -> int:
        return len(self._outstanding)

    @property
    def next_deadline_ns(self) -> int | None:
        """When ``poll`` next has something to do (None: nothing scheduled)."""
        times = [t for t in (self._timer_ns, self._ack_due_ns()) if t is not None]
        return min(times) if times else None

    def shift_time(self, step_ns: int) -> None:
        """Move the timers by ``step_ns``: the caller's clock stepped (runtime/clock.py), the
        time left on each stays."""
        if self._timer_ns is not None:
            self._timer_ns += step_ns
        if self._ack_owed_since is not None:
            self._ack_owed_since += step_ns

    # --- inputs --------------------------------------------------------------------------

    def start(self, now_ns: int) -> list[Event]:
        """Begin start-up: send STRT and retry it every start_timeout_ns."""
        self._reset_sequence()
        self._state = LinkState.ISTRT
        self._timer_ns = now_ns + self.config.start_timeout_ns
        return [_control_tx(strt, self.config.address)]

    def stop(self) -> list[Event]:
        """Halt: the line is ignored until ``start``."""
        events: list[Event] = []
        if self._state is LinkState.RUNNING:
            events.append(LinkDown("stopped", len(self._outstanding)))
        self._state = LinkState.HALTED
        self._reset_sequence()
        return events

    def send(self, payload: bytes, now_ns: int) -> list[Event]:
        """Send one data message (RESP piggybacks our acknowledgement)."""
        if not 1 <= len(payload) <= self.config.max_data_bytes:
            raise ValueError(f"payload length must be in [1, {self.config.max_data_bytes}]")
        if self._state is not LinkState.RUNNING:
            return [SendRejected("link not running")]
        if len(self._outstanding) >= self.config.window:
            return [SendRejected("window full")]
        self._n = (self._n + 1) & 0xFF
        self._outstanding.append((self._n, bytes(payload)))
        self._ack_owed_since = None  # piggybacked
        if self._timer_ns is None:
            self._timer_ns = now_ns + self.config.rep_timeout_ns
        return [_tx(DataFrame(self._n, self._r, bytes(payload), self.config.address))]

    def receive(self, data: bytes, now_ns: int) -> list[Event]:
        """Bytes from the line: frames, errors, deliveries and our answers."""
        events: list[Event] = []
        for item in self._decoder.feed(data):
            if isinstance(item, FrameError):
                self._on_frame_error(item, events)
            elif item.addr != self.config.address:
                events.append(Discarded("wrong_address", getattr(item, "num", None)))
            elif isinstance(item, DataFrame):
                self._on_data(item, now_ns, events)
            else:
                self._on_control(item, now_ns, events)
        if self.config.ack_delay_ns == 0:
            self._send_owed_ack(events)
        return events

    def poll(self, now_ns: int) -> list[Event]:
        """Timers: owed ACK, STRT/STACK retry, REP (and link-down after max_reps)."""
        events: list[Event] = []
        due = self._ack_due_ns()
        if due is not None and now_ns >= due:
            self._send_owed_ack(events)
        if self._timer_ns is None or now_ns < self._timer_ns:
            return events
        cfg = self.config
        if self._state is LinkState.ISTRT:
            events.append(_control_tx(strt, cfg.address))
            self._timer_ns = now_ns + cfg.start_timeout_ns
        elif self._state is LinkState.ASTRT:
            self._rep_count += 1
            if self._rep_count > cfg.max_reps:
                # STACK after STACK and no ACK(0): the peer may be running on an old sequence
                # (a forged or lost frame). Start over: a STRT restarts any peer.
                events.extend(self.start(now_ns))
            else:
                events.append(_control_tx(stack, cfg.address))
                self._timer_ns = now_ns + cfg.start_timeout_ns
        elif self._state is LinkState.RUNNING and self._outstanding:
            self._rep_count += 1
            if self._rep_count > cfg.max_reps:
                events.append(LinkDown("no answer to REP", len(self._outstanding)))
                events.extend(self.start(now_ns))
            else:
                events.append(RepSent(self._n, self._rep_count))
                events.append(_control_tx(rep, self._n, cfg.address))
                self._timer_ns = now_ns + cfg.rep_timeout_ns
        else:
            self._timer_ns = None
        return events

    # --- internals -----------------------------------------------------------------------

    def _reset_sequence(self) -> None:
        self._r = 0
        self._n = 0
        self._a = 0
        self._outstanding: deque[tuple[int, bytes]] = deque()
        self._timer_ns: int | None = None
        self._rep_count = 0
        self._ack_owed_since: int | None = None
        self._nak_sent = False  # one NAK per run of errors (DDCMP's SNAK flag)

    def _ack_due_ns(self) -> int | None:
        if self._ack_owed_since is None:
            return None
        return self._ack_owed_since + self.config.ack_delay_ns

    def _send_owed_ack(self, events: list[Event]) -> None:
        if self._ack_owed_since is not None and self._state is LinkState.RUNNING:
            events.append(_control_tx(ack, self._r, self.config.address))
        self._ack_owed_since = None

    def _go_running(self, events: list[Event]) -> None:
        self._state = LinkState.RUNNING
        self._timer_ns = None
        events.append(LinkUp())

    def _on_frame_error(self, error: FrameError, events: list[Event]) -> None:
        events.append(error)
        reason = error.reason.nak_reason
        if self._state is LinkState.RUNNING and reason is not None and not self._nak_sent:
            self._nak_sent = True
            self._ack_owed_since = None  # the NAK carries RESP = R too
            events.append(_control_tx(nak, self._r, reason, self.config.address))

    def _process_resp(self, resp: int, now_ns: int, events: list[Event]) -> None:
        """Peer acknowledges up to ``resp``; ignore if not within (A, N]."""
        count = (resp - self._a) & 0xFF
        if count == 0 or count > ((self._n - self._a) & 0xFF):
            return
        for _ in range(count):
            self._outstanding.popleft()
        self._a = resp
        self._rep_count = 0
        self._timer_ns = now_ns + self.config.rep_timeout_ns if self._outstanding else None
        events.append(Acknowledged(resp, count))

    def _on_data(self, frame: DataFrame, now_ns: int, events: list[Event]) -> None:
        if self._state is LinkState.ASTRT and frame.resp == 0:
            self._go_running(events)  # the peer's first data implies it got our STACK
        if self._state is not LinkState.RUNNING:
            events.append(Discarded("not_running", frame.num))
            return
        self._nak_sent = False
        self._process_resp(frame.resp, now_ns, events)
        if frame.num == (self._r + 1) & 0xFF:
            self._r = frame.num
            events.append(DataReceived(frame.num, frame.payload))
            if self._ack_owed_since is None:
                self._ack_owed_since = now_ns
        elif (self._r - frame.num) & 0xFF < 128:
            # Already have it (a retransmission): discard, re-acknowledge.
            events.append(Discarded("duplicate", frame.num))
            if self._ack_owed_since is None:
                self._ack_owed_since = now_ns
        else:
            events.append(Discarded("out_of_order", frame.num))

    def _on_control(self, frame: ControlFrame, now_ns: int, events: list[Event]) -> None:
        cfg = self.config
        kind = frame.kind
        state = self._state
        if state is LinkState.HALTED:
            return
        self._nak_sent = False
        if state is LinkState.ISTRT:
            if kind is ControlType.STRT:
                self._state = LinkState.ASTRT
                self._timer_ns = now_ns + cfg.start_timeout_ns
                events.append(_control_tx(stack, cfg.address))
            elif kind is ControlType.STACK:
                events.append(_control_tx(ack, 0, cfg.address))
                self._go_running(events)
            return
        if state is LinkState.ASTRT:
            if kind is ControlType.STRT:
                events.append(_control_tx(stack, cfg.address))
            elif kind is ControlType.STACK:
                events.append(_control_tx(ack, 0, cfg.address))
                self._go_running(events)
            elif kind is ControlType.ACK and frame.rcvr == 0:
                self._go_running(events)
            return
        # RUNNING
        if kind is ControlType.ACK:
            self._process_resp(frame.rcvr, now_ns, events)
            self._rep_count = 0
        elif kind is ControlType.NAK:
            self._process_resp(frame.rcvr, now_ns, events)
            self._rep_count = 0
            resent = list(self._outstanding)
            events.append(NakReceived(frame.subtype, frame.rcvr, len(resent)))
            if resent:
                self._ack_owed_since = None
                events.append(_tx(*(DataFrame(n, self._r, p, cfg.address) for n, p in resent)))
                self._timer_ns = now_ns + cfg.rep_timeout_ns
        elif kind is ControlType.REP:
            self._ack_owed_since = None
            if frame.sndr == self._r:
                events.append(_control_tx(ack, self._r, cfg.address))
            else:
                events.append(_control_tx(nak, self._r, NakReason.REP_RESPONSE, cfg.address))
        elif kind is ControlType.STRT:
            # The peer restarted: our sequence state is void. Answer and start again.
            events.append(LinkDown("peer restarted (STRT)", len(self._outstanding)))
            self._reset_sequence()
            self._state = LinkState.ASTRT
            self._timer_ns = now_ns + cfg.start_timeout_ns
            events.append(_control_tx(stack, cfg.address))
        elif kind is ControlType.STACK:
            if self._r == 0 and self._n == 0:
                events.append(_control_tx(ack, 0, cfg.address))  # it missed our ACK(0)
            else:
                # The peer is in start-up while we run on a sequence it has forgotten (it
                # got a STRT we did not send): no ACK of ours can end its start-up. Restart.
                events.append(LinkDown("peer in start-up (STACK while running)", len(self._outstanding)))
                events.extend(self.start(now_ns))
