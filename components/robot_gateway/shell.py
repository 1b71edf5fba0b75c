"""robot_gateway's live-shell adapters: its link's (a serial port for ALTER, a UDP socket
for RSI), from the link registry (``links.LINKS``)."""

from __future__ import annotations

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.links import link_kind


def adapters(config: GatewayConfig) -> list:
    """The live shell's adapters (runtime.registry ADAPTERS): the link's I/O adapter."""
    return link_kind(config.link).adapters(config)
