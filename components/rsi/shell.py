"""The RSI gateway's live-shell adapter: a UDP socket on a thread of its own.

Datagrams read from the robot become ``udp_rx`` inputs (humanpt.SerialChunk, stamped when
read, frame_id = the sender's host:port); the core's ``udp_tx`` outputs go back to the
robot only. The socket never waits behind bus traffic: the read loop is its own thread and
puts straight into the shell's input queue (local inputs go first).

Which sender is the robot (issue 29, :class:`PeerLock`): the first datagram from an allowed
host (``udp_robot``: "host" or "host:port"; "" any) that is a valid ``<Rob>`` locks the
adapter onto its host *and port*; from then on only that sender's datagrams reach the core
and answers go only there. Any other datagram is dropped on arrival, before it is parsed
(a comparison of addresses: a flood from elsewhere costs a ``recvfrom`` each). Another
sender can take over only once the locked one has been silent for ``relock_after_ms`` (the
gateway's silence watchdog, ``status_timeout_cycles`` cycles: the gateway has declared
``link_down`` by then), which is how a robot that restarts RSI from another port is found
again.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable

from humanpt.rsi.config import RsiGatewayConfig, parse_address
from humanpt.rsi.protocol import RsiProtocolError, decode_rob
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.rsi")

LOG_INTERVAL_NS = 1_000_000_000  # dropped datagrams are logged at most once a second, with a count


def _is_rob(data: bytes) -> bool:
    try:
        decode_rob(data)
    except RsiProtocolError:
        return False
    return True


class PeerLock:
    """Which sender is the robot (pure: times are given). ``allowed``: "host" or
    "host:port" the robot's datagrams must come from ("": any); ``fixed``: (host, port)
    locked for good (the simulated robot's side: its gateway); ``relock_after_ns``: how long
    the locked sender must be silent before another may take over; ``valid(data)``: whether
    a datagram may start a session (a well-formed ``<Rob>``)."""

    def __init__(self, allowed: str = "", *, fixed: tuple[str, int] | None = None,
                 relock_after_ns: int = 300_000_000, valid: Callable[[bytes], bool] = _is_rob):
        host, _, port = allowed.rpartition(":") if ":" in allowed else (allowed, "", "")
        self.host, self.port = host or None, int(port) if port else None
        self.fixed = fixed is not None
        self.peer: tuple[str, int] | None = fixed
        self.relock_after_ns = relock_after_ns
        self.valid = valid
        self._last_ns: int | None = None
        self.counters = dict.fromkeys(("not_robot", "not_peer", "invalid", "locks"), 0)

    def accept(self, peer: tuple[str, int], data: bytes, t_ns: int) -> bool:
        """Whether the datagram ``data`` from ``peer`` at ``t_ns`` is the robot's (and may
        lock onto it). The locked sender's datagrams are accepted without looking at them."""
        if peer == self.peer:
            self._last_ns = t_ns
            return True
        if (self.host is not None and peer[0] != self.host) or (self.port is not None and peer[1] != self.port):
            self.counters["not_robot"] += 1
            return False
        if self.fixed or (self.peer is not None and self._last_ns is not None
                          and t_ns - self._last_ns < self.relock_after_ns):
            self.counters["not_peer"] += 1
            return False
        if not self.valid(data):  # only while nobody (or a silent sender) holds the lock
            self.counters["invalid"] += 1
            return False
        self.peer, self._last_ns = peer, t_ns
        self.counters["locks"] += 1
        return True

    @property
    def rejected(self) -> int:
        return self.counters["not_robot"] + self.counters["not_peer"] + self.counters["invalid"]


class UdpAdapter:
    topics_out = ("udp_tx",)

    def __init__(self, bind: str, *, robot: str = "", rx_topic: str = "udp_rx", poll_s: float = 0.2,
                 peer: str = "", relock_after_ms: float = 300.0):
        """``robot``: "host" or "host:port" the datagrams must come from ("": any);
        ``peer``: "host:port" to send to and take datagrams from only, for good (the
        simulated robot's side: its gateway); "": the first valid ``<Rob>`` locks
        (:class:`PeerLock`), the gateway's way; ``relock_after_ms``: how long the locked
        sender must be silent before another may take over."""
        self.bind = bind
        self.lock = PeerLock(robot, fixed=parse_address(peer) if peer else None,
                             relock_after_ns=round(relock_after_ms * 1e6))
        self.rx_topic = rx_topic
        self.poll_s = poll_s
        self._sock: socket.socket | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.datagrams_in = 0
        self.datagrams_out = 0
        self.errors = 0
        self._logged_ns = -LOG_INTERVAL_NS
        self._logged_rejected = 0

    @property
    def rejected(self) -> int:
        """Datagrams dropped on arrival: not from the robot's host, not the locked sender,
        or (while unlocked) not a valid <Rob>."""
        return self.lock.rejected

    @property
    def peer(self) -> tuple[str, int] | None:
        """The sender the adapter is locked onto (the robot), None before the first <Rob>."""
        return self.lock.peer

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
        sock, lock, topic = self._sock, self.lock, self.rx_topic
        recvfrom, clock, stamp_now = sock.recvfrom, time.monotonic_ns, time.time_ns
        while not self._stop.is_set():
            try:
                data, peer = recvfrom(65536)
            except TimeoutError:
                continue
            except OSError as e:
                if self._stop.is_set():
                    return
                self.errors += 1
                log.error("UDP %s: %s", self.bind, e)
                time.sleep(self.poll_s)  # a socket error (not a wait for data): do not spin
                continue
            stamp = stamp_now()
            if not lock.accept(peer, data, clock()):
                self._log_rejected(peer)
                continue
            self.datagrams_in += 1
            put(topic, pb.SerialChunk(header=header(stamp, frame_id=f"{peer[0]}:{peer[1]}"), data=data))

    def _log_rejected(self, peer: tuple[str, int]) -> None:
        now = time.monotonic_ns()
        if now - self._logged_ns < LOG_INTERVAL_NS:
            return
        n = self.lock.rejected
        locked = f"{self.lock.peer[0]}:{self.lock.peer[1]}" if self.lock.peer else "nobody yet"
        log.warning("UDP %s: %d datagram(s) dropped on arrival since the last report (e.g. from %s:%d): "
                    "not the robot (locked onto %s); %d so far (%s)", self.bind, n - self._logged_rejected,
                    peer[0], peer[1], locked, n, self.lock.counters)
        self._logged_ns, self._logged_rejected = now, n

    def write(self, topic: str, msg: pb.SerialChunk) -> None:
        peer, sock = self.lock.peer, self._sock
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
    """The live shell's adapters: one UDP socket at ``udp_bind``, locked onto the robot's
    sender; another may take over after the gateway's silence watchdog
    (``status_timeout_cycles`` x ``cycle_period_ms``)."""
    return [UdpAdapter(config.udp_bind, robot=config.udp_robot,
                       relock_after_ms=config.status_timeout_cycles * config.cycle_period_ms)]
