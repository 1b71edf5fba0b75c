"""The live shell: a core on a Zenoh session.

* inputs arrive from Zenoh subscribers (one per bus port of the core, decoded with the
  port's message type) and from the tick timer;
  they are queued and fed to the core one at a time from one thread, in arrival order,
  with ``t_ns`` = the time (shared time base, :mod:`humanpt.runtime.clock`) at which the
  core is given the input;
* time (runtime/clock.py): waits and the tick timer on the monotonic clock, stamps and
  ``t_ns`` in the shared time base; a step of the wall clock (NTP) is accepted before the
  next input and given to a core with a ``clock_step`` port as an input (recorded, so it
  replays), and a local input stamped before the step is re-stamped in the new base;
* outputs are published on ``humanpt/<cell>/<topic>``;
* a liveliness token ``humanpt/<cell>/<component>`` says the component is up;
* a queryable ``humanpt/<cell>/<component>/params`` serves the live parameters and sets
  them (payload ``{"set": {"key": value}}``); a change reaches the core as a ``param``
  input, so it is recorded and replays;
* everything the core consumed and produced is recorded to ``<run dir>/<component>.mcap``
  (``<component>.1.mcap``... when the component restarts into the same run: never truncated);
  images as ``[record]`` says (``record``): a consumer's image input is a reference when its
  producer records into the same run directory (runtime/README.md "Images");
  a write error (full disk) never stops the component: it publishes a ``record_error``
  event at once, ``record_resumed`` when recording goes on in a new segment, and the
  losses go to ``<component>.losses.json`` (see :class:`~humanpt.runtime.recording.Recorder`);
* a payload that fails to decode is dropped with a log line and a counter (and kept raw
  in the recording); the component lives on;
* the liveliness of the components named in ``core.watch`` reaches the core as
  ``liveliness`` inputs;
* adapters bridge local I/O: an adapter puts local inputs (``serial_rx``, ``capture``:
  ports of the core) into the same queue and receives the core's outputs on its local
  topics (``serial_tx``).
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import zenoh
from google.protobuf.message import DecodeError

from humanpt.runtime.bus import liveliness_key, params_key, rig_key, zenoh_config
from humanpt.runtime.clock import CLOCK, Clock
from humanpt.runtime.config import RecordConfig, RuntimeConfig
from humanpt.runtime.core import Core, UndeclaredInputError
from humanpt.runtime.recording import (
    IMAGE_PRODUCER_NAMES,
    IN,
    OUT,
    ImagePolicy,
    Recorder,
    live_producers,
)
from humanpt.runtime.snapshot import Snapshotter
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.convert import header

log = logging.getLogger("humanpt.live")

CLOCK_STEP = "clock_step"  # the local input saying the wall clock stepped (runtime/clock.py)


@dataclass
class Counters:
    consumed: int = 0
    produced: int = 0
    dropped: int = 0
    core_errors: int = 0
    by_reason: dict[str, int] = field(default_factory=dict)


@dataclass
class _ParamRequest:
    key: str
    value_json: str
    done: threading.Event = field(default_factory=threading.Event)
    result: dict | None = None


class Adapter(Protocol):
    """Local I/O of a live shell (a serial port...).

    ``start(put)`` begins delivering local inputs with ``put(topic, message)`` (from any
    thread); ``write(topic, message)`` receives the core's outputs on ``topics_out``.
    """

    topics_out: tuple[str, ...]

    def start(self, put: Callable[[str, object], None]) -> None: ...

    def write(self, topic: str, msg) -> None: ...

    def close(self) -> None: ...


class Inbox:
    """What waits for the core: local inputs (serial bytes, ticks, liveliness, parameters,
    adapters' inputs) in arrival order and always first, then bus messages, one topic after
    another (round robin), each topic bounded by its port's ``queue`` (oldest dropped; 1:
    latest wins).  So a flood on one bus topic delays neither the serial line nor the other
    topics, and holds bounded memory.  Thread-safe: Zenoh's threads put, the worker gets."""

    def __init__(self, bounds: dict[str, int]):
        self._bounds = bounds
        self._cv = threading.Condition()
        self._local: deque = deque()
        self._bus: dict[str, deque] = {}
        self._turn: deque[str] = deque()  # bus topics with something waiting, in turn
        self.dropped: dict[str, int] = {}  # topic -> messages dropped for a full queue
        self._tick_waiting = False

    def put_local(self, item) -> None:
        with self._cv:
            if item[0] == "tick" and self._tick_waiting:
                return  # a core that fell behind gets one tick, not a burst of them
            self._tick_waiting = self._tick_waiting or item[0] == "tick"
            self._local.append(item)
            self._cv.notify()

    def put_bus(self, short: str, payload: bytes) -> None:
        with self._cv:
            q = self._bus.get(short)
            if q is None:
                q = self._bus[short] = deque()
            if not q:
                self._turn.append(short)
            elif len(q) >= self._bounds[short]:
                q.popleft()
                self.dropped[short] = self.dropped.get(short, 0) + 1
            q.append(payload)
            self._cv.notify()

    def get(self, timeout: float):
        """The next (kind, short, item), or None after ``timeout`` s with nothing waiting."""
        with self._cv:
            if not self._local and not self._turn:
                self._cv.wait(timeout)
            if self._local:
                item = self._local.popleft()
                if item[0] == "tick":
                    self._tick_waiting = False
                return item
            if not self._turn:
                return None
            short = self._turn.popleft()
            q = self._bus[short]
            payload = q.popleft()
            if q:
                self._turn.append(short)
            return "bus", short, payload


class LiveShell:
    """Bind ``core`` to Zenoh; :meth:`run` blocks until ``stop`` is set."""

    def __init__(self, core: Core, rt: RuntimeConfig, *, run_dir: str | Path | None = None,
                 zconf: zenoh.Config | None = None, adapters: list[Adapter] | None = None,
                 record: RecordConfig | None = None, clock: Clock | None = None):
        self.core = core
        # The one source of time (runtime/clock.py): the process's unless a test gives one.
        self.clock = clock or CLOCK
        self._epoch = self.clock.epoch  # the clock's steps given to the core so far
        try:
            core.port(CLOCK_STEP)
            self._takes_steps = True
        except UndeclaredInputError:
            self._takes_steps = False
        self.record = record or RecordConfig()  # [record]: what the recording keeps of images
        self.adapters = list(adapters or [])
        self._local_out = {t: a for a in self.adapters for t in a.topics_out}
        self.rt = rt
        self.cell = rt.cell
        self.run_dir = Path(run_dir) if run_dir is not None else None
        # under mTLS the component presents its own certificate (its name is its identity)
        self.zconf = zconf or zenoh_config(rt, identity=core.name)
        self.counters = Counters()
        self.stop = threading.Event()
        self.ready = threading.Event()
        self._q = Inbox({p.topic: p.queue for p in core.ports if p.on_bus})
        self._pubs: dict[str, zenoh.Publisher] = {}
        self.recorder: Recorder | None = None
        # used when recording; a realtime core's only if [record] snapshot_realtime (its cycle)
        self._snapshots = Snapshotter(self.record.snapshot_period_s
                                      if self.record.snapshot_realtime or not core.realtime else 0.0)
        self._tick_handled = threading.Event()  # a realtime core's tick was taken (_tick_loop)
        self._tick_handled_at = 0.0  # time.monotonic() then

    # -- Zenoh callbacks (Zenoh threads): only enqueue -----------------------------------
    def _on_sample(self, short: str):
        def cb(sample: zenoh.Sample) -> None:
            self._q.put_bus(short, sample.payload.to_bytes())
        return cb

    def _on_rig_query(self, query: zenoh.Query) -> None:
        """Serve the rig this component runs with (JSON; ``humanpt rig show``)."""
        from humanpt.runtime.rigfile import rig_to_json

        # Reply on this component's own key (the query may be a wildcard over the cell).
        query.reply(rig_key(self.cell, self.core.name), rig_to_json(self.core.rig))

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            body = json.loads(query.payload.to_bytes()) if query.payload is not None else {}
            sets = body.get("set", {}) if isinstance(body, dict) else {}
            if not isinstance(sets, dict):
                raise ValueError('"set" must be an object of key: value')
        except (ValueError, UnicodeDecodeError) as e:
            query.reply(query.key_expr, json.dumps({"ok": False, "error": f"bad request: {e}"}))
            return
        results = []
        for key, value in sets.items():
            req = _ParamRequest(str(key), json.dumps(value))
            self._q.put_local(("param", "param", req))
            if not req.done.wait(5.0):
                results.append({"key": key, "ok": False, "text": "the component did not answer in 5 s"})
            else:
                results.append(req.result)
        self._sync_drops()
        reply = {"ok": all(r["ok"] for r in results), "component": self.core.name, "results": results,
                 "params": self.core.params(), "counters": self.counters.__dict__}
        query.reply(query.key_expr, json.dumps(reply, default=str))

    def _sync_drops(self) -> None:
        """Messages the inbox dropped for a full queue, into the counters."""
        c = self.counters
        for short, n in list(self._q.dropped.items()):
            reason = f"queue of {short} full (oldest dropped)"
            c.dropped += n - c.by_reason.get(reason, 0)
            c.by_reason[reason] = n

    def _on_liveliness(self, component: str):
        def cb(sample: zenoh.Sample) -> None:
            self._q.put_local(("liveliness", component, sample.kind == zenoh.SampleKind.PUT))
        return cb

    def _put_local(self, topic: str, msg) -> None:
        # with the clock's epoch: a stamp taken before a step the worker accepts meanwhile
        # is moved into the new base when the core is given it (_restamp)
        self._q.put_local(("local", topic, (msg, self.clock.epoch)))

    def _restamp(self, msg, epoch: int):
        """``msg`` with its stamp (``header.stamp_ns``, a foxglove image's ``timestamp``) moved
        by the clock steps accepted since ``epoch``."""
        shift = self.clock.shift_since(epoch)
        if not shift:
            return msg
        header_ = getattr(msg, "header", None)
        if header_ is not None and getattr(header_, "stamp_ns", 0):
            header_.stamp_ns = max(0, header_.stamp_ns + shift)
        stamp = getattr(msg, "timestamp", None)
        if stamp is not None and hasattr(stamp, "ToNanoseconds") and stamp.ToNanoseconds():
            stamp.FromNanoseconds(max(0, stamp.ToNanoseconds() + shift))
        return msg

    def _clock_step(self, step_ns: int) -> None:
        """The wall clock stepped by ``step_ns`` (accepted by the clock): a core that takes
        steps is told (an input, recorded), the log says so in any case."""
        log.warning("%s: the wall clock stepped by %+.3f s (NTP?); stamps follow it, watchdogs keep "
                    "monotonic time%s", self.core.name, step_ns / 1e9,
                    "" if self._takes_steps else " (this component keeps no watchdog on it)")
        if self._takes_steps:
            t_ns = self.clock.now_ns()
            self._feed(t_ns, CLOCK_STEP, pb.Event(header=header(t_ns), severity=pb.SEVERITY_WARNING, source="clock",
                                                  code=CLOCK_STEP, text=str(step_ns)))

    def _tick_loop(self) -> None:
        next_t = time.monotonic()
        realtime = self.core.realtime
        while not self.stop.is_set():
            period = self.core.tick_period_ns()
            if not period:
                return
            next_t += period / 1e9
            delay = next_t - time.monotonic()
            if delay < -period / 1e9:  # fell behind by more than a period: skip, do not burst
                next_t = time.monotonic()
                delay = 0.0
            if self.stop.wait(max(delay, 0.0)):
                return
            if not realtime:
                self._q.put_local(("tick", "tick", None))
                continue
            # A realtime core (a robot link's cycle) never gets a cycle shorter than its
            # period: the next tick is due a period after the worker got to this one. A busy
            # process stretches its cycle (a real controller's would not) but never cuts the
            # next one short, which would leave a peer less than a cycle to answer.
            self._tick_handled.clear()
            self._q.put_local(("tick", "tick", None))
            while not self._tick_handled.wait(0.1):
                if self.stop.is_set():
                    return
            next_t = self._tick_handled_at

    # -- the one worker thread -----------------------------------------------------------
    def _feed(self, t_ns: int, topic: str, msg, data: bytes | None = None) -> list:
        # Outputs go on the bus first and into the recording after: recording never adds
        # to the latency of what the core produced.  The file keeps consumption order (the
        # input, then its outputs).
        if self.recorder and data is None:
            data = msg.SerializeToString()  # as given, before the core sees it
        self.counters.consumed += 1
        try:
            outs = self.core.step(t_ns, topic, msg)
        except Exception as e:  # noqa: BLE001 - last resort: a core bug must not kill the process
            if self.recorder:
                self.recorder.write(IN, t_ns, topic, msg, data)
                self._snapshot(t_ns)
            self.counters.core_errors += 1
            log.exception("%s: core raised on %s", self.core.name, topic)
            self._publish_raw(f"{self.core.name}/events", pb.Event(
                header=header(t_ns), severity=pb.SEVERITY_ERROR, source=self.core.name, code="core_error",
                text=f"{type(e).__name__}: {e}"))
            return []
        payloads = []
        for out_topic, out in outs:
            payload = out.SerializeToString()
            payloads.append(payload)
            adapter = self._local_out.get(out_topic)
            if adapter is not None:
                try:
                    adapter.write(out_topic, out)
                except Exception:  # noqa: BLE001 - a failing port must not stop the core
                    log.exception("%s: adapter could not write %s", self.core.name, out_topic)
            if "/" in out_topic:  # bus topics are published even when an adapter also takes them
                self._publish(out_topic, payload)
            self.counters.produced += 1
        if self.recorder:
            self.recorder.write(IN, t_ns, topic, msg, data)
            for (out_topic, out), payload in zip(outs, payloads, strict=True):
                self.recorder.write(OUT, t_ns, out_topic, out, payload)
            self._snapshot(t_ns)
        return outs

    def _snapshot(self, t_ns: int) -> None:
        """The core's state into the recording when one is due ([record] snapshot_period_s),
        after the input's outputs were published; a state that cannot be frozen stops the
        snapshots (a warning event, once), never the core."""
        data = self._snapshots.after_input(self.core, t_ns)
        if data is not None:
            self.recorder.write_snapshot(t_ns, data)
        elif self._snapshots.news():
            log.warning("%s", self._snapshots.error)
            self._publish_raw(f"{self.core.name}/events", pb.Event(
                header=header(t_ns), severity=pb.SEVERITY_WARNING, source=self.core.name, code="snapshot_error",
                text=self._snapshots.error[:500]))

    def _publish(self, short: str, payload: bytes) -> None:
        pub = self._pubs.get(short)
        if pub is None:
            from humanpt.runtime.bus import declare_topic_publisher

            # application/protobuf;<type>: any client decodes it from the .proto (runtime/bus.py)
            pub = self._pubs[short] = declare_topic_publisher(self._session, self.cell, short)
        pub.put(payload)

    def _publish_raw(self, short: str, msg) -> None:
        try:
            self._publish(short, msg.SerializeToString())
        except Exception:  # noqa: BLE001
            log.exception("could not publish on %s", short)

    def _recording_news(self) -> None:
        """The recorder's write errors and resumptions, as events (and log lines)."""
        while self.recorder.news:
            code, text = self.recorder.news.popleft()
            error = code == "record_error"
            log.log(logging.ERROR if error else logging.WARNING, "%s: %s", self.core.name, text)
            self._publish_raw(f"{self.core.name}/events", pb.Event(
                header=header(self.clock.now_ns()), severity=pb.SEVERITY_ERROR if error else pb.SEVERITY_INFO,
                source=self.core.name, code=code, text=text))

    def _drop(self, t_ns: int, short: str, payload: bytes, reason: str) -> None:
        c = self.counters
        c.dropped += 1
        c.by_reason[reason] = c.by_reason.get(reason, 0) + 1
        if c.dropped <= 10 or c.dropped % 1000 == 0:
            log.warning("%s: dropped a message on %s (%d bytes): %s [dropped so far: %d]",
                        self.core.name, short, len(payload), reason, c.dropped)
        if self.recorder:
            self.recorder.write_dropped(t_ns, short, payload)

    def _handle(self, kind: str, short: str, item) -> None:
        t_ns = self.clock.now_ns()
        if kind == "bus":
            cls = self.core.port(short).type
            msg = cls()
            try:
                msg.ParseFromString(item)
            except (DecodeError, ValueError, RuntimeError) as e:
                self._drop(t_ns, short, item, f"does not decode as {cls.DESCRIPTOR.full_name}: {e}")
                return
            self._feed(t_ns, short, msg, item)
        elif kind == "local":
            msg, epoch = item
            self._feed(t_ns, short, self._restamp(msg, epoch) if epoch != self.clock.epoch else msg)
        elif kind == "liveliness":
            self._feed(t_ns, "liveliness", pb.Liveliness(header=header(t_ns), component=short, alive=item))
        elif kind == "tick":
            if self.core.realtime:  # _tick_loop waits for it
                # The tick's stamp (t_ns, taken as the worker took the tick) comes before the
                # instant the next cycle counts from: a realtime core's tick stamps are a
                # period apart at least, however late its step runs after them.
                self._tick_handled_at = time.monotonic()
                self._tick_handled.set()
            self._feed(t_ns, "tick", pb.Tick(header=header(t_ns), period_ns=self.core.tick_period_ns() or 0))
        elif kind == "param":
            req: _ParamRequest = item
            msg = pb.ParamSet(header=header(t_ns), component=self.core.name, key=req.key, value_json=req.value_json)
            outs = self._feed(t_ns, "param", msg)
            codes = [o.code for _, o in outs if isinstance(o, pb.Event)]
            texts = [o.text for _, o in outs if isinstance(o, pb.Event)]
            req.result = {"key": req.key, "ok": "param_changed" in codes, "text": "; ".join(texts)}
            req.done.set()

    def run(self) -> Counters:
        """Open the session, serve until :attr:`stop` is set, then close everything."""
        name = self.core.name
        if self.run_dir is not None and self.rt.record:
            self.recorder = Recorder(
                self.run_dir / f"{name}.mcap",
                self.core.recording_metadata("live", start_time_ns=self.clock.now_ns(), cell=self.cell,
                                             host=socket.gethostname(), pid=os.getpid()),
                chunk_size=self.rt.chunk_size if name not in IMAGE_PRODUCER_NAMES else max(
                    self.rt.chunk_size, self.record.image_chunk_size),
                flush_interval_s=self.rt.flush_interval_s,
                # A robot link's cycle must not wait for a chunk's compression.
                background=self.rt.record_thread or bool(self.core.realtime),
                images=ImagePolicy.from_config(name, self.record, live_producers(
                    self.run_dir, fresh_s=max(10.0, 5 * self.rt.flush_interval_s))))
            log.info("%s: recording to %s", name, self.recorder.path)
        try:
            t_warm = time.perf_counter()
            try:
                self.core.warm_up()
            except Exception as e:  # only a head start: the first input does the same work
                log.warning("%s: warm-up failed (%s); the first input will do its work", name, e)
            if time.perf_counter() - t_warm > 1.0:
                log.info("%s: warmed up in %.1f s before saying it is up (e.g. kernels compiled on a "
                         "first run after an install)", name, time.perf_counter() - t_warm)
            with zenoh.open(self.zconf) as session:
                self._session = session
                bus_ports = [p.topic for p in self.core.ports if p.on_bus]
                subs = [session.declare_subscriber(topics.TOPICS[s].key(self.cell), self._on_sample(s))
                        for s in bus_ports]
                watchers = [session.liveliness().declare_subscriber(liveliness_key(self.cell, w),
                                                                    self._on_liveliness(w), history=True)
                            for w in self.core.watch]
                for a in self.adapters:
                    a.start(self._put_local)
                qbl = session.declare_queryable(params_key(self.cell, name), self._on_query)
                rig_qbl = (None if self.core.rig is None else
                           session.declare_queryable(rig_key(self.cell, name), self._on_rig_query))
                ticker = threading.Thread(target=self._tick_loop, name=f"{name}-tick", daemon=True)
                ticker.start()
                # Last: the liveliness token means "ready" (adapters, e.g. viz's server, and the
                # parameter queryable are up), not merely "process started".
                token = session.liveliness().declare_token(liveliness_key(self.cell, name))
                self.ready.set()
                log.info("%s up in cell %s (bus inputs: %s)", name, self.cell, ", ".join(bus_ports) or "none")
                rec = self.recorder
                clock = self.clock
                while not self.stop.is_set():
                    got = self._q.get(timeout=0.1)
                    if got is not None:
                        if clock.check() != self._epoch:
                            for step_ns in clock.steps[self._epoch:]:
                                self._clock_step(step_ns)
                            self._epoch = clock.epoch
                        self._handle(*got)
                    if rec is not None and rec.news:  # a cheap test, after every input
                        self._recording_news()
                ticker.join(timeout=1.0)
                self._sync_drops()
                qbl.undeclare()
                if rig_qbl is not None:
                    rig_qbl.undeclare()
                token.undeclare()
                for w in watchers:
                    w.undeclare()
                for s in subs:
                    s.undeclare()
                for p in self._pubs.values():
                    p.undeclare()
                self._pubs.clear()
        finally:
            for a in self.adapters:
                try:
                    a.close()
                except Exception:  # noqa: BLE001
                    log.exception("closing an adapter")
            if self.recorder:
                self.recorder.close()
        return self.counters
