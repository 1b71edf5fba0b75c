"""The gateway's config over the RSI link: the safety rules (``GatewayConfig``: limits,
envelope, watchdogs) with the RSI link's fields and RSI's cycle times."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.runtime.config import Range, live

RSI_CYCLES_MS = (4.0, 12.0)  # the RSI cycle times (IPO_FAST and IPO modes)


def parse_address(text: str) -> tuple[str, int]:
    """``"host:port"`` -> (host, port); ValueError with the bad text."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"an address must be host:port (port 0..65535), got {text!r}")
    return host, int(port)


@dataclass(frozen=True)
class RsiConfig(GatewayConfig):
    """The gateway over a KUKA RSI-style link (UDP/XML). Same safety fields as over ALTER;
    the per-cycle limits follow the RSI cycle (100 mm/s at 4 ms: 0.4 mm per cycle)."""

    # Where the gateway listens: the robot's RSI configuration sends to this address
    # (its IP_NUMBER and PORT); the answers go back to where each <Rob> came from.
    udp_bind: str = "127.0.0.1:49152"
    cycle_period_ms: Annotated[float, Range(4, 12, "ms")] = 4.0
    tick_ms: Annotated[float, Range(0.1, 12, "ms")] = 0.5
    # The answer must reach the robot within its cycle: wait at most this long for the
    # controller's command of the cycle before answering with the freshest one.
    # Unset: a quarter of the cycle, at most 2 ms (4 ms: 1 ms, 12 ms: 2 ms). At 4 ms the
    # command-ahead chain (robot state -> filter -> controller -> gateway, three bus hops)
    # does not always fit in a cycle, and a wait of 2 ms left too little of it for the
    # answer's way back (issue 22: 97.7 % in time live with 2 ms, 98.9 % with 1 ms); a
    # controller that does not command ahead needs the longer wait at 12 ms.
    reply_deadline_ms: Annotated[float, Range(0.01, 12, "ms")] | None = None
    status_timeout_cycles: Annotated[int, Range(1, 1000, "cycles")] = 25
    # ~0.3 s at 4 ms, as ALTER's 10 cycles are at 28 ms.
    fault_after_missed: Annotated[int, Range(1, 10000, "cycles")] = live(
        70, "consecutive missed cycles that raise a fault", stricter="lower")
    # The robot's RSI correction frame (its ST_PATHCORR / POSCORR reference): RKorr is in
    # the robot base ("base") or the flange ("tool"). Must match the robot's configuration.
    correction_frame: Literal["base", "tool"] = "base"
    # Only datagrams from this host (or host:port) are the robot's; others are dropped (and
    # logged) by the adapter. Empty: any host. Either way the adapter locks onto the host and
    # port of the first valid <Rob> and takes datagrams only from there until that sender has
    # been silent for status_timeout_cycles (shell.PeerLock).
    udp_robot: str = ""
    # The robot's late limit (the RSI ETHERNET object's limit of late answers in a row before
    # RSI stops; required on the robot: as low as the application allows, 10 here). If HOLDON
    # is on for RKorr the robot repeats the last correction for every late answer until then:
    # the gateway keeps each step and this many repeats inside the envelope
    # (pose + (1 + robot_late_limit) x step), so set it >= the robot's limit. 0 only if the
    # robot applies zero when an answer is late (HOLDON="0" on every RKorr element).
    robot_late_limit: Annotated[int, Range(0, 1000, "cycles")] = 10
    sen_type: str = "ImFree"  # <Sen Type=...>: the robot's SENTYPE
    link: str = "rsi"  # ([robot_gateway] link = "rsi" selects this config)

    def __post_init__(self) -> None:
        if self.reply_deadline_ms is None:
            object.__setattr__(self, "reply_deadline_ms", min(2.0, self.cycle_period_ms / 4.0))
        super().__post_init__()
        if self.cycle_period_ms not in RSI_CYCLES_MS:
            raise ValueError(f"cycle_period_ms must be one of {RSI_CYCLES_MS} (RSI), got {self.cycle_period_ms}")
        parse_address(self.udp_bind)
        if self.udp_robot and ":" in self.udp_robot:
            parse_address(self.udp_robot)
        if self.correction_frame not in ("base", "tool"):
            raise ValueError(f"correction_frame must be base or tool, got {self.correction_frame!r}")
        if not 0 <= self.robot_late_limit <= 1000:
            raise ValueError(f"robot_late_limit must be within 0 and 1000 (late answers), got {self.robot_late_limit}")
        if not self.sen_type.isidentifier():
            raise ValueError(f"sen_type must be a plain name, got {self.sen_type!r}")
