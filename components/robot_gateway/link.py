"""The gateway's link interface: what a robot link protocol gives the safety rules
(:class:`CycleState` per robot cycle) and what it must do (:class:`Link`). Implementations:
``humanpt.robot_gateway.alter_link.AlterLink`` (ALTER, serial) and
``humanpt.rsi.link.RsiLink`` (KUKA RSI-style, UDP/XML)."""

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
    """Link event: the robot's state for a cycle arrived."""

    state: CycleState


@dataclass(frozen=True, slots=True)
class LinkError:
    """Link event: something on the wire could not be used (a bad frame, malformed XML)."""

    text: str


class Link(Protocol):
    """A robot link protocol as the gateway sees it (pure: times are given, never read).

    ``start``/``receive``/``poll``/``send`` return link events: ``Transmit`` (bytes for the
    wire), :class:`CycleReceived`, ``LinkUp``, ``LinkDown``, :class:`LinkError`,
    ``SendRejected``, ``RepSent`` (the last four from humanpt.alter, shared)."""

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
