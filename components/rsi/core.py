"""The gateway core (pure) over a KUKA RSI-style link: ``udp_rx`` datagrams in (a
``<Rob>`` per robot cycle), ``udp_tx`` datagrams out (the ``<Sen>`` answer echoing the
IPOC), the same safety rules as over ALTER (humanpt.alter_gateway.core.GatewayCore),
the same topics (``alter_gateway/robot_state``, ``alter_gateway/events``)."""

from __future__ import annotations

from humanpt.alter_gateway.core import WATCH, GatewayCore, gateway_ports
from humanpt.rsi.config import RsiGatewayConfig
from humanpt.rsi.link import RsiLink


class RsiGatewayCore(GatewayCore):
    name = "alter_gateway"  # one gateway component whatever its link (topics unchanged)
    config_type = RsiGatewayConfig
    ports = gateway_ports(RsiLink.rx_topic)
    watch = WATCH

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def make_link(self, config: RsiGatewayConfig) -> RsiLink:
        return RsiLink(config.cycle_period_ms, config.correction_frame, config.sen_type)
