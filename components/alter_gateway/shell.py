"""alter_gateway's live-shell adapter: the serial port to the robot controller (pyserial).

``port`` is a device (/dev/ttyS0, /dev/ttyUSB0) or a pyserial URL (``rfc2217://host:port``,
``socket://host:port``, ``loop://``); the default is the link sim_robot makes to its pty.
If the port fails the adapter reopens it every second; the core sees the silence (a
``link_down`` event) and the robot, without corrections, holds.
"""

from __future__ import annotations

from humanpt.alter_gateway.config import AlterGatewayConfig
from humanpt.runtime.serial_io import SerialAdapter


def adapters(config: AlterGatewayConfig) -> list[SerialAdapter]:
    """The live shell's adapters (registry ADAPTERS): one serial port, 8N1 at ``baud``."""
    return [SerialAdapter(config.port, config.baud)]
