"""The gateway's config over the UR RTDE link: the safety rules (``GatewayConfig``) with the
link's own fields and RTDE's cycle (2 ms: 500 Hz on an e-Series; 8 ms: 125 Hz on a CB3)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.links.rsi.config import parse_address
from humanpt.runtime.config import Range, live

# RTDE's output frequencies: 500 Hz on an e-Series, 125 Hz on a CB3; a divisor of either.
E_SERIES_CYCLE_MS = 2.0
CB3_CYCLE_MS = 8.0
REGISTER_RANGE = (24, 47)  # UR's general-purpose registers (0..23: the fieldbus adapters')
INPUT_DOUBLES = 6  # the target pose: x, y, z (m), rx, ry, rz (rotation vector, rad)
STALE_MS = 24.0  # the staleness bound's default (README: "The staleness bound")


@dataclass(frozen=True)
class UrConfig(GatewayConfig):
    """The gateway over UR RTDE. Same safety fields as every link. The gateway is RTDE's
    client: it connects to the controller (``rtde_address``, port 30004), asks for the state
    every cycle and writes, each cycle, a sequence number and the ABSOLUTE target pose to
    input registers that humanpt's URScript program (``humanpt robot-files``) reads and
    servoes to. As over ABB EGM the link keeps the target and bounds its lead over the
    fed-back pose by ``max_lead_mm`` / ``max_lead_deg``."""

    rtde_address: str = "127.0.0.1:30004"
    cycle_period_ms: Annotated[float, Range(2, 1000, "ms")] = E_SERIES_CYCLE_MS
    tick_ms: Annotated[float, Range(0.1, 12, "ms")] = 0.5
    reply_deadline_ms: Annotated[float, Range(0.01, 1000, "ms")] | None = None
    status_timeout_cycles: Annotated[int, Range(1, 1000, "cycles")] = 50
    fault_after_missed: Annotated[int, Range(1, 10000, "cycles")] = 100
    # The first register of humanpt's: input_int_register_<n> the sequence number,
    # input_double_register_<n>..<n+5> the target; output_int_register_<n> the program's
    # heartbeat (+1 every program cycle), output_int_register_<n+1> the last sequence it took.
    register_base: Annotated[int, Range(24, 42, "")] = 24
    # The URScript program's watchdog: the sequence not advancing for this many of its
    # cycles stops the arm (stopl) and waits for a sequence newer than the one it stopped at.
    watchdog_cycles: Annotated[int, Range(1, 1000, "cycles")] = 25
    # The heartbeat not advancing for this many received cycles: corrections off.
    heartbeat_cycles: Annotated[int, Range(1, 1000, "cycles")] = 25
    correction_frame: Literal["base", "tool"] = "base"
    max_lead_mm: Annotated[float, Range(0.01, 100, "mm")] = 5.0
    max_lead_deg: Annotated[float, Range(0.01, 30, "deg")] = 2.0
    # The staleness bound in time (README: "The staleness bound"): with no command for a cycle,
    # the gateway answers with the freshest one at most this old (velocity hold), then holds;
    # a command arriving later than this after its cycle is dropped. At most the program's
    # watchdog (watchdog_cycles x cycle): the gateway never runs on longer than the robot would.
    stale_ms: Annotated[float, Range(0, 2000, "ms")] = STALE_MS
    # Over UR the bound in cycles is floor(stale_ms / cycle_period_ms) unless given (as on
    # every link; ``humanpt param`` may only lower it).
    stale_cycles: Annotated[int, Range(0, 100, "cycles")] | None = live(
        None, "cycles a command may be reused before it is stale (over UR: from stale_ms)", stricter="lower")
    link: str = "ur"

    def __post_init__(self) -> None:
        if self.reply_deadline_ms is None:
            object.__setattr__(self, "reply_deadline_ms", min(1.0, self.cycle_period_ms / 4.0))
        v = self.stale_ms
        if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and v >= 0.0):
            raise ValueError(f"stale_ms must be a finite number of ms >= 0, got {v!r}")
        watchdog_ms = self.watchdog_cycles * self.cycle_period_ms if isinstance(self.watchdog_cycles, int) else None
        if watchdog_ms is not None and v > watchdog_ms:
            raise ValueError(f"stale_ms = {v:g} is longer than the robot program's watchdog (watchdog_cycles x "
                             f"cycle_period_ms = {watchdog_ms:g} ms): the gateway would run the arm on without "
                             "the controller longer than the robot runs it on without the gateway")
        if self.stale_cycles is None:
            n = self.cycle_period_ms
            object.__setattr__(self, "stale_cycles", int(math.floor(v / n + 1e-9)) if n > 0 else 0)
        super().__post_init__()
        n = self.cycle_period_ms / E_SERIES_CYCLE_MS
        if not (math.isfinite(n) and n >= 1 and abs(n - round(n)) < 1e-9):
            raise ValueError(f"cycle_period_ms must be a multiple of {E_SERIES_CYCLE_MS:g} ms (RTDE at 500 Hz or "
                             f"a divisor of it; 8 ms on a CB3), got {self.cycle_period_ms}")
        parse_address(self.rtde_address)
        lo, hi = REGISTER_RANGE
        if not (isinstance(self.register_base, int) and lo <= self.register_base <= hi + 1 - INPUT_DOUBLES):
            raise ValueError(f"register_base must be within {lo} and {hi + 1 - INPUT_DOUBLES}, got "
                             f"{self.register_base!r}")
        if self.correction_frame not in ("base", "tool"):
            raise ValueError(f"correction_frame must be base or tool, got {self.correction_frame!r}")
        for name in ("max_lead_mm", "max_lead_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite value > 0, got {v}")
        for name in ("watchdog_cycles", "heartbeat_cycles"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 1 <= v <= 1000):
                raise ValueError(f"{name} must be within 1 and 1000, got {v!r}")
