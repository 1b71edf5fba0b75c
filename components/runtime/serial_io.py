"""A live-shell adapter for a serial port (pyserial: a device name or a pyserial URL).

Bytes read become ``serial_rx`` inputs (humanpt.SerialChunk, stamped when read); the core's
``serial_tx`` outputs are written to the port.  If the port fails, the adapter logs it and
reopens it every ``reopen_s``; the core sees the silence and acts (a missed cycle, a fault).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import serial

from humanpt.runtime.clock import CLOCK
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.serial")


class SerialAdapter:
    topics_out = ("serial_tx",)

    def __init__(self, url: str, baudrate: int = 38400, *, reopen_s: float = 1.0, read_timeout_s: float = 0.002):
        self.url = url
        self.baudrate = baudrate
        self.reopen_s = reopen_s
        self.read_timeout_s = read_timeout_s
        self._port: serial.SerialBase | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.bytes_in = 0
        self.bytes_out = 0
        self.errors = 0

    def open(self) -> None:
        """Open now (raises serial.SerialException with the port's name on failure)."""
        self._port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=self.read_timeout_s)

    def start(self, put: Callable[[str, object], None]) -> None:
        if self._port is None:
            self.open()
        self._thread = threading.Thread(target=self._read_loop, args=(put,), name="serial-rx", daemon=True)
        self._thread.start()

    def _read_loop(self, put) -> None:
        while not self._stop.is_set():
            port = self._port
            try:
                if port is None:
                    raise serial.SerialException(f"{self.url} is closed")
                data = port.read(max(1, port.in_waiting))
            except (serial.SerialException, OSError) as e:
                self.errors += 1
                log.error("serial port %s failed: %s; reopening in %.1f s", self.url, e, self.reopen_s)
                self._reopen()
                continue
            if data:
                self.bytes_in += len(data)
                put("serial_rx", pb.SerialChunk(header=header(CLOCK.now_ns(), frame_id=self.url), data=data))

    def _reopen(self) -> None:
        with self._lock:
            try:
                if self._port is not None:
                    self._port.close()
            except Exception:  # noqa: BLE001
                pass
            self._port = None
        while not self._stop.wait(self.reopen_s):
            try:
                with self._lock:
                    self.open()
                log.info("serial port %s reopened", self.url)
                return
            except (serial.SerialException, OSError) as e:
                log.debug("serial port %s still failing: %s", self.url, e)

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        with self._lock:
            if self._port is None:
                return  # the port is down: the bytes are lost, as on a broken line
            self._port.write(msg.data)
            self.bytes_out += len(msg.data)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        with self._lock:
            if self._port is not None:
                self._port.close()
                self._port = None
