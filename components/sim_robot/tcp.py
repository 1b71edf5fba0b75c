"""The simulated controllers' TCP servers: one accept loop for every listening port.

A UR controller serves several TCP ports at once (RTDE on 30004, the Dashboard server on
29999), every client of each. :class:`TcpServers` listens on a set of named addresses
(``{service: "host:port"}``), accepts on all of them in one thread (``select`` over the
listening sockets) and reads each connection in a thread of its own; what to do with a
connection is its handler's (:class:`Handler`). Both the ``sim_robot`` process's adapter
(:class:`humanpt.sim_robot.shell.TcpServerAdapter`) and the in-process server of tests and
``humanpt bench ur`` (:class:`humanpt.sim_robot.ur.RtdeServer`) run on it.
"""

from __future__ import annotations

import logging
import select
import socket
import threading
from collections.abc import Mapping
from typing import Protocol

log = logging.getLogger("humanpt.sim_robot")


class Handler(Protocol):
    """What a server does with its connections (called from its threads). ``peer``: the
    client's "host:port"."""

    def opened(self, service: str, peer: str, conn: socket.socket) -> None: ...

    def received(self, service: str, peer: str, conn: socket.socket, data: bytes) -> bool:
        """Bytes read; False: the server closes this connection."""

    def closed(self, service: str, peer: str, conn: socket.socket) -> None: ...


class TcpServers:
    """Listening sockets at ``binds`` (service -> "host:port"; port 0: a free one, see
    :attr:`addresses`), served by one accept thread and a reader thread per connection.
    A port that cannot be had is an OSError in one line naming the service and the address
    (``what``: who listens, for the message)."""

    def __init__(self, binds: Mapping[str, str], handler: Handler, *, poll_s: float = 0.2, what: str = "sim_robot"):
        from humanpt.robot_gateway.links.rsi.config import parse_address

        self.handler = handler
        self.poll_s = poll_s
        self._listen: dict[socket.socket, str] = {}
        for service, bind in binds.items():
            address = parse_address(bind)
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(address)
            except OSError as e:
                s.close()
                for other in self._listen:
                    other.close()
                raise OSError(f"{what}: cannot listen for {service} at {bind}: {e.strerror or e}") from None
            s.listen(8)
            s.setblocking(False)
            self._listen[s] = service
        # service -> (host, port) listened at (port 0: the one the system chose)
        self.addresses: dict[str, tuple[str, int]] = {v: s.getsockname()[:2] for s, v in self._listen.items()}
        self.conns: dict[tuple[str, str], socket.socket] = {}  # (service, peer) -> its connection
        self.lock = threading.Lock()  # (guards conns)
        self._stop = threading.Event()
        self._accept: threading.Thread | None = None
        self._threads: list[threading.Thread] = []  # the readers
        self.connections = 0

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def start(self) -> TcpServers:
        self._accept = threading.Thread(target=self._accept_loop, name="tcp-accept", daemon=True)
        self._accept.start()
        return self

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select(list(self._listen), [], [], self.poll_s)
            except (OSError, ValueError):  # (closed)
                return
            for s in ready:
                try:
                    conn, addr = s.accept()
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError:
                    return
                service = self._listen[s]
                conn.setblocking(True)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                conn.settimeout(self.poll_s)
                peer = "{}:{}".format(*addr[:2])
                self.connections += 1
                with self.lock:
                    self.conns[(service, peer)] = conn
                try:
                    self.handler.opened(service, peer, conn)
                except OSError as e:  # (a client gone at once)
                    log.info("sim_robot: %s client %s: %s", service, peer, e)
                t = threading.Thread(target=self._read, args=(service, peer, conn), name=f"tcp-{service}",
                                     daemon=True)
                t.start()
                self._threads = [x for x in self._threads if x.is_alive()] + [t]

    def _read(self, service: str, peer: str, conn: socket.socket) -> None:
        try:
            while not self._stop.is_set():
                try:
                    data = conn.recv(65536)
                except TimeoutError:
                    continue
                if not data or self.handler.received(service, peer, conn, data) is False:
                    break
        except OSError as e:
            log.info("sim_robot: %s client %s: %s", service, peer, e)
        finally:
            with self.lock:
                if self.conns.get((service, peer)) is conn:
                    del self.conns[(service, peer)]
            try:
                self.handler.closed(service, peer, conn)
            finally:
                conn.close()

    def connection(self, service: str, peer: str) -> socket.socket | None:
        with self.lock:
            return self.conns.get((service, peer))

    def drop(self, conn: socket.socket) -> None:
        """End a connection (its reader sees the end and closes it)."""
        try:
            conn.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass

    def drop_all(self) -> None:
        with self.lock:
            conns = list(self.conns.values())
        for conn in conns:
            self.drop(conn)

    def close(self) -> None:
        self._stop.set()
        for s in self._listen:
            s.close()
        if self._accept is not None:
            self._accept.join(timeout=2.0)
        self.drop_all()
        for t in list(self._threads):
            t.join(timeout=2.0)
