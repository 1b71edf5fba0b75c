"""sim_robot's live-shell adapter: the master side of a pseudo-terminal pair.

``humanpt sim_robot`` opens a pty pair (``os.openpty``, raw mode), points the symlink
``pty_link`` (default ``/tmp/humanpt-alter``) at the slave side and serves the master side:
bytes read become ``serial_rx`` inputs, ``serial_tx`` outputs are written. The gateway
opens ``pty_link`` as its ``port`` (pyserial), exactly as it would open /dev/ttyS0.

A pty has no baud rate: bytes cross at once. Writes never block the core: if nobody reads
the slave and the pty buffer is full, bytes are dropped (counted), as on a line whose far
end is unplugged.
"""

from __future__ import annotations

import errno
import logging
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.sim_robot.config import SimRobotConfig

log = logging.getLogger("humanpt.sim_robot")


class PtyAdapter:
    """The master end of a fresh pty pair, with ``link`` -> the slave's device path."""

    topics_out = ("serial_tx",)

    def __init__(self, link: str | Path, *, poll_s: float = 0.05):
        self.link = Path(link)
        self.poll_s = poll_s
        self.master_fd, self._slave_fd = os.openpty()
        # Raw: no echo, no line discipline, 8-bit clean (the pty's termios is shared).
        tty.setraw(self.master_fd)
        tty.setraw(self._slave_fd)
        os.set_blocking(self.master_fd, False)
        self.slave_path = os.ttyname(self._slave_fd)
        self._make_link()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_in = 0
        self.bytes_out = 0
        self.bytes_dropped = 0

    def _make_link(self) -> None:
        if self.link.exists() and not self.link.is_symlink():
            raise FileExistsError(
                f"pty_link {self.link} exists and is not a symlink; not replacing it"
            )
        self.link.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.link.with_name(f".{self.link.name}.{os.getpid()}")
        if tmp.is_symlink():
            tmp.unlink()
        os.symlink(self.slave_path, tmp)
        os.replace(tmp, self.link)  # atomic: a gateway never sees the link missing
        log.info("sim_robot: serial pty %s, linked from %s", self.slave_path, self.link)

    def start(self, put: Callable[[str, object], None]) -> None:
        self._thread = threading.Thread(
            target=self._read_loop, args=(put,), name="pty-rx", daemon=True
        )
        self._thread.start()

    def _read_loop(self, put) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self.master_fd], [], [], self.poll_s)
                if not ready:
                    continue
                data = os.read(self.master_fd, 4096)
            except BlockingIOError:
                continue
            except OSError as e:
                if self._stop.is_set() or e.errno == errno.EBADF:
                    return
                log.error("pty read failed: %s", e)
                self._stop.wait(self.poll_s)
                continue
            if data:
                self.bytes_in += len(data)
                put(
                    "serial_rx",
                    pb.SerialChunk(
                        header=header(time.time_ns(), frame_id=str(self.link)), data=data
                    ),
                )

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        data = memoryview(msg.data)
        while data:
            try:
                n = os.write(self.master_fd, data)
            except BlockingIOError:
                self.bytes_dropped += len(data)
                return
            except OSError as e:
                if e.errno in (errno.EIO, errno.EBADF):
                    self.bytes_dropped += len(data)
                    return
                raise
            self.bytes_out += n
            data = data[n:]

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        try:
            if self.link.is_symlink() and os.readlink(self.link) == self.slave_path:
                self.link.unlink()
        except OSError:
            pass
        for fd in (self.master_fd, self._slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass


class TcpServerAdapter:
    """The simulated UR's TCP servers: RTDE at ``bind`` ("host:port") and, with
    ``dashboard``, the Dashboard server there, on one accept loop
    (:class:`humanpt.sim_robot.tcp.TcpServers`); every client of each at once, as a UR
    controller serves them (the gateway, and any other: a second client is refused the
    gateway's registers by the controller, IN_USE). Each accepted connection is first marked
    by an EMPTY ``serial_rx`` chunk (frame_id = the client's "host:port", a Dashboard client's
    "dashboard host:port" (:data:`humanpt.sim_robot.ur.DASHBOARD`): the core starts a fresh
    session for it; TCP never delivers an empty read as data), then every read is a
    ``serial_rx`` chunk with that frame_id, and its end an empty chunk from "<frame_id> closed"
    (:data:`humanpt.sim_robot.ur.CLOSED`). ``serial_tx`` goes to the client its frame_id names
    (an empty one: the latest RTDE client's; lost while there is none); an empty ``serial_tx``
    chunk closes that client's connection (the controller drops it)."""

    topics_out = ("serial_tx",)

    def __init__(self, bind: str, *, dashboard: str | None = None, poll_s: float = 0.2):
        from humanpt.sim_robot.tcp import TcpServers

        binds = {"RTDE": bind} if dashboard is None else {"RTDE": bind, "Dashboard": dashboard}
        self.tcp = TcpServers(binds, self, poll_s=poll_s)
        self.address = self.tcp.addresses["RTDE"]
        self.dashboard_address = self.tcp.addresses.get("Dashboard")
        self._put: Callable[[str, object], None] | None = None
        self._latest = ""
        self.bytes_in = 0
        self.bytes_out = 0
        self.bytes_dropped = 0
        log.info("sim_robot: RTDE server at %s:%d", *self.address)
        if self.dashboard_address is not None:
            log.info("sim_robot: Dashboard server at %s:%d", *self.dashboard_address)

    @property
    def connections(self) -> int:
        return self.tcp.connections

    def start(self, put: Callable[[str, object], None]) -> None:
        self._put = put
        self.tcp.start()

    @staticmethod
    def _frame_id(service: str, peer: str) -> str:
        from humanpt.sim_robot.ur import DASHBOARD

        return peer if service == "RTDE" else DASHBOARD + peer

    def _chunk(self, frame_id: str, data: bytes) -> None:
        assert self._put is not None
        self._put("serial_rx", pb.SerialChunk(header=header(time.time_ns(), frame_id=frame_id), data=data))

    # -- the connections (humanpt.sim_robot.tcp.Handler) ------------------------------------------
    def opened(self, service: str, peer: str, conn) -> None:
        log.info("sim_robot: %s client %s (connection %d)", service, peer, self.tcp.connections)
        if service == "RTDE":
            self._latest = peer
        self._chunk(self._frame_id(service, peer), b"")

    def received(self, service: str, peer: str, conn, data: bytes) -> bool:
        self.bytes_in += len(data)
        self._chunk(self._frame_id(service, peer), data)
        return True

    def closed(self, service: str, peer: str, conn) -> None:
        from humanpt.sim_robot.ur import CLOSED

        if not self.tcp.stopping:
            self._chunk(self._frame_id(service, peer) + CLOSED, b"")

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        from humanpt.sim_robot.ur import DASHBOARD

        frame_id = msg.header.frame_id or self._latest
        service, peer = ("Dashboard", frame_id.removeprefix(DASHBOARD)) if frame_id.startswith(DASHBOARD) \
            else ("RTDE", frame_id)
        conn = self.tcp.connection(service, peer)
        if conn is None:
            self.bytes_dropped += len(msg.data)
            return
        try:
            if not msg.data:  # the controller drops this client
                self.tcp.drop(conn)
                return
            conn.sendall(msg.data)
            self.bytes_out += len(msg.data)
        except OSError:
            self.bytes_dropped += len(msg.data)

    def close(self) -> None:
        self.tcp.close()


def adapters(config: SimRobotConfig) -> list:
    """The live shell's adapters (registry ADAPTERS): the pty, linked at ``pty_link``; over
    RSI (``protocol = "rsi"``) a UDP socket on an ephemeral loopback port that sends each
    ``<Rob>`` to ``rsi_gateway`` and takes answers only from there; over EGM the same to
    ``egm_gateway``; over RTDE TCP servers at ``rtde_bind`` and ``dashboard_bind``
    (:class:`TcpServerAdapter`)."""
    if config.protocol == "rsi":
        from humanpt.robot_gateway.links.rsi.shell import UdpAdapter

        return [UdpAdapter("127.0.0.1:0", robot=config.rsi_gateway, peer=config.rsi_gateway)]
    if config.protocol == "egm":  # the same socket, to and from the EGM gateway
        from humanpt.robot_gateway.links.rsi.shell import UdpAdapter

        return [UdpAdapter("127.0.0.1:0", robot=config.egm_gateway, peer=config.egm_gateway)]
    if config.protocol == "rtde":  # the UR's RTDE and Dashboard servers; the gateway connects to RTDE
        return [TcpServerAdapter(config.rtde_bind, dashboard=config.dashboard_address)]
    return [PtyAdapter(config.pty_link)]
