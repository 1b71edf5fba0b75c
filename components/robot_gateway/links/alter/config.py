"""The gateway's config over the ALTER link: the safety rules (``GatewayConfig``) plus the
serial line (``port``, ``baud``); ALTER's cycle is the paper's 28 ms."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.runtime.config import Range

SUPPORTED_BAUDS = (19_200, 38_400)
# int16 wire units: 327.67 mm or 327.67 deg per cycle at most (messages.py).
WIRE_MAX_PER_CYCLE = 327.67


@dataclass(frozen=True)
class AlterConfig(GatewayConfig):
    """``[robot_gateway]`` with ``link = "alter"`` (the default): the serial port to the
    Puma's controller; the cycle and timers are GatewayConfig's defaults (28 ms, 2 ms)."""

    # Serial device (/dev/ttyS0) or pyserial URL; the default is sim_robot's pty link.
    port: str = "/tmp/humanpt-alter"
    baud: Annotated[int, Range(1200, 115200, "baud")] = 38_400
    wire_max_per_cycle: ClassVar[float | None] = WIRE_MAX_PER_CYCLE

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.port:
            raise ValueError("port must name a serial device or a pyserial URL")
        if self.baud not in SUPPORTED_BAUDS:
            raise ValueError(f"baud must be one of {SUPPORTED_BAUDS} (the ALTER board), got {self.baud}")
