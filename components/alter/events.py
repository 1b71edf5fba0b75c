"""Events the ALTER codec returns. Small frozen dataclasses; the shell acts on them.

Every call into the link or an endpoint returns ``list[Event]`` in the order things
happened. ``Transmit`` carries bytes the shell must write to the serial port, in order.
"""

from __future__ import annotations

from dataclasses import dataclass

from humanpt.alter.ddcmp import FrameError
from humanpt.alter.messages import ControllerStatus, Correction


@dataclass(frozen=True)
class Transmit:
    """Bytes to write to the line now (one or more whole frames)."""

    data: bytes


@dataclass(frozen=True)
class LinkUp:
    """Start-up (STRT/STACK/ACK) completed; data may flow. Sequence numbers start at 0."""


@dataclass(frozen=True)
class LinkDown:
    """The link left RUNNING. ``unacked``: data messages sent but never acknowledged (lost)."""

    reason: str
    unacked: int = 0


@dataclass(frozen=True)
class DataReceived:
    """An in-sequence data message (link level; endpoints turn it into an app event)."""

    num: int
    payload: bytes


@dataclass(frozen=True)
class Acknowledged:
    """The peer acknowledged our data messages up to and including ``num``."""

    num: int
    count: int


@dataclass(frozen=True)
class NakReceived:
    """The peer NAKed; ``reason`` is the raw DDCMP code, ``resent`` messages went again."""

    reason: int
    resp: int
    resent: int


@dataclass(frozen=True)
class RepSent:
    """The reply timer expired with data outstanding; we asked the peer (REP)."""

    num: int
    consecutive: int


@dataclass(frozen=True)
class Discarded:
    """A valid frame that was not accepted. ``why``: duplicate, out_of_order,
    wrong_address, not_running."""

    why: str
    num: int | None = None


@dataclass(frozen=True)
class SendRejected:
    """``send`` could not queue the message (link not running, window full)."""

    why: str


@dataclass(frozen=True)
class StatusReceived:
    """Host side: the controller's per-cycle status, decoded and validated."""

    status: ControllerStatus


@dataclass(frozen=True)
class CorrectionReceived:
    """Controller side: a validated correction for a cycle this controller issued.

    ``age_cycles``: how many cycles ago the echoed cycle was issued (0 = the latest).
    """

    correction: Correction
    age_cycles: int


@dataclass(frozen=True)
class MessageRejected:
    """An in-sequence data message whose content failed validation (dropped)."""

    why: str


Event = (
    Transmit
    | LinkUp
    | LinkDown
    | DataReceived
    | Acknowledged
    | NakReceived
    | RepSent
    | Discarded
    | SendRejected
    | FrameError
    | StatusReceived
    | CorrectionReceived
    | MessageRejected
)
