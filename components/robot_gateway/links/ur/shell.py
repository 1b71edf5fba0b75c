"""The UR RTDE link's I/O adapter: a TCP client on a thread of its own.

It connects to the controller (``rtde_address``, port 30004 on a real one) and, on every
connection, first puts an EMPTY ``serial_rx`` chunk (the link's mark of a new stream: it
sets up a session), then every read as a ``serial_rx`` chunk (humanpt.SerialChunk, stamped
when read, frame_id = the controller's host:port); ``serial_tx`` chunks are written to the
connection (lost while there is none). A closed or failed connection is tried again every
``retry_s``; the gateway's silence watchdog reports it (``link_down``). Only the controller
at ``rtde_address`` is ever read: TCP has no other sender.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable

from humanpt.robot_gateway.links.rsi.config import parse_address
from humanpt.robot_gateway.links.ur.config import UrConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.robot_gateway.links.ur")


class TcpClientAdapter:
    topics_out = ("serial_tx",)

    def __init__(self, address: str, *, rx_topic: str = "serial_rx", retry_s: float = 0.2,
                 connect_timeout_s: float = 1.0):
        self.address = parse_address(address)
        self.rx_topic = rx_topic
        self.retry_s = retry_s
        self.connect_timeout_s = connect_timeout_s
        self._sock: socket.socket | None = None
        self._wlock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.connections = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self.errors = 0

    def start(self, put: Callable[[str, object], None]) -> None:
        self._thread = threading.Thread(target=self._loop, args=(put,), name="rtde-rx", daemon=True)
        self._thread.start()

    def _connect(self) -> socket.socket | None:
        try:
            sock = socket.create_connection(self.address, timeout=self.connect_timeout_s)
        except OSError as e:
            self.errors += 1
            if self.errors == 1 or self.errors % 50 == 0:
                log.warning("RTDE %s:%d: cannot connect: %s (%d tries so far); trying again", *self.address,
                            e.strerror or e, self.errors)
            return None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(self.retry_s)
        return sock

    def _loop(self, put) -> None:
        frame_id = "{}:{}".format(*self.address)
        while not self._stop.is_set():
            sock = self._connect()
            if sock is None:
                self._stop.wait(self.retry_s)
                continue
            self.connections += 1
            log.info("RTDE: connected to %s (connection %d)", frame_id, self.connections)
            put(self.rx_topic, pb.SerialChunk(header=header(time.time_ns(), frame_id=frame_id), data=b""))
            with self._wlock:
                self._sock = sock
            try:
                while not self._stop.is_set():
                    try:
                        data = sock.recv(65536)
                    except TimeoutError:
                        continue
                    if not data:
                        log.warning("RTDE %s: the controller closed the connection", frame_id)
                        break
                    self.bytes_in += len(data)
                    put(self.rx_topic, pb.SerialChunk(header=header(time.time_ns(), frame_id=frame_id), data=data))
            except OSError as e:
                if not self._stop.is_set():
                    self.errors += 1
                    log.warning("RTDE %s: %s", frame_id, e)
            finally:
                with self._wlock:
                    self._sock = None
                sock.close()
            self._stop.wait(self.retry_s)

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        with self._wlock:
            sock = self._sock
            if sock is None:
                return  # no connection: lost (the link sets up afresh on the next one)
            try:
                sock.sendall(msg.data)
                self.bytes_out += len(msg.data)
            except OSError as e:
                self.errors += 1
                log.warning("RTDE: write lost: %s", e)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)


def adapters(config: UrConfig) -> list[TcpClientAdapter]:
    """One TCP connection to the controller's RTDE server at ``rtde_address``."""
    return [TcpClientAdapter(config.rtde_address)]
