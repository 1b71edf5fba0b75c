"""The RSI link's I/O adapter: a UDP socket on a thread of its own.

Datagrams read from the robot become ``udp_rx`` inputs (humanpt.SerialChunk, stamped when
read, frame_id = the sender's host:port); the core's ``udp_tx`` outputs go back to the
robot only. The socket never waits behind bus traffic: the read loop is its own thread and
puts straight into the shell's input queue (local inputs go first).

Which sender is the robot (issue 29, :class:`PeerLock`): the first datagram from an allowed
host (``udp_robot``: "host" or "host:port"; "" any) that is a valid ``<Rob>`` locks the
adapter onto its host *and port*; from then on only that sender's datagrams reach the core
and answers go only there. Once locked the socket is *connected* to the robot's address,
so the kernel itself drops every other sender's datagram before it is queued: a flood from
elsewhere neither costs the reader anything nor fills the socket's buffer ahead of the
robot's datagrams (until the lock, others are dropped by the reader, by address, before they
are parsed). Another sender can take over only once the locked one has been silent for
``relock_after_ms`` (the gateway's silence watchdog, ``status_timeout_cycles`` cycles: the
gateway has declared ``link_down`` by then): the socket is then bound afresh, unconnected,
which is how a robot that restarts RSI from another port is found again.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable

from humanpt.robot_gateway.links.rsi.config import RsiConfig, parse_address
from humanpt.robot_gateway.links.rsi.protocol import RsiProtocolError, decode_rob
from humanpt.runtime.clock import CLOCK
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.robot_gateway.links.rsi")

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

    def silent(self, t_ns: int) -> bool:
        """Whether another sender may take over at ``t_ns``: the locked one has said nothing
        for ``relock_after_ns`` (never for a fixed peer)."""
        return (not self.fixed and self.peer is not None and self._last_ns is not None
                and t_ns - self._last_ns >= self.relock_after_ns)


class UdpAdapter:
    topics_out = ("udp_tx",)

    def __init__(self, bind: str, *, robot: str = "", rx_topic: str = "udp_rx", poll_s: float = 0.2,
                 peer: str = "", relock_after_ms: float = 300.0, valid: Callable[[bytes], bool] = _is_rob):
        """``robot``: "host" or "host:port" the datagrams must come from ("": any);
        ``peer``: "host:port" to send to and take datagrams from only, for good (the
        simulated robot's side: its gateway); "": the first valid ``<Rob>`` locks
        (:class:`PeerLock`), the gateway's way; ``relock_after_ms``: how long the locked
        sender must be silent before another may take over; ``valid``: whether a datagram
        is the robot's message (may lock): RSI's ``<Rob>`` by default, another UDP link's
        own check (ABB EGM's EgmRobot)."""
        self.bind = bind
        self.lock = PeerLock(robot, fixed=parse_address(peer) if peer else None,
                             relock_after_ns=round(relock_after_ms * 1e6), valid=valid)
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
        self._connected: tuple[str, int] | None = None  # the socket's connected peer
        self.refused = 0  # sends refused by the peer's host (nobody listening there)
        self._refused_logged_ns = -LOG_INTERVAL_NS

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
        """Bind now (OSError names the address on failure); connected to a fixed peer."""
        self._sock = self._bind()
        if self.lock.fixed:
            self._connect(self._sock, self.lock.peer)

    def _bind(self) -> socket.socket:
        host, port = parse_address(self.bind)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((host, port))  # (no SO_REUSEADDR: for UDP it would let another socket share the port)
        except OSError as e:
            sock.close()
            raise OSError(f"cannot bind UDP {self.bind}: {e.strerror or e}") from None
        sock.settimeout(self.poll_s)
        if port == 0:
            self.bind = "{}:{}".format(*sock.getsockname())  # the same port if bound afresh
        return sock

    def _connect(self, sock: socket.socket, peer: tuple[str, int]) -> None:
        """From now on the kernel delivers only ``peer``'s datagrams to ``sock``."""
        sock.connect(peer)
        self._connected = peer

    def _unlock(self) -> None:
        """The locked sender is silent: take datagrams from any sender again (a socket bound
        afresh: a connected UDP socket cannot be disconnected portably)."""
        old = self._sock
        self._connected = None
        old.close()
        while True:  # a closed UDP port is free at once: bound again in one go, unless taken meanwhile
            try:
                self._sock = self._bind()
                break
            except OSError as e:
                self.errors += 1
                log.error("UDP %s: %s; trying again", self.bind, e)
                if self._stop.wait(self.poll_s):
                    self._sock = None
                    return
        log.warning("UDP %s: the robot at %s:%d silent for %.0f ms: the next valid robot message from an "
                    "allowed sender locks", self.bind, *self.lock.peer, self.lock.relock_after_ns / 1e6)

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port) (port 0 in the config: the one the system chose)."""
        assert self._sock is not None, "not open"
        # (from the bound address kept in self.bind: during a relock the socket is bound afresh,
        # and another thread asking meanwhile must not meet the closed one)
        return parse_address(self.bind)

    def start(self, put: Callable[[str, object], None]) -> None:
        if self._sock is None:
            self.open()
        self._thread = threading.Thread(target=self._read_loop, args=(put,), name="udp-rx", daemon=True)
        self._thread.start()

    def _read_loop(self, put) -> None:
        lock, topic = self.lock, self.rx_topic
        clock, stamp_now = time.monotonic_ns, CLOCK.now_ns  # watchdog, stamp (runtime/clock.py)
        while not self._stop.is_set():
            sock = self._sock
            if sock is None:
                return
            try:
                data, peer = sock.recvfrom(65536)
            except TimeoutError:
                if self._connected is not None and lock.silent(clock()):
                    self._unlock()
                continue
            except ConnectionRefusedError:
                continue  # (an ICMP "port unreachable" for an answer: the robot's socket is gone)
            except OSError as e:
                if self._stop.is_set():
                    return
                self.errors += 1
                log.error("UDP %s: %s", self.bind, e)
                time.sleep(self.poll_s)  # a socket error (not a wait for data): do not spin
                continue
            stamp = stamp_now()
            now = clock()
            if not lock.accept(peer, data, now):
                self._log_rejected(peer)
                if self._connected is not None and lock.silent(now):
                    self._unlock()
                continue
            if self._connected != peer:
                self._connect(sock, peer)
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
            if self._connected == peer:
                sock.send(msg.data)
            else:
                sock.sendto(msg.data, peer)
            self.datagrams_out += 1
        except ConnectionRefusedError:
            # (a connected socket reports an earlier datagram's ICMP "port unreachable": nobody
            # listens there now, e.g. the gateway restarting; at most one report a second)
            self.refused += 1
            now = time.monotonic_ns()
            if now - self._refused_logged_ns >= LOG_INTERVAL_NS:
                self._refused_logged_ns = now
                log.warning("UDP %s: nobody listens at %s:%d (%d refused so far)", self.bind, peer[0], peer[1],
                            self.refused)
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


def adapters(config: RsiConfig) -> list[UdpAdapter]:
    """The live shell's adapters: one UDP socket at ``udp_bind``, locked onto the robot's
    sender; another may take over after the gateway's silence watchdog
    (``status_timeout_cycles`` x ``cycle_period_ms``)."""
    return [UdpAdapter(config.udp_bind, robot=config.udp_robot,
                       relock_after_ms=config.status_timeout_cycles * config.cycle_period_ms)]
