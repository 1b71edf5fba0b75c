"""Events the ALTER codec returns. Small frozen dataclasses; the shell acts on them.

Every call into the link or an endpoint returns ``list[Event]`` in the order things
happened. ``Transmit`` carries bytes the shell must write to the serial port, in order.
``Transmit``, ``LinkUp``, ``LinkDown``, ``RepSent`` and ``SendRejected`` are every link's
(``humanpt.robot_gateway.link``); the others are ALTER's.
"""

from __future__ import annotations

from dataclasses import dataclass

from humanpt.robot_gateway.link import LinkDown, LinkUp, RepSent, SendRejected, Transmit
from humanpt.robot_gateway.links.alter.ddcmp import FrameError
from humanpt.robot_gateway.links.alter.messages import ControllerStatus, Correction


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
class Discarded:
    """A valid frame that was not accepted. ``why``: duplicate, out_of_order,
    wrong_address, not_running."""

    why: str
    num: int | None = None


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
