"""The gateway's link interface: what a robot link protocol gives the safety rules
(:class:`CycleState` per robot cycle), the events it returns, and what it must do
(:class:`Link`). Implementations, one folder each (``links.LINKS``):
``links.alter.link.AlterLink`` (ALTER, serial) and ``links.rsi.link.RsiLink`` (KUKA
RSI-style, UDP/XML)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True, slots=True, eq=False)
class CycleState:
    """What the robot reported for one of its cycles, whatever the link.

    ``cycle``: the link's cycle number (uint32, +1 per robot cycle); ``base_T_flange_mm``:
    (4, 4) the flange in the robot base frame, mm (read only); ``corrections_on``: the robot
    takes corrections (ALTER active, RSI running); ``tool_mode``: corrections are in the tool
    (flange) frame, else in the base frame; ``correction_missed``: the robot says the answer
    to the previous cycle came too late."""

    cycle: int
    base_T_flange_mm: np.ndarray
    corrections_on: bool
    tool_mode: bool
    cumulative: bool
    arm_power: bool
    fault: bool
    correction_missed: bool


@dataclass(frozen=True, slots=True)
class CycleReceived:
    """Link event: the robot's state for a cycle arrived.  ``age_ns``: how long before the
    bytes' arrival the robot sampled it, by the robot's own clock (0: just now, as one state
    per read gives it; a stream read that holds several states ages the earlier ones)."""

    state: CycleState
    age_ns: int = 0


@dataclass(frozen=True)
class Transmit:
    """Link event: bytes to write to the wire now (whole frames or one datagram)."""

    data: bytes


@dataclass(frozen=True)
class LinkUp:
    """Link event: the link (re)started a session (ALTER: the DDCMP start-up STRT/STACK/ACK
    completed, sequence numbers start at 0; RSI: the first datagram of a session)."""


@dataclass(frozen=True)
class LinkDown:
    """Link event: the link left its running state. ``unacked``: messages sent but never
    acknowledged (lost)."""

    reason: str
    unacked: int = 0


@dataclass(frozen=True)
class RepSent:
    """Link event: the reply timer expired with data outstanding; the link asked the peer
    again (ALTER's DDCMP REP)."""

    num: int
    consecutive: int


@dataclass(frozen=True)
class SendRejected:
    """Link event: ``send`` could not queue the message (link not running, window full)."""

    why: str


@dataclass(frozen=True, slots=True)
class LinkError:
    """Link event: something on the wire could not be used (a bad frame, malformed XML)."""

    text: str


class Link(Protocol):
    """A robot link protocol as the gateway sees it (pure: times are given, never read).

    ``start``/``receive``/``poll``/``send`` return link events: :class:`Transmit` (bytes for
    the wire), :class:`CycleReceived`, :class:`LinkUp`, :class:`LinkDown`, :class:`LinkError`,
    :class:`SendRejected`, :class:`RepSent` (others are ignored). A link is made from its
    config by its kind (``links.LinkKind.make``); its config is a ``GatewayConfig``."""

    name: str  # "ALTER", "RSI": in event texts
    rx_topic: str  # local topic of what the robot sent ("serial_rx", "udp_rx")
    tx_topic: str  # local topic of what the shell sends ("serial_tx", "udp_tx")
    up_text: str  # the link_up event's text

    @property
    def is_running(self) -> bool: ...

    def start(self, t_ns: int) -> list: ...

    def receive(self, data: bytes, t_ns: int) -> list: ...

    def poll(self, t_ns: int) -> list: ...

    def correction(self, cycle: int, dp_mm: np.ndarray, rv_rad: np.ndarray,
                   max_step_mm: float, max_step_deg: float) -> Any:
        """The wire correction for cycle ``cycle``: ``dp_mm`` (3,), ``rv_rad`` (3,) in the
        robot's correction frame, within the limits; quantised so that it stays within."""

    def hold(self, cycle: int, corrections_off: bool) -> Any:
        """The wire's zero correction for ``cycle`` (asking the robot to leave correction
        mode if ``corrections_off`` and the protocol can)."""

    def send(self, correction: Any, t_ns: int) -> list: ...

    # A link with timers of its own (ALTER's DDCMP) also has ``shift_time(step_ns)``: the
    # gateway's clock stepped (runtime/clock.py), each timer keeps the time it had left.
