"""Two tiny components that exercise the runtime end to end (``humanpt up --profile selftest``).

``pinger`` publishes a Tick on ``pinger/ping`` every ``period_ms``; ``ponger`` answers each
ping with an Event on ``ponger/pong`` that carries the ping's sequence number.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from humanpt.runtime.config import Range, live
from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb


@dataclass(frozen=True)
class PingerConfig:
    period_ms: Annotated[float, Range(1, 60000, "ms")] = live(100.0, "ping period")
    payload_note: str = "ping"

    def __post_init__(self):
        if not 1.0 <= self.period_ms <= 60_000.0:
            raise ValueError(f"period_ms must be within 1 and 60000, got {self.period_ms}")


class PingerCore(Core):
    name = "pinger"
    config_type = PingerConfig
    ports = (Port("tick", pb.Tick, "_on_tick"),)

    def tick_period_ns(self) -> int | None:
        return int(self.config.period_ms * 1e6)

    def _on_tick(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        return [("pinger/ping", pb.Tick(header=self.next_header("pinger/ping", t_ns, self.config.payload_note),
                                        period_ns=self.tick_period_ns()))]


@dataclass(frozen=True)
class PongerConfig:
    prefix: str = live("pong", "text before the ping's sequence number")


class PongerCore(Core):
    name = "ponger"
    config_type = PongerConfig
    ports = (Port("pinger/ping", pb.Tick, "_on_ping"),)

    def __init__(self, config: PongerConfig):
        super().__init__(config)
        self.pings = 0

    def _on_ping(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        self.pings += 1
        text = f"{self.config.prefix} {msg.header.seq} (#{self.pings})"
        return [("ponger/pong", pb.Event(header=self.next_header("ponger/pong", msg.header.stamp_ns),
                                       severity=pb.SEVERITY_DEBUG, source=self.name, code="pong", text=text))]
