"""The lock-step shell: several cores on virtual time in one process, no network.

Inputs are delivered in time order; equal times keep the order in which they were
scheduled, so a run is fully deterministic.  Every message is serialised and parsed on
the way, as on the network, so each subscriber gets its own copy.  With a run directory
each core is recorded exactly as the live shell records it, so lock-step recordings
replay with ``humanpt replay`` too (``record``: the ``[record]`` section; by default a
consumer's image inputs are references to the producer's recording, which is here).

Serial lines (:meth:`Lockstep.connect_serial`) carry one core's ``serial_tx`` bytes to
another core's ``serial_rx`` with the line's timing: a chunk of n bytes occupies the line
for n x bits-per-byte / baud seconds (8N1: 10 bits), chunks queue one after another, and
each arrives whole when its last byte has.  UDP paths (:meth:`Lockstep.connect_udp`, the
RSI link) carry ``udp_tx`` datagrams to ``udp_rx``, each arriving whole a fixed delay
after it was sent (the robot's own clock is its core's tick).
"""

from __future__ import annotations

import hashlib
import heapq
import logging
import time
from dataclasses import dataclass
from pathlib import Path

from humanpt.runtime.config import RecordConfig
from humanpt.runtime.core import Core
from humanpt.runtime.recording import (
    IMAGE_PRODUCER_NAMES,
    IMAGE_PRODUCERS,
    IN,
    OUT,
    ImagePolicy,
    Recorder,
)
from humanpt.runtime.snapshot import Snapshotter
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.lockstep")


@dataclass(frozen=True)
class Delivered:
    """One output of the run: (time, producing component, topic, serialised message)."""

    t_ns: int
    component: str
    topic: str
    data: bytes


@dataclass
class SerialLine:
    """One direction of a serial line between two cores (see :meth:`Lockstep.connect_serial`).

    Set ``enabled = False`` to cut it (bytes written meanwhile are lost; bytes already on
    the wire still arrive).
    """

    src: str
    dst: str
    baud: int
    bits_per_byte: int = 10
    enabled: bool = True
    free_at_ns: int = 0
    bytes_carried: int = 0
    bytes_lost: int = 0

    def wire_time_ns(self, n_bytes: int) -> int:
        """Time on the wire of ``n_bytes`` (ns, rounded up)."""
        return -(-n_bytes * self.bits_per_byte * 1_000_000_000 // self.baud)


@dataclass
class UdpPath:
    """One direction of a UDP path between two cores (:meth:`Lockstep.connect_udp`): every
    datagram arrives ``delay_ns`` after it was sent; ``enabled = False`` loses them."""

    src: str
    dst: str
    delay_ns: int
    enabled: bool = True
    datagrams: int = 0
    lost: int = 0


class Lockstep:
    """Run cores on virtual time.

    ``latency_ns`` delays every bus message (0: delivered at the time it was produced,
    after everything already scheduled for that time).  ``digest=False`` skips hashing the
    outputs (:meth:`digest` then raises).
    """

    def __init__(
        self,
        cores: list[Core],
        *,
        start_ns: int = 0,
        latency_ns: int = 0,
        run_dir: str | Path | None = None,
        keep_outputs: bool = True,
        chunk_size: int = 1024 * 1024,
        digest: bool = True,
        record: RecordConfig | None = None,
    ):
        names = [c.name for c in cores]
        if len(set(names)) != len(names):
            raise ValueError(f"two cores share a name: {names}")
        self.cores = cores
        self.now_ns = start_ns
        self.latency_ns = latency_ns
        self.keep_outputs = keep_outputs
        self.outputs: list[Delivered] = []
        # SHA-256 of every output (~0.25 ms per 640x480 image): off for runs nobody compares.
        self._digest = hashlib.sha256() if digest else None
        self._account: dict[str, float] | None = None  # see account()
        self._heap: list[tuple[int, int, int, str, bytes]] = []
        self._order = 0
        self._subs: dict[str, list[int]] = {}  # bus topic -> indices of the cores with a port on it
        # per core index: topic -> message class of its port (decodes what is delivered)
        self._lines: dict[int, list[tuple[SerialLine, int]]] = {}  # src index -> (line, dst index)
        self._udp: dict[int, list[tuple[UdpPath, int]]] = {}  # src index -> (path, dst index)
        for i, c in enumerate(cores):
            for p in c.ports:
                if p.on_bus:
                    self._subs.setdefault(p.topic, []).append(i)
            if c.tick_period_ns():
                self._push(start_ns, i, "tick", b"")
        self.recorders: dict[str, Recorder] = {}
        # Per recorded core: its state frozen into its recording every [record] snapshot_period_s.
        self.snapshotters: dict[str, Snapshotter] = {}
        if run_dir is not None:
            record = record or RecordConfig()
            recorded = set(names)  # every core records: an image's producer is recorded if it is here

            def producers(topic: str, me: str) -> tuple[str, ...]:
                return tuple(n for n in IMAGE_PRODUCERS.get(topic, ()) if n != me and n in recorded)

            for c in cores:
                self.recorders[c.name] = Recorder(
                    Path(run_dir) / f"{c.name}.mcap",
                    c.recording_metadata("lockstep", start_time_ns=start_ns, wall_start_time_ns=time.time_ns()),
                    chunk_size=chunk_size if c.name not in IMAGE_PRODUCER_NAMES else max(
                        chunk_size, record.image_chunk_size),
                    background=True,
                    images=ImagePolicy.from_config(c.name, record, producers),
                )
                self.snapshotters[c.name] = Snapshotter(record.snapshot_period_s)

    def _push(self, t_ns: int, core_index: int, topic: str, data: bytes) -> None:
        heapq.heappush(self._heap, (t_ns, self._order, core_index, topic, data))
        self._order += 1

    def connect_serial(
        self, a: str, b: str, baud: int = 38_400, *, both_ways: bool = True, bits_per_byte: int = 10
    ) -> list[SerialLine]:
        """Wire core ``a``'s ``serial_tx`` to core ``b``'s ``serial_rx`` (and back, unless
        ``both_ways`` is False) at ``baud`` with ``bits_per_byte`` per byte (8N1: 10)."""
        if baud <= 0 or bits_per_byte <= 0:
            raise ValueError("baud and bits_per_byte must be > 0")
        names = [c.name for c in self.cores]
        ia, ib = names.index(a), names.index(b)
        pairs = [(a, ia, b, ib)] + ([(b, ib, a, ia)] if both_ways else [])
        for _, _, _, idst in pairs:
            self.cores[idst].port("serial_rx")  # a core without a serial_rx port cannot take the line
        lines = []
        for src, isrc, dst, idst in pairs:
            line = SerialLine(src, dst, baud, bits_per_byte, free_at_ns=self.now_ns)
            self._lines.setdefault(isrc, []).append((line, idst))
            lines.append(line)
        return lines

    def connect_udp(self, a: str, b: str, delay_ns: int = 100_000) -> list[UdpPath]:
        """Wire core ``a``'s ``udp_tx`` to core ``b``'s ``udp_rx`` and back, each datagram
        arriving ``delay_ns`` after it was sent (default 0.1 ms: loopback or a switch)."""
        if delay_ns < 0:
            raise ValueError("delay_ns must be >= 0")
        names = [c.name for c in self.cores]
        ia, ib = names.index(a), names.index(b)
        paths = []
        for src, isrc, dst, idst in ((a, ia, b, ib), (b, ib, a, ia)):
            self.cores[idst].port("udp_rx")  # a core without a udp_rx port cannot take the path
            path = UdpPath(src, dst, delay_ns)
            self._udp.setdefault(isrc, []).append((path, idst))
            paths.append(path)
        return paths

    def _send_udp(self, t_ns: int, src: int, msg) -> None:
        for path, dst in self._udp[src]:
            if not path.enabled:
                path.lost += 1
                continue
            path.datagrams += 1
            chunk = pb.SerialChunk(header=header(t_ns + path.delay_ns, frame_id=path.src), data=msg.data)
            self._push(t_ns + path.delay_ns, dst, "udp_rx", chunk.SerializeToString())

    def _transmit(self, t_ns: int, src: int, msg) -> None:
        for line, dst in self._lines.get(src, ()):
            n = len(msg.data)
            if not line.enabled:
                line.bytes_lost += n
                continue
            start = max(t_ns, line.free_at_ns)
            end = start + line.wire_time_ns(n)
            line.free_at_ns = end
            line.bytes_carried += n
            chunk = pb.SerialChunk(
                header=header(end, frame_id=f"{line.src}->{line.dst}"), data=msg.data
            )
            self._push(end, dst, "serial_rx", chunk.SerializeToString())

    def inject(self, t_ns: int, component: str, topic: str, msg) -> None:
        """Schedule an input (e.g. a ``param`` change) for one component; ``topic`` must be
        one of its ports (else UndeclaredInputError, now rather than when it is due)."""
        idx = [c.name for c in self.cores].index(component)
        self.cores[idx].port(topic)
        self._push(t_ns, idx, topic, msg.SerializeToString())

    def set_param(self, t_ns: int, component: str, key: str, value_json: str) -> None:
        self.inject(
            t_ns,
            component,
            "param",
            pb.ParamSet(header=header(t_ns), component=component, key=key, value_json=value_json),
        )

    PARTS = ("decode", "encode", "record", "schedule")
    """What :meth:`account` counts beside the cores' steps."""

    def account(self) -> dict[str, float]:
        """From now on, count where the scheduler's thread spends its time (seconds of
        ``time.thread_time``, the CPU this thread used): each core's step under its name,
        and ``decode``, ``encode``, ``record`` (the recorders' writes and snapshots) and
        ``schedule`` (the rest of the loop: the event queue, the lines).  Returns the dict,
        updated by every later :meth:`run_until` (for the lock-step bench's shares)."""
        if self._account is None:
            self._account = {}
        return self._account

    def run_until(self, end_ns: int) -> None:
        """Process every input scheduled at or before ``end_ns``."""
        acc = self._account
        clock = time.thread_time
        if acc is not None:
            t_start = clock()
            acc_core = {c.name: 0.0 for c in self.cores}
            acc_part = dict.fromkeys(self.PARTS[:3], 0.0)
        while self._heap and self._heap[0][0] <= end_ns:
            t_ns, _, idx, topic, data = heapq.heappop(self._heap)
            self.now_ns = t_ns
            core = self.cores[idx]
            if acc is not None:
                t0 = clock()
            if topic == "tick":
                period = core.tick_period_ns()
                msg = pb.Tick(header=header(t_ns), period_ns=period or 0)
                if period:
                    self._push(t_ns + period, idx, "tick", b"")
                data = msg.SerializeToString()
            else:
                msg = core.port(topic).type()
                msg.ParseFromString(data)
            rec = self.recorders.get(core.name)
            if acc is not None:
                t1 = clock()
                acc_part["decode"] += t1 - t0
            if rec:
                rec.write(IN, t_ns, topic, msg, data)
            if acc is not None:
                t2 = clock()
                acc_part["record"] += t2 - t1
            outputs = core.step(t_ns, topic, msg)
            if acc is not None:
                acc_core[core.name] += clock() - t2
            for out_topic, out in outputs:
                if acc is not None:
                    t3 = clock()
                payload = out.SerializeToString()
                if acc is not None:
                    t4 = clock()
                    acc_part["encode"] += t4 - t3
                if rec:
                    rec.write(OUT, t_ns, out_topic, out, payload)
                    if acc is not None:
                        acc_part["record"] += clock() - t4
                if self._digest is not None:
                    self._digest.update(f"{t_ns}|{core.name}|{out_topic}|".encode())
                    self._digest.update(payload)
                if self.keep_outputs:
                    self.outputs.append(Delivered(t_ns, core.name, out_topic, payload))
                for j in self._subs.get(out_topic, ()):
                    self._push(t_ns + self.latency_ns, j, out_topic, payload)
                if out_topic == "serial_tx" and idx in self._lines:
                    self._transmit(t_ns, idx, out)
                elif out_topic == "udp_tx" and idx in self._udp:
                    self._send_udp(t_ns, idx, out)
            if rec:
                if acc is not None:
                    t5 = clock()
                self._snapshot(core, rec, t_ns)
                if acc is not None:
                    acc_part["record"] += clock() - t5
        self.now_ns = max(self.now_ns, end_ns)
        if acc is not None:
            total = clock() - t_start
            for k, v in (*acc_core.items(), *acc_part.items()):
                acc[k] = acc.get(k, 0.0) + v
            acc["schedule"] = acc.get("schedule", 0.0) + total - sum(acc_core.values()) - sum(acc_part.values())

    def _snapshot(self, core: Core, rec: Recorder, t_ns: int) -> None:
        """The core's state into its recording when one is due (after the input's outputs)."""
        snap = self.snapshotters[core.name]
        data = snap.after_input(core, t_ns)
        if data is not None:
            rec.write_snapshot(t_ns, data)
        elif snap.error is not None and snap.news():
            log.warning("%s", snap.error)

    def digest(self) -> str:
        """SHA-256 over every output so far (time, component, topic, bytes)."""
        if self._digest is None:
            raise RuntimeError("this lock-step run was built with digest=False")
        return self._digest.hexdigest()

    def close(self) -> None:
        for r in self.recorders.values():
            r.close()

    def __enter__(self) -> Lockstep:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
