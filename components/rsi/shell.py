"""The RSI gateway's live-shell adapter: a UDP socket on a thread of its own.

Datagrams read (from the robot's address, ``udp_robot``, if set) become ``udp_rx`` inputs (humanpt.SerialChunk, stamped when read, frame_id
= the sender's host:port); the core's ``udp_tx`` outputs go back to the sender of the
latest datagram (the robot). The socket never waits behind bus traffic: the read loop is
its own thread and puts straight into the shell's input queue (local inputs go first).
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable

from humanpt.rsi.config import RsiGatewayConfig, parse_address
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.rsi")


class UdpAdapter:
    topics_out = ("udp_tx",)

    def __init__(self, bind: str, *, robot: str = "", rx_topic: str = "udp_rx", poll_s: float = 0.2,
                 peer: str = ""):
        """``robot``: "host" or "host:port" the datagrams must come from ("": any);
        ``peer``: "host:port" to send to before anything arrived (the simulated robot's
        gateway; "": answer only, the gateway's way)."""
        self.bind = bind
        host, _, port = robot.rpartition(":") if ":" in robot else (robot, "", "")
        self._robot_host, self._robot_port = host or None, int(port) if port else None
        self.rejected = 0
        self.rx_topic = rx_topic
        self.poll_s = poll_s
        self._sock: socket.socket | None = None
        self._peer: tuple[str, int] | None = parse_address(peer) if peer else None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.datagrams_in = 0
        self.datagrams_out = 0
        self.errors = 0

    def open(self) -> None:
        """Bind now (OSError names the address on failure)."""
        host, port = parse_address(self.bind)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((host, port))
        except OSError as e:
            sock.close()
            raise OSError(f"cannot bind UDP {self.bind}: {e.strerror or e}") from None
        sock.settimeout(self.poll_s)
        self._sock = sock

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port) (port 0 in the config: the one the system chose)."""
        assert self._sock is not None, "not open"
        return self._sock.getsockname()

    def start(self, put: Callable[[str, object], None]) -> None:
        if self._sock is None:
            self.open()
        self._thread = threading.Thread(target=self._read_loop, args=(put,), name="udp-rx", daemon=True)
        self._thread.start()

    def _read_loop(self, put) -> None:
        sock = self._sock
        while not self._stop.is_set():
            try:
                data, peer = sock.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError as e:
                if self._stop.is_set():
                    return
                self.errors += 1
                log.error("UDP %s: %s", self.bind, e)
                time.sleep(self.poll_s)  # a socket error (not a wait for data): do not spin
                continue
            stamp = time.time_ns()
            if ((self._robot_host is not None and peer[0] != self._robot_host)
                    or (self._robot_port is not None and peer[1] != self._robot_port)):
                self.rejected += 1
                if self.rejected == 1 or self.rejected % 1000 == 0:
                    log.warning("UDP %s: datagram from %s:%d dropped: not the robot (%d so far)",
                                self.bind, peer[0], peer[1], self.rejected)
                continue
            self._peer = peer
            self.datagrams_in += 1
            put(self.rx_topic, pb.SerialChunk(header=header(stamp, frame_id=f"{peer[0]}:{peer[1]}"), data=data))

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        peer, sock = self._peer, self._sock
        if peer is None or sock is None:
            return  # nobody to answer yet: lost, as a datagram to nowhere
        try:
            sock.sendto(msg.data, peer)
            self.datagrams_out += 1
        except OSError as e:
            self.errors += 1
            log.warning("UDP %s: answer to %s:%d lost: %s", self.bind, peer[0], peer[1], e)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def adapters(config: RsiGatewayConfig) -> list[UdpAdapter]:
    """The live shell's adapters: one UDP socket at ``udp_bind``."""
    return [UdpAdapter(config.udp_bind, robot=config.udp_robot)]
