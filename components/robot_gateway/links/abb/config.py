"""The gateway's config over the ABB EGM link: the safety rules (``GatewayConfig``) with the
link's own fields and EGM's cycle (4 ms, or a multiple: EGMActPose's ``\\SampleRate``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.links.rsi.config import parse_address
from humanpt.runtime.config import Range

EGM_BASE_CYCLE_MS = 4.0  # EGM's sample rate is a multiple of 4 ms


@dataclass(frozen=True)
class AbbConfig(GatewayConfig):
    """The gateway over ABB EGM position guidance. Same safety fields as every link; EGM
    takes absolute targets, so the link keeps one (the session's first fed-back pose plus
    every step) and bounds its lead over the fed-back pose by ``max_lead_mm`` /
    ``max_lead_deg`` (the robot converges to the last target when humanpt goes silent: the
    envelope accounts for that lead, see README)."""

    # Where the gateway listens: the controller's UDPUC transmission protocol sends here
    # (its RemoteAddress and RemotePortNumber); answers go back to the robot's address.
    udp_bind: str = "127.0.0.1:6510"
    cycle_period_ms: Annotated[float, Range(4, 1000, "ms")] = 4.0
    tick_ms: Annotated[float, Range(0.1, 12, "ms")] = 0.5
    # Wait at most this long for the controller's command of the cycle (a quarter of the
    # cycle, at most 2 ms, as over RSI).
    reply_deadline_ms: Annotated[float, Range(0.01, 1000, "ms")] | None = None
    status_timeout_cycles: Annotated[int, Range(1, 1000, "cycles")] = 25
    fault_after_missed: Annotated[int, Range(1, 10000, "cycles")] = 70
    # The frame the steps are given in to the target: the robot base ("base": EGMActPose's
    # correction frame is the base, \\CorrFrame:=wobj0) or the flange ("tool").
    correction_frame: Literal["base", "tool"] = "base"
    # Only datagrams from this host (or host:port) are the robot's (empty: any); the adapter
    # locks onto the first valid EgmRobot's sender as over RSI.
    udp_robot: str = ""
    # How far the target may run ahead of the fed-back pose: the link pulls it back to this.
    max_lead_mm: Annotated[float, Range(0.01, 100, "mm")] = 5.0
    max_lead_deg: Annotated[float, Range(0.01, 30, "deg")] = 2.0
    link: str = "abb"

    def __post_init__(self) -> None:
        if self.reply_deadline_ms is None:
            object.__setattr__(self, "reply_deadline_ms", min(2.0, self.cycle_period_ms / 4.0))
        super().__post_init__()
        n = self.cycle_period_ms / EGM_BASE_CYCLE_MS
        if not (math.isfinite(n) and n >= 1 and abs(n - round(n)) < 1e-9):
            raise ValueError(f"cycle_period_ms must be a multiple of {EGM_BASE_CYCLE_MS:g} ms (EGM's sample rate), "
                             f"got {self.cycle_period_ms}")
        parse_address(self.udp_bind)
        if self.udp_robot and ":" in self.udp_robot:
            parse_address(self.udp_robot)
        if self.correction_frame not in ("base", "tool"):
            raise ValueError(f"correction_frame must be base or tool, got {self.correction_frame!r}")
        for name in ("max_lead_mm", "max_lead_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite value > 0, got {v}")
