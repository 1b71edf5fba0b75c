"""The gateway core (pure) over a KUKA RSI-style link: ``udp_rx`` datagrams in (a
``<Rob>`` per robot cycle), ``udp_tx`` datagrams out (the ``<Sen>`` answer echoing the
IPOC), the same safety rules as over ALTER (humanpt.robot_gateway.core.GatewayCore),
the same topics (``robot_gateway/robot_state``, ``robot_gateway/events``)."""

from __future__ import annotations

from typing import Any

from humanpt.robot_gateway.core import WATCH, AlterGatewayCore, GatewayCore, gateway_ports
from humanpt.rsi.config import RsiGatewayConfig
from humanpt.rsi.link import RsiLink


class RsiGatewayCore(GatewayCore):
    name = "robot_gateway"  # one gateway component whatever its link (topics unchanged)
    config_type = RsiGatewayConfig
    ports = gateway_ports(RsiLink.rx_topic)
    watch = WATCH

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def make_link(self, config: RsiGatewayConfig) -> RsiLink:
        return RsiLink(config.cycle_period_ms, config.correction_frame, config.sen_type)

    def late_repeat_cycles(self, config: RsiGatewayConfig) -> int:
        # HOLDON on RKorr repeats the last correction for each late answer until the robot's
        # late limit stops RSI: the envelope keeps the step and as many repeats inside.
        return config.robot_late_limit

    def recording_metadata(self, shell: str, **extra: Any) -> dict[str, Any]:
        # The registry's entry for the component (AlterGatewayCore) rebuilds this core from
        # the recorded config (link = "rsi"): a replay finds the class it knows.
        from humanpt.runtime.registry import class_path

        return super().recording_metadata(shell, **extra) | {"core": class_path(AlterGatewayCore)}
