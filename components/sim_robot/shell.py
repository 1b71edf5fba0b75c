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
    """The simulated UR's RTDE server: listens at ``bind`` ("host:port") and serves every
    client at once, as a UR controller does (the gateway, and any other: a second client is
    refused the gateway's registers by the controller, IN_USE). Each accepted connection is
    first marked by an EMPTY ``serial_rx`` chunk (frame_id = the client's "host:port": the
    core starts a fresh RTDE session for it; TCP never delivers an empty read as data), then
    every read is a ``serial_rx`` chunk with that frame_id, and its end an empty chunk from
    "<host:port> closed" (:data:`humanpt.sim_robot.ur.CLOSED`). ``serial_tx`` goes to the client
    its frame_id names (an empty one: the latest client's; lost while there is none); an empty
    ``serial_tx`` chunk closes that client's connection (the controller drops it)."""

    topics_out = ("serial_tx",)

    def __init__(self, bind: str, *, poll_s: float = 0.2):
        import socket

        from humanpt.robot_gateway.links.rsi.config import parse_address

        self.address = parse_address(bind)
        self.poll_s = poll_s
        self._listen = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listen.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listen.bind(self.address)
        except OSError as e:
            self._listen.close()
            raise OSError(f"sim_robot: cannot listen for RTDE at {bind}: {e.strerror or e}") from None
        self._listen.listen(8)
        self._listen.settimeout(poll_s)
        self.address = self._listen.getsockname()[:2]  # (port 0: the one the system chose)
        self._conns: dict = {}  # client "host:port" -> its socket
        self._latest = ""
        self._wlock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._readers: list[threading.Thread] = []
        self.connections = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self.bytes_dropped = 0
        log.info("sim_robot: RTDE server at %s:%d", *self.address)

    def start(self, put: Callable[[str, object], None]) -> None:
        self._thread = threading.Thread(target=self._loop, args=(put,), name="rtde-server", daemon=True)
        self._thread.start()

    def _loop(self, put) -> None:
        import socket

        while not self._stop.is_set():
            try:
                conn, peer = self._listen.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(self.poll_s)
            self.connections += 1
            frame_id = "{}:{}".format(*peer[:2])
            log.info("sim_robot: RTDE client %s (connection %d)", frame_id, self.connections)
            with self._wlock:
                self._conns[frame_id] = conn
                self._latest = frame_id
            put("serial_rx", pb.SerialChunk(header=header(time.time_ns(), frame_id=frame_id), data=b""))
            reader = threading.Thread(target=self._read, args=(conn, frame_id, put), name="rtde-client", daemon=True)
            reader.start()
            self._readers = [t for t in self._readers if t.is_alive()] + [reader]

    def _read(self, conn, frame_id: str, put) -> None:
        from humanpt.sim_robot.ur import CLOSED

        try:
            while not self._stop.is_set():
                try:
                    data = conn.recv(65536)
                except TimeoutError:
                    continue
                if not data:
                    break
                self.bytes_in += len(data)
                put("serial_rx", pb.SerialChunk(header=header(time.time_ns(), frame_id=frame_id), data=data))
        except OSError as e:
            log.info("sim_robot: RTDE client %s: %s", frame_id, e)
        finally:
            with self._wlock:
                if self._conns.get(frame_id) is conn:
                    del self._conns[frame_id]
            conn.close()
            if not self._stop.is_set():
                put("serial_rx", pb.SerialChunk(header=header(time.time_ns(), frame_id=frame_id + CLOSED), data=b""))

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        import socket

        with self._wlock:
            conn = self._conns.get(msg.header.frame_id or self._latest)
        if conn is None:
            self.bytes_dropped += len(msg.data)
            return
        try:
            if not msg.data:  # the controller drops this client
                conn.shutdown(socket.SHUT_RDWR)
                return
            conn.sendall(msg.data)
            self.bytes_out += len(msg.data)
        except OSError:
            self.bytes_dropped += len(msg.data)

    def close(self) -> None:
        self._stop.set()
        self._listen.close()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for t in self._readers:
            t.join(timeout=2.0)


def adapters(config: SimRobotConfig) -> list:
    """The live shell's adapters (registry ADAPTERS): the pty, linked at ``pty_link``; over
    RSI (``protocol = "rsi"``) a UDP socket on an ephemeral loopback port that sends each
    ``<Rob>`` to ``rsi_gateway`` and takes answers only from there; over EGM the same to
    ``egm_gateway``; over RTDE a TCP server at ``rtde_bind`` (:class:`TcpServerAdapter`)."""
    if config.protocol == "rsi":
        from humanpt.robot_gateway.links.rsi.shell import UdpAdapter

        return [UdpAdapter("127.0.0.1:0", robot=config.rsi_gateway, peer=config.rsi_gateway)]
    if config.protocol == "egm":  # the same socket, to and from the EGM gateway
        from humanpt.robot_gateway.links.rsi.shell import UdpAdapter

        return [UdpAdapter("127.0.0.1:0", robot=config.egm_gateway, peer=config.egm_gateway)]
    if config.protocol == "rtde":  # the UR's RTDE server; the gateway connects to it
        return [TcpServerAdapter(config.rtde_bind)]
    return [PtyAdapter(config.pty_link)]
