"""The ALTER link's I/O adapter: the serial port to the robot controller (pyserial).

``port`` is a device (/dev/ttyS0, /dev/ttyUSB0) or a pyserial URL (``rfc2217://host:port``,
``socket://host:port``, ``loop://``); the default is the link sim_robot makes to its pty.
If the port fails, or is not there yet at start (sim_robot not up yet), the adapter logs
it and tries again every second; the core sees the silence (a ``link_down`` event once
it had a link) and the robot, without corrections, holds.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import serial

from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.runtime.serial_io import SerialAdapter

log = logging.getLogger("humanpt.robot_gateway")


class PatientSerialAdapter(SerialAdapter):
    """A SerialAdapter that starts even when its port cannot be opened yet (and retries)."""

    def start(self, put: Callable[[str, object], None]) -> None:
        if self._port is None:
            try:
                self.open()
            except (serial.SerialException, OSError) as e:
                log.warning(
                    "serial port %s not available (%s); retrying every %.1f s",
                    self.url,
                    e,
                    self.reopen_s,
                )
        self._thread = threading.Thread(
            target=self._read_loop, args=(put,), name="serial-rx", daemon=True
        )
        self._thread.start()


def adapters(config: AlterConfig) -> list:
    """The live shell's adapters: one serial port, 8N1 at ``baud``."""
    return [PatientSerialAdapter(config.port, config.baud)]
