"""Recording a component's run to MCAP, and reading it back (even when truncated).

A component's recording ``<run dir>/<component>.mcap`` holds, in the order the core saw
them, every input it consumed (channel metadata ``direction=in``, log time = the time
given to the core) and every output it produced (``direction=out``, log time = the
time of the step that produced it).  Inputs that failed to decode are kept raw on a
``direction=dropped`` channel, so nothing is lost.  Schemas are registered as protobuf
FileDescriptorSets so Foxglove and rerun open the files.  A metadata record
``humanpt.run`` holds the component, its core class, its config, the version and the
start time; replay builds the core from it.

Writing uses mcap's public :class:`mcap.writer.Writer` only (zstd chunks of
``chunk_size`` bytes).  Each finished chunk is put in the file at once, and a timer ends the
chunk in progress and puts it in the file ``flush_interval_s`` after the last flush, whether
messages keep coming or not: a process killed (SIGKILL, a crash) loses at most the messages
it gave its recorder in the last ``flush_interval_s``, plus those being compressed and
written at that moment (with ``background=True``, what waits for the writer thread: see
:class:`Recorder`).  Every channel is also written, when registered, in a ``humanpt.channels``
metadata record outside the chunks, so a file never closed (no summary) whose chunk declaring
a channel is damaged still reads the channel's messages in later chunks.  A write error (a
full disk) never raises to the component: the recording stops at its last whole chunk,
counts what it loses, and resumes in the next segment when there is room.

Reading (:func:`iter_records`, :func:`iter_entries`, :func:`read`) never trusts what a file
declares: a chunk is decompressed only when its declared size is within
:data:`MAX_CHUNK_BYTES` and what its compression can make of its bytes (:data:`MAX_RATIO`),
and never into more than it declares; a chunk refused or damaged is skipped with one line
naming the file and its offset, and reading goes on; channels come from the summary section
too, so damage in the first chunk hides only that chunk.  A recording read with any note
(cut, never closed, a chunk skipped, fewer messages than its summary counts) is not read in
full, and replay never calls it a match.
"""

from __future__ import annotations

import dataclasses
import errno
import heapq
import io
import json
import logging
import os
import queue
import struct
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lz4.frame
import zstandard
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.message import DecodeError, Message
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, Metadata, Schema, Statistics
from mcap.records import Message as McapMessage
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema

from humanpt.runtime.files import write_atomic
from humanpt.schemas import topics

RUN_METADATA = "humanpt.run"
# Each channel as it is registered (id -> JSON: topic, schema name, metadata), outside the chunks:
# a file never closed (no summary) whose chunk declaring a channel is damaged still reads its messages.
CHANNELS_METADATA = "humanpt.channels"
IN, OUT, DROPPED = "in", "out", "dropped"
# A core's state frozen between two inputs (Core.freeze, runtime/snapshot.py): JSON on a
# schema-less channel of its own (topic ``snapshot``); readers of the messages never see it
# (iter_entries), replay starts from it (Recording.snapshots).
SNAPSHOT = "snapshot"
# What a channel's messages hold (channel metadata ``payload``; absent: the whole message).
# Images only (foxglove.RawImage): the message with its ``data`` (the pixels) left out, and
# where the pixels are: REFERENCE in the recording of the producer named by ``producers``
# (the image of topic ``ref_topic`` with the same stamp and frame_id), SAME_AS_INPUT in this
# recording (the last input on ``ref_topic`` before it: an output that copies its input),
# OMITTED nowhere (``[record] images`` kept only ``policy``).
FULL, REFERENCE, SAME_AS_INPUT, OMITTED = "", "reference", "same_as_input", "omitted"
# The components that may publish an image topic (the twin's camera stands in for the real one).
IMAGE_PRODUCERS: dict[str, tuple[str, ...]] = {"camera/image": ("camera", "sim_camera")}
IMAGE_PRODUCER_NAMES = frozenset(n for names in IMAGE_PRODUCERS.values() for n in names)

log = logging.getLogger("humanpt.recording")


class RecordingError(ValueError):
    """A recording that cannot be read: missing, not MCAP, not a humanpt recording, or
    written by an incompatible schema version.  The message says which."""


class _SegmentFile:
    """A recording file written straight to the OS, no buffer in between: :meth:`tell` is
    what the OS accepted, so after a failed write the Recorder knows where its last
    complete chunk ends and cuts the file back there (the reader then finds a clean end,
    and the messages counted as lost are exactly those not in the file).  Never opens an
    existing file (``O_EXCL``)."""

    def __init__(self, path: Path):
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
        self.fd = os.open(path, flags, 0o644)
        self.pos = 0  # bytes the OS accepted

    def write(self, data) -> int:
        view = memoryview(data)
        while view:  # a full disk may take part of a write, then refuse the rest
            n = os.write(self.fd, view)
            if n <= 0:
                raise OSError(errno.EIO, "write wrote nothing")
            self.pos += n
            view = view[n:]
        return len(data)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        """Nothing waits in memory (the MCAP writer calls this)."""

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            os.close(fd)


def _open_new_segment(path: Path) -> tuple[Path, _SegmentFile]:
    """Open ``path`` for writing, never over an existing file: a component restarted into
    the same run directory (or a recording resumed after a write error) writes
    ``<stem>.1.mcap``, ``<stem>.2.mcap``... beside the first recording. Returns (the path
    opened, the file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    candidate, n = path, 0
    while True:
        try:
            return candidate, _SegmentFile(candidate)
        except FileExistsError:
            n += 1
            candidate = path.with_name(f"{path.stem}.{n}{path.suffix}")


def _by_topic_text(lost: dict[tuple[str, str], int], most: int = 4) -> str:
    """``in pinger/ping 60, out ponger/pong 60``: the most lost first."""
    items = sorted(lost.items(), key=lambda kv: (-kv[1], kv[0]))
    text = ", ".join(f"{d} {t} {n}" for (d, t), n in items[:most])
    return text + (f", {len(items) - most} more topics" if len(items) > most else "")


def strip_image(msg: RawImage) -> RawImage:
    """The image without its pixels (``data``): stamp, frame_id, size, encoding, step kept."""
    out = RawImage(timestamp=msg.timestamp, frame_id=msg.frame_id, width=msg.width, height=msg.height,
                   encoding=msg.encoding, step=msg.step)
    return out


def image_identity(msg: RawImage) -> tuple[int, str]:
    """(capture stamp ns, frame_id): what names one image of a producer (RawImage has no
    sequence number; a camera's stamps strictly increase - the camera core drops a frame not
    after the previous one -, and the twin's are its capture times)."""
    return msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos, msg.frame_id


def segments_of(run_dir: Path, component: str) -> list[Path]:
    """``<component>.mcap``, ``<component>.1.mcap``... in ``run_dir`` (segment order)."""
    found = [(0, p) for p in [run_dir / f"{component}.mcap"] if p.is_file()]
    for p in run_dir.glob(f"{component}.*.mcap"):
        n = p.name[len(component) + 1:-len(".mcap")]
        if n.isdigit():
            found.append((int(n), p))
    return [p for _, p in sorted(found)]


def live_producers(run_dir: Path, fresh_s: float = 10.0) -> Callable[[str, str], tuple[str, ...]]:
    """``producers(topic, me)`` of a live shell: the producers of ``topic`` (other than ``me``)
    whose recording is in ``run_dir`` and was written to in the last ``fresh_s`` s (a producer
    opens its recording before it publishes and writes to it at least every
    ``flush_interval_s`` while images flow; a stale file of an earlier run does not count)."""

    def producers(topic: str, me: str) -> tuple[str, ...]:
        now = time.time()
        out = []
        for name in IMAGE_PRODUCERS.get(topic, ()):
            if name == me:
                continue
            try:
                if any(now - p.stat().st_mtime <= fresh_s for p in segments_of(run_dir, name)):
                    out.append(name)
            except OSError:
                continue
        return tuple(out)

    return producers


@dataclass
class ImagePolicy:
    """What a :class:`Recorder` keeps of images (foxglove.RawImage): ``[record]``
    (``config.RecordConfig``) applied to one component's recording.

    An input image on a bus topic is recorded as a REFERENCE when ``references`` and
    ``producers(topic, component)`` names a producer recording into the same run; an output
    image whose pixels equal those of the last input image is recorded SAME_AS_INPUT;
    any other image (the producer's output, the camera's capture, a consumer's input with
    no producer recorded) keeps its pixels for one in ``keep_every`` per topic (0: none),
    the others are OMITTED."""

    component: str
    keep_every: int = 1
    references: bool = True
    producers: Callable[[str, str], tuple[str, ...]] = lambda topic, me: ()
    policy_text: str = "all"

    @classmethod
    def from_config(cls, component: str, record, producers) -> ImagePolicy:
        """From a ``config.RecordConfig``."""
        return cls(component, record.keep_every, record.image_inputs == "reference", producers, record.images)


class Recorder:
    """Writes one component's inputs and outputs to an MCAP file.

    Call it from one thread (the shell's worker).  With ``background=True`` the MCAP
    writing and the chunks' compression run on a writer thread of the recorder's own
    (zstd releases the GIL, so compression overlaps the caller's work); the caller only
    appends each message to a batch, handed to the thread when it holds a quarter of
    ``chunk_size`` bytes or :data:`BATCH_MESSAGES` messages, on :meth:`flush` and every
    ``flush_interval_s`` (by a timer, even when no message comes).  At most
    :data:`QUEUED_BATCHES` batches wait for the thread (the caller then waits: back-pressure,
    not unbounded memory).  Either way a crash loses at most the messages given in the last
    ``flush_interval_s`` (the timer flushes that long after the last flush) plus those the
    writer is compressing and writing at that moment (and, with the thread, the batches
    queued for it when it lags).  One thread writes, in the
    order the messages were given: the file holds the same messages in the same order
    as without the thread.  :meth:`close` drains the queue.

    A write error (a full disk, EIO...) never raises to the caller, in either mode: the
    recorder cuts the file back to its last complete chunk (still a readable recording),
    counts every message it could not keep (by direction and topic: the chunk in progress
    and all later ones), and every ``flush_interval_s``, once the file system has
    :attr:`min_free_bytes` free, opens the next segment (``<stem>.N.mcap``, its metadata
    naming the segment it continues).  Recording has resumed when a first chunk of that
    segment is in the file.  The caller polls :attr:`news` (a deque, cheap to test) for
    ``(code, text)`` pairs: ``record_error`` when an outage starts (what was lost so
    far), ``record_resumed`` when it ends (what it lost).  :meth:`losses` sums it up and
    is saved as ``<first segment stem>.losses.json`` beside the recording (at each error
    and resumption, and at :meth:`close`); no such file: nothing was lost.
    """

    BATCH_MESSAGES = 256  # a batch's size in messages, at most
    QUEUED_BATCHES = 2  # batches waiting for the writer thread, at most

    def __init__(
        self,
        path: str | Path,
        metadata: dict[str, Any],
        *,
        chunk_size: int = 1024 * 1024,
        flush_interval_s: float = 1.0,
        compression: str = "zstd",
        background: bool = False,
        images: ImagePolicy | None = None,
    ):
        self._queue: queue.Queue | None = None
        self._images = images
        self._image_refs: dict[str, tuple[str, ...]] = {}  # input topic -> producers referenced
        self._image_counts: dict[tuple[str, str], int] = {}  # (direction, topic) -> images seen
        self._last_in_image: tuple[str, RawImage] | None = None  # (topic, message) of the last input image
        self._thread: threading.Thread | None = None
        self._base = Path(path)
        self._chunk_size = chunk_size
        self._comp = {
            "zstd": CompressionType.ZSTD,
            "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE,
        }[compression]
        self._meta = {
            k: v if isinstance(v, str) else json.dumps(v, sort_keys=True)
            for k, v in metadata.items()
        }
        self._meta.setdefault("schema_version", str(topics.SCHEMA_VERSION))
        # Resume only into room for a couple of chunks: a disk that frees a few pages
        # (the cut-off chunk's) would fail again at once.
        self.min_free_bytes = 2 * chunk_size + 64 * 1024
        self.segments: list[Path] = []
        self._writer: Writer | None = None
        self._file: _SegmentFile | None = None
        self._count = 0
        self._flush_interval_s = flush_interval_s
        self._last_flush = time.monotonic()
        self._lock = threading.Lock()  # between the caller and the flush timer
        self._unflushed = 0  # messages given since the last flush
        self._stop_timer = threading.Event()
        self.bytes_written = 0
        self._closed = False
        self._batch: list[tuple] = []
        self._batch_bytes = 0
        self._batch_limit = max(1, chunk_size // 4)
        # Losses (writer side; read by the caller only through ``news`` and after close).
        self.news: deque[tuple[str, str]] = deque()
        self._lost: dict[tuple[str, str], int] = {}  # (direction, topic) -> messages
        self._lost_n = 0
        self._lost_t: list[int] = []  # [first, last] log time (ns) of a lost message
        self._outages: list[dict[str, Any]] = []
        self._outage: dict[str, Any] | None = None  # the one in progress
        self._retry_at = 0.0
        try:
            self._open_segment()
        except OSError as e:  # before the run: a clear error, the component does not start
            raise RecordingError(f"cannot start recording {self._base}: {e}") from e
        self.path = self.segments[0]  # the segment being written (the last one opened)
        self.losses_path = self.path.with_name(f"{self.path.stem}.losses.json")
        if background:
            self._queue = queue.Queue(maxsize=self.QUEUED_BATCHES)
            self._thread = threading.Thread(
                target=self._drain, name=f"recorder-{self.path.stem}", daemon=True
            )
            self._thread.start()
        # Flushes on wall time, whether messages come or not (a component that stops producing
        # still has its last messages in the file within flush_interval_s).
        self._timer = threading.Thread(target=self._flush_timer, name=f"recorder-flush-{self.path.stem}",
                                       daemon=True)
        self._timer.start()

    # -- segments --------------------------------------------------------------------------
    def _open_segment(self) -> None:
        """Open the next segment and write its header and metadata (raises OSError)."""
        path, f = _open_new_segment(self._base)
        meta = dict(self._meta)
        if self._outages:  # a continuation: replay cannot rebuild the core's state here
            meta["continues"] = self.segments[-1].name if self.segments else ""
            meta["lost_before"] = str(self._lost_n)
        try:
            writer = Writer(f, chunk_size=self._chunk_size, compression=self._comp)
            writer.start(profile="humanpt", library="humanpt")
            writer.add_metadata(RUN_METADATA, meta)
        except BaseException:
            f.close()
            path.unlink(missing_ok=True)
            raise
        self._writer, self._file, self.path = writer, f, path
        self.segments.append(path)
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple, int] = {}  # (direction, topic, variant) -> channel id
        self._chan_keys: list[tuple[str, str]] = [("", "")]  # channel id -> (direction, topic)
        self._pend: list[int] = [0]  # channel id -> messages not yet in the file
        self._pend_t: list[int] = []  # [first, last] log time of those
        self._raw_schema: int | None = None
        self._committed_pos = f.pos  # the file ends here at a record boundary
        self._seg_messages = 0  # messages of this segment in the file
        self._probation = bool(self._outage)  # resumed once a first chunk is in the file

    def _commit(self) -> None:
        """The messages given so far are in the file (a chunk was written whole)."""
        self._committed_pos = self._file.pos
        n = sum(self._pend)
        if n:
            self._seg_messages += n
            self._pend = [0] * len(self._pend)
            self._pend_t = []
            if self._probation:
                self._resumed()

    def _fail(self, e: BaseException) -> None:
        """A write failed: count what is lost, cut the file back, wait for room."""
        if not isinstance(e, OSError):
            log.exception("recording to %s failed", self.path)
        lost_before = self._lost_n
        pend: dict[tuple[str, str], int] = {}
        for cid, n in enumerate(self._pend):
            if n:  # several channels may share a (direction, topic): images with and without pixels
                pend[self._chan_keys[cid]] = pend.get(self._chan_keys[cid], 0) + n
        for key, n in pend.items():
            self._lose(key, n, self._pend_t)
        lost_now = sum(pend.values())
        f, path, kept = self._file, self.path, self._seg_messages
        self._writer, self._file = None, None
        try:
            if kept:
                os.ftruncate(f.fd, self._committed_pos)  # a clean end after the last whole chunk
            f.close()
            if not kept:
                path.unlink(missing_ok=True)  # nothing of it was kept
                self.segments.remove(path)
        except OSError as e2:
            log.warning("recording: could not tidy %s after the write error: %s", path, e2)
            f.close()
        self._retry_at = time.monotonic() + self._flush_interval_s
        if self._probation:  # the resumed segment failed before its first chunk: same outage
            self._probation = False
            return
        now = time.time_ns()
        self._outage = {"error": str(e) or type(e).__name__, "segment": path.name, "start_ns": now,
                        "end_ns": None, "lost": lost_before}
        self._outages.append(self._outage)
        self.news.append(("record_error", (
            f"recording stopped: cannot write {path.name}: {self._outage['error']}; "
            f"{lost_now} messages lost so far{f' ({_by_topic_text(pend)})' if pend else ''}; "
            f"retrying every {self._flush_interval_s:g} s (with {self.min_free_bytes // 1024} KiB free) "
            f"in a new segment")))
        self._save_losses()

    def _lose(self, key: tuple[str, str], n: int, times: list[int]) -> None:
        self._lost[key] = self._lost.get(key, 0) + n
        self._lost_n += n
        if times:
            if not self._lost_t:
                self._lost_t = [times[0], times[-1]]
            else:
                self._lost_t[0] = min(self._lost_t[0], times[0])
                self._lost_t[1] = max(self._lost_t[1], times[-1])

    def _resumed(self) -> None:
        self._probation = False
        o, self._outage = self._outage, None
        now = time.time_ns()
        o["end_ns"] = now
        o["lost"] = self._lost_n - o["lost"]
        o["resumed_in"] = self.path.name
        self.news.append(("record_resumed", (
            f"recording resumed in {self.path.name} after {(now - o['start_ns']) / 1e9:.1f} s: "
            f"{o['lost']} messages lost in this outage, {self._lost_n} in all ({_by_topic_text(self._lost)})")))
        self._save_losses()

    def _retry(self) -> bool:
        """At most every ``flush_interval_s``: open the next segment if there is room."""
        now = time.monotonic()
        if now < self._retry_at:
            return False
        self._retry_at = now + self._flush_interval_s
        try:
            st = os.statvfs(self._base.parent)
            if st.f_bavail * st.f_frsize < self.min_free_bytes:
                return False
        except (OSError, AttributeError):
            pass  # no statvfs here: opening the segment will tell
        try:
            self._open_segment()
        except Exception as e:  # noqa: BLE001 - still no room (or no disk): keep waiting
            if self._outage is not None:
                self._outage["retry_error"] = str(e)
            return False
        return True

    def losses(self) -> dict[str, Any]:
        """What was lost: segments written, messages lost (in all and by direction and
        topic), first and last log time (ns) of a lost message, and each outage (wall-clock
        start and end in ns, the error, messages lost, the segment it resumed in)."""
        by: dict[str, dict[str, int]] = {}
        for (d, t), n in sorted(self._lost.items()):
            by.setdefault(d, {})[t] = n
        return {"component": self._meta.get("component", ""), "segments": [p.name for p in self.segments],
                "lost": self._lost_n, "lost_by_topic": by,
                "first_lost_ns": self._lost_t[0] if self._lost_t else None,
                "last_lost_ns": self._lost_t[1] if self._lost_t else None,
                "outages": [dict(o) for o in self._outages], "closed": self._closed}

    def _save_losses(self) -> None:
        """Write :meth:`losses` beside the recording (atomically; on a full disk it may
        fail: logged, tried again at the next resumption and at close)."""
        try:
            write_atomic(self.losses_path, json.dumps(self.losses(), indent=1) + "\n")
        except OSError as e:
            log.warning("recording: could not write %s: %s", self.losses_path, e)

    def summary(self) -> str:
        """One line: the segments written and what was lost."""
        if self.segments:
            text = "recording " + " + ".join([str(self.segments[0])] + [p.name for p in self.segments[1:]])
        else:
            text = f"recording {self._base}: nothing kept"
        if self._lost_n or self._outages:
            text += (f"; LOST {self._lost_n} messages ({_by_topic_text(self._lost) or 'none'}) in "
                     f"{len(self._outages)} write outage(s), first: {self._outages[0]['error']}"
                     f"{'; not recording at the end' if self._outage is not None else ''} (see {self.losses_path.name})")
        return text

    # -- writing ---------------------------------------------------------------------------
    @staticmethod
    def _ordinary_task() -> None:
        # In a realtime process (SCHED_FIFO, runtime.tuning) a thread would inherit the class,
        # and a chunk's compression would hold a CPU against the link's threads of the same
        # priority (FIFO does not share a CPU among them): the recorder's threads are ordinary.
        if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) != os.SCHED_OTHER:
            try:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            except OSError:
                pass

    def _flush_timer(self) -> None:
        """Flush ``flush_interval_s`` after the last flush, messages or not: what was given is
        in the file (written to the OS: a killed process loses none of it) at most
        ``flush_interval_s`` after it was given, plus the time to compress and write it."""
        self._ordinary_task()
        while True:
            due_in = min(self._last_flush + self._flush_interval_s - time.monotonic(), threading.TIMEOUT_MAX)
            if due_in > 0:
                if self._stop_timer.wait(due_in):
                    return
                continue
            with self._lock:
                if self._closed:
                    return
                now = time.monotonic()
                if now - self._last_flush < self._flush_interval_s:
                    continue  # the caller flushed meanwhile
                self._last_flush = now
                if not self._unflushed and (self._writer is not None or self._queue is not None):
                    continue  # nothing new (a write outage's retry goes on: the flush item retries)
                self._unflushed = 0
                if self._queue is None:
                    self._do("flush")
                    continue
                self._batch.append(("flush",))
                try:
                    self._queue.put_nowait(self._batch)  # never wait here holding the caller's lock
                    self._batch, self._batch_bytes = [], 0
                except queue.Full:  # the writer thread is busy: again shortly
                    self._batch.pop()
                    self._last_flush = now - self._flush_interval_s + min(0.05, self._flush_interval_s)

    def _drain(self) -> None:
        self._ordinary_task()
        while True:
            batch = self._queue.get()
            if batch is None:
                return
            for item in batch:
                try:
                    self._do(*item)
                except BaseException:  # noqa: BLE001 - the thread must live, or the caller blocks
                    log.exception("recording: writer thread")

    def _do(self, kind: str, *args) -> None:
        """Write one item (``("msg", direction, t_ns, topic, type, payload)`` or
        ``("flush",)``); on a write error count it lost instead.  Never raises."""
        if self._writer is None and not self._retry():
            if kind == "msg":
                self._lose((args[0], args[2]), 1, [args[1]])
            return
        # A full disk must not stop the component: no error leaves here.
        if kind == "msg":
            direction, t_ns, topic, msg_type, payload, variant = args
            try:
                cid = self._channel(direction, topic, msg_type, variant)
            except Exception as e:  # noqa: BLE001 - registering the channel ended a chunk, which failed
                self._lose((direction, topic), 1, [t_ns])
                self._fail(e)
                return
            try:
                self._add(cid, t_ns, payload)  # counts the message pending first
            except Exception as e:  # noqa: BLE001
                self._fail(e)
        elif kind == "flush":
            try:
                self._flush_now()
            except Exception as e:  # noqa: BLE001
                self._fail(e)

    def _submit(self, item: tuple, size: int = 0) -> None:
        """Write ``item`` now, or batch it for the writer thread."""
        with self._lock:
            self._submit_locked(item, size)

    def _submit_locked(self, item: tuple, size: int) -> None:
        self._unflushed += 1
        due = time.monotonic() - self._last_flush >= self._flush_interval_s
        if due:
            self._last_flush = time.monotonic()
            self._unflushed = 0
        if self._queue is None:
            self._do(*item)
            if due:
                self._do("flush")
            return
        self._batch.append(item)
        self._batch_bytes += size
        if due:
            self._batch.append(("flush",))
        if due or self._batch_bytes >= self._batch_limit or len(self._batch) >= self.BATCH_MESSAGES:
            self._hand_over()

    def _hand_over(self) -> None:
        if self._batch:
            self._queue.put(self._batch)
            self._batch, self._batch_bytes = [], 0

    def _channel(self, direction: str, topic: str, msg_type: type[Message] | None,
                 variant: tuple[tuple[str, str], ...] = ()) -> int:
        key = (direction, topic, variant)
        cid = self._channels.get(key)
        if cid is None:
            if direction == SNAPSHOT:
                sid, enc = 0, "json"  # schema-less JSON (MCAP allows it; Foxglove shows it)
            elif msg_type is None:
                if self._raw_schema is None:
                    self._raw_schema = self._writer.register_schema(
                        name="raw", encoding="", data=b""
                    )
                sid, enc = self._raw_schema, "raw"
            else:
                full = msg_type.DESCRIPTOR.full_name
                if full not in self._schemas:
                    self._schemas[full] = register_schema(self._writer, msg_type)
                sid, enc = self._schemas[full], "protobuf"
            cid = self._writer.register_channel(
                topic=topic, message_encoding=enc, schema_id=sid, metadata={"direction": direction, **dict(variant)}
            )
            self._channels[key] = cid
            self._chan_keys.append((direction, topic))
            self._pend.append(0)
            if self._file.pos != self._committed_pos:  # registering ended a chunk
                self._commit()
            # The channel once more outside the chunks (the chunk holding it may be damaged, and
            # a file never closed has no summary to repeat it): a record of its own, at once.
            schema = msg_type.DESCRIPTOR.full_name if msg_type is not None else "json" if direction == SNAPSHOT else "raw"
            self._writer.add_metadata(CHANNELS_METADATA, {str(cid): json.dumps(
                {"topic": topic, "schema": schema, "encoding": enc,
                 "metadata": {"direction": direction, **dict(variant)}}, sort_keys=True)})
            self._committed_pos = self._file.pos  # the file ends at a record boundary; nothing committed
        return cid

    def write(
        self, direction: str, t_ns: int, topic: str, msg: Message, data: bytes | None = None
    ) -> None:
        """Record one input (``IN``) or output (``OUT``) at time ``t_ns``.

        ``data`` may pass the already serialised bytes of ``msg`` to save work.
        """
        variant: tuple[tuple[str, str], ...] = ()
        if self._images is not None and type(msg) is RawImage:
            variant = self._image_variant(direction, topic, msg)
            if variant:  # the pixels are elsewhere, or not kept
                data = strip_image(msg).SerializeToString()
        payload = msg.SerializeToString() if data is None else data
        self._submit(("msg", direction, t_ns, topic, type(msg), payload, variant), len(payload))

    def _image_variant(self, direction: str, topic: str, msg: RawImage) -> tuple[tuple[str, str], ...]:
        """The channel metadata saying where this image's pixels are (empty: here); see
        :class:`ImagePolicy`."""
        p = self._images
        if direction == IN:
            self._last_in_image = (topic, msg)  # its pixels are read only if an output image follows
            if p.references and "/" in topic:
                refs = self._image_refs.get(topic)
                if refs is None:  # decided at the first image: the producer is recording by then
                    refs = self._image_refs[topic] = tuple(p.producers(topic, p.component))
                if refs:
                    return (("payload", REFERENCE), ("producers", ",".join(refs)), ("ref_topic", topic))
        elif self._last_in_image is not None and msg.data and msg.data == self._last_in_image[1].data:
            return (("payload", SAME_AS_INPUT), ("ref_topic", self._last_in_image[0]))
        key = (direction, topic)
        n = self._image_counts.get(key, 0)
        self._image_counts[key] = n + 1
        if p.keep_every == 1 or (p.keep_every and n % p.keep_every == 0):
            return ()
        return (("payload", OMITTED), ("policy", p.policy_text))

    def write_snapshot(self, t_ns: int, payload: bytes) -> None:
        """Record the core's state frozen after its input at ``t_ns`` (JSON bytes,
        runtime/snapshot.py), between that input's outputs and the next input."""
        self._submit(("msg", SNAPSHOT, t_ns, SNAPSHOT, None, payload, ()), len(payload))

    def write_dropped(self, t_ns: int, topic: str, payload: bytes) -> None:
        """Record an input that failed to decode, raw."""
        self._submit(("msg", DROPPED, t_ns, topic, None, payload, ()), len(payload))

    def _add(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        # Pending first: if add_message fails (ending a chunk), this message is lost too.
        self._pend[channel_id] += 1
        pt = self._pend_t
        if pt:
            pt[1] = t_ns
        else:
            self._pend_t = [t_ns, t_ns]
        self._writer.add_message(
            channel_id=channel_id,
            log_time=int(t_ns),
            data=payload,
            publish_time=int(t_ns),
            sequence=self._count,
        )
        self._count += 1
        self.bytes_written += len(payload)
        if self._file.pos != self._committed_pos:
            # A chunk (holding this message too) was written whole.
            self._commit()

    def flush(self) -> None:
        """End the chunk in progress and put it in the file (with ``background=True``:
        once the writer thread gets there)."""
        with self._lock:
            self._last_flush = time.monotonic()
            self._unflushed = 0
            if self._queue is None:
                self._do("flush")
            else:
                self._batch.append(("flush",))
                self._hand_over()

    def _flush_now(self) -> None:
        self._writer.flush()
        if self._file.pos != self._committed_pos:
            self._commit()

    def close(self) -> None:
        """Write the summary and close the file (idempotent).  Never raises for a write
        error: what was lost is in :meth:`losses`, :meth:`summary` and the losses file."""
        if self._closed:
            return
        self._stop_timer.set()
        with self._lock:  # a timed flush in progress ends first
            self._closed = True
        self._timer.join()
        if self._thread is not None:
            self._hand_over()
            self._queue.put(None)
            self._thread.join()
        if self._writer is not None:
            try:
                self._writer.finish()
                self._file.close()
                self._writer = None
            except Exception as e:  # noqa: BLE001
                self._fail(e)
        if self._lost_n or self._outages:
            self._save_losses()
            log.warning("%s", self.summary())

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def losses_lines(run_dir: str | Path) -> list[str]:
    """One line per component whose recording lost messages to a write error (its
    ``<component>.losses.json``, see runtime/README.md); none when nothing was lost."""
    out = []
    for f in sorted(Path(run_dir).glob("*.losses.json")):
        try:
            d = json.loads(f.read_text())
            out.append(f"RECORDING LOST {d['lost']} messages of {d['component']} in {len(d['outages'])} "
                       f"write outage(s) ({d['outages'][0]['error'] if d['outages'] else '?'}): {f}")
        except (OSError, ValueError, KeyError, TypeError, IndexError, RecursionError) as e:
            out.append(f"RECORDING LOSSES: {f} cannot be read ({type(e).__name__}: {e})")
    return out


@dataclass
class Entry:
    """One recorded message."""

    index: int
    direction: str  # IN, OUT or DROPPED
    t_ns: int
    topic: str
    data: bytes
    schema: str  # full protobuf type name, or "raw"
    payload: str = FULL  # FULL, or where the pixels of an image are (channel metadata, see FULL)
    channel: dict[str, str] = field(default_factory=dict)  # the channel's metadata (shared: read only)
    missing: str = ""  # an image still without its pixels after resolve_images: why

    def decode(self) -> Message:
        """The message, decoded with this build's schema for its topic."""
        cls = topics.message_type(self.topic)
        if cls.DESCRIPTOR.full_name != self.schema:
            raise RecordingError(
                f"topic {self.topic!r} was recorded as {self.schema}, "
                f"this version reads it as {cls.DESCRIPTOR.full_name}"
            )
        msg = cls()
        try:
            msg.ParseFromString(self.data)
        except DecodeError as e:
            raise RecordingError(
                f"message {self.index} on {self.topic!r} does not decode: {e}"
            ) from e
        return msg


@dataclass(frozen=True)
class SnapshotEntry:
    """A core's state frozen into its recording (:data:`SNAPSHOT`): after the first ``at``
    entries of the file (the input it followed and that input's outputs), JSON ``data``."""

    at: int
    t_ns: int
    data: bytes


@dataclass
class Recording:
    """A component recording read back: metadata, entries in file order, truncation."""

    path: Path
    metadata: dict[str, str]
    entries: list[Entry] = field(default_factory=list)
    truncated: str | None = None  # why it could not be read in full (the first note), None when it was
    notes: list[str] = field(default_factory=list)  # every reason (damage, skipped chunks, messages not read)
    first_gap: int | None = None  # entries read before the first skipped chunk (messages missing there)
    # Inputs without their pixels that replay cannot get (replay.missing_inputs): what, else None.
    missing: str | None = None
    resolved: bool = False  # images recorded without their pixels were looked up (replay.missing_inputs)
    snapshots: list[SnapshotEntry] = field(default_factory=list)  # in file order

    @property
    def component(self) -> str:
        return self.metadata.get("component", "")

    @property
    def inputs(self) -> list[Entry]:
        return [e for e in self.entries if e.direction == IN]

    @property
    def outputs(self) -> list[Entry]:
        return [e for e in self.entries if e.direction == OUT]

    def config(self) -> dict[str, Any]:
        """The recorded config (raises RecordingError, one line, when it is not a JSON table)."""
        table = recorded_json(self.metadata.get("config", "{}"), f"{self.path}: its recorded config")
        return topics.current_config(self.component, table)  # (keys an older version had, dropped)


def recorded_json(text: str, what: str) -> dict[str, Any]:
    """A JSON table a recording holds (its config), or a RecordingError naming ``what``:
    not JSON, not a table, or nested too deeply for the parser (a crafted file)."""
    try:
        value = json.loads(text)
    except RecursionError:
        raise RecordingError(f"{what} is nested too deeply to be read (a damaged or crafted file)") from None
    except ValueError as e:
        raise RecordingError(f"{what} is not valid JSON ({e})") from None
    if not isinstance(value, dict):
        raise RecordingError(f"{what} is a JSON {type(value).__name__}, not a table")
    return value


def iter_records(path: Path, skipped: list[str] | None = None) -> Iterator[Any]:
    """MCAP records of ``path``, chunks opened: first the schemas, channels and statistics of
    its summary section (when the file was closed and its summary is sound), then the data
    section in file order.  Raises :class:`RecordingDamage` (a clear line: the file, the
    offset, what is wrong) where the file stops being readable: cut inside a record, ended
    without its summary (a writer killed), a record whose framing is broken (with a sound
    summary, reading resumes at the next chunk it indexes, and ``skipped`` says what was
    jumped over).

    A chunk is decompressed only when what it declares is plausible (:data:`MAX_CHUNK_BYTES`,
    :data:`MAX_RATIO`), and never into more than it declares.  A chunk refused, or whose
    content is damaged (CRC, compression), is skipped, its description appended to
    ``skipped``, and reading goes on with the next record: one bad chunk does not hide the
    rest of the file.  Without ``skipped`` it raises at the bad chunk instead."""
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(8) != MAGIC:
            raise RecordingDamage(f"{path}: does not start with the MCAP magic")
        footer = _footer(f, size)
        summary_notes: list[str] = []  # a summary not used loses no message: said at the end
        summary = None if footer is None else _read_summary(f, size, footer, path, summary_notes)
        resume: list[int] = []
        try:
            if summary is not None:
                yield from summary.records
                resume = sorted(summary.chunk_starts)
            yield from _scan(f, size, path, resume, skipped)
        finally:
            if skipped is not None:
                skipped.extend(summary_notes)
        if summary_notes and skipped is None:
            raise RecordingDamage(summary_notes[0])
        if footer is None:  # the data section ended (DataEnd) but the file does not close
            raise RecordingDamage(f"{path}: its footer or closing magic is missing or damaged (the last bytes "
                                  f"are cut or overwritten)")


class RecordingDamage(Exception):
    """Where and why a recording stops being readable (one line, naming the file and offset)."""


class _ChunkRefused(Exception):
    """A chunk not decompressed: what it declares is not plausible, or its content is damaged."""


@dataclass
class _Summary:
    records: list[Any]  # Schema, Channel, Statistics of the summary section
    chunk_starts: list[int]  # where its chunk indexes say chunks start


_FOOTER_TAIL = 1 + 8 + 20 + 8  # the footer record (opcode, length, 20 bytes) and the closing magic
# Records the reader needs the body of; the others (indexes, attachments, the header) are stepped over.
_READ_OPS = {Opcode.CHUNK: Chunk, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel, Opcode.METADATA: Metadata,
             Opcode.MESSAGE: McapMessage, Opcode.STATISTICS: Statistics, Opcode.CHUNK_INDEX: ChunkIndex}


def _parse(op: int, body: bytes) -> Any:
    stream = ReadDataStream(io.BytesIO(body))
    cls = _READ_OPS[op]
    return cls.read(stream, len(body)) if cls is McapMessage else cls.read(stream)


def _footer(f, size: int) -> bytes | None:
    """The footer record and closing magic of a closed file, else None."""
    if size < 8 + _FOOTER_TAIL:
        return None
    f.seek(size - _FOOTER_TAIL)
    tail = f.read(_FOOTER_TAIL)
    if tail[-8:] != MAGIC or tail[0] != Opcode.FOOTER or struct.unpack_from("<Q", tail, 1)[0] != 20:
        return None
    return tail


def _read_summary(f, size: int, tail: bytes, path: Path, skipped: list[str]) -> _Summary | None:
    """The summary section the footer ``tail`` names (its CRC checked when it has one), else None."""
    footer_at = size - _FOOTER_TAIL
    start, _, crc = struct.unpack_from("<QQI", tail, 9)
    if start == 0:
        return _Summary([], [])
    if not 8 <= start <= footer_at:
        skipped.append(f"{path}: its footer puts the summary at offset {start}, outside the file: summary not used")
        return None
    f.seek(start)
    region = f.read(footer_at - start)
    if crc and zlib.crc32(tail[:1 + 8 + 16], zlib.crc32(region)) != crc:
        skipped.append(f"{path}: its summary section (offset {start}) fails its CRC: not used")
        return None
    out = _Summary([], [])
    pos = 0
    while pos + 9 <= len(region):
        op, length = struct.unpack_from("<BQ", region, pos)
        if length > len(region) - pos - 9:
            break
        if op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.STATISTICS, Opcode.CHUNK_INDEX):
            try:
                rec = _parse(op, region[pos + 9:pos + 9 + length])
            except _DAMAGE:
                break
            if isinstance(rec, ChunkIndex):
                out.chunk_starts.append(rec.chunk_start_offset)
            else:
                out.records.append(rec)
        pos += 9 + length
    return out


def _chunk_data(chunk: Chunk) -> bytes:
    """The records of ``chunk``, decompressed only if what it declares is plausible and never
    beyond it; raises :class:`_ChunkRefused` saying why not."""
    n, clen, comp = chunk.uncompressed_size, len(chunk.data), chunk.compression
    name = comp or "uncompressed"
    if comp not in MAX_RATIO:
        raise _ChunkRefused(f"compression {comp!r} is not one a recording uses (zstd, lz4 or none)")
    if n > MAX_CHUNK_BYTES:
        raise _ChunkRefused(f"it declares {n} bytes uncompressed from {clen} bytes of {name}, more than the "
                            f"reader's limit of {MAX_CHUNK_BYTES // 2**20} MiB per chunk: refused, not decompressed")
    if n > MAX_RATIO[comp] * clen + _RATIO_SLACK:
        raise _ChunkRefused(f"it declares {n} bytes uncompressed from {clen} bytes of {name}, more than "
                            f"{name} can expand them to ({MAX_RATIO[comp]}:1): refused, not decompressed")
    if comp == "zstd":
        parts, want = [], n + 1  # one byte more than declared tells a chunk that lies
        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data)) as r:
            while want > 0:
                part = r.read(min(want, 1 << 20))
                if not part:
                    break
                parts.append(part)
                want -= len(part)
        data = b"".join(parts)
    elif comp == "lz4":
        data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=n + 1)
    else:
        data = chunk.data
    if len(data) != n:
        raise _ChunkRefused(f"its {name} data holds {'more than' if len(data) > n else len(data)} bytes, "
                            f"not the {n} it declares")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise _ChunkRefused(f"CRC of its records is {zlib.crc32(data):#010x}, the chunk says "
                            f"{chunk.uncompressed_crc:#010x}")
    return data


_MESSAGE_HEAD = struct.Struct("<HIQQ")  # a Message record's channel id, sequence, log and publish times


def _chunk_records(data: bytes) -> list[Any]:
    """The records of a chunk's decompressed ``data``, as ``mcap``'s ``breakup_chunk`` reads
    them (the same records, the same errors on damage), its Message records unpacked here at
    once: read through ``mcap``'s stream, field by field, they were most of a recording's
    reading time (a 60 s twin run's eight recordings: 620 000 messages).  Whatever is not a
    whole Message record inside the data (a Schema, a Channel, a record cut short) is read by
    ``mcap`` as before."""
    out: list[Any] = []
    pos, n = 0, len(data)
    head, unpack_from = _MESSAGE_HEAD.unpack_from, struct.unpack_from
    while pos < n:
        if pos + 9 <= n:
            op, length = unpack_from("<BQ", data, pos)
            end = pos + 9 + length
            if op == Opcode.MESSAGE and length >= 22 and end <= n:
                channel_id, sequence, log_time, publish_time = head(data, pos + 9)
                out.append(McapMessage(channel_id=channel_id, log_time=log_time, data=data[pos + 31:end],
                                       publish_time=publish_time, sequence=sequence))
                pos = end
                continue
            if op in (Opcode.SCHEMA, Opcode.CHANNEL):
                body = io.BytesIO(data)
                body.seek(pos + 9)
                stream = ReadDataStream(body)
                out.append((Schema if op == Opcode.SCHEMA else Channel).read(stream))
                pos += 9 + stream.count  # (mcap steps by what it read, not by the record's length)
                continue
            if op != Opcode.MESSAGE and end <= n:  # a record of another kind: stepped over
                pos = end
                continue
        # the rest (a record cut short, a Message shorter than its fields): mcap's own reading
        out.extend(breakup_chunk(Chunk(compression="", data=data[pos:], message_start_time=0, message_end_time=0,
                                       uncompressed_crc=0, uncompressed_size=n - pos)))
        break
    return out


def _scan(f, size: int, path: Path, resume: list[int], skipped: list[str] | None) -> Iterator[Any]:
    """The data section's records from offset 8 (see :func:`iter_records`)."""
    pos = 8
    while True:
        if pos == size:
            raise RecordingDamage(f"{path}: ends at offset {size} without its summary: its writer did not "
                                  f"close it (killed or crashed)")
        f.seek(pos)
        head = f.read(9)
        problem = None
        if len(head) < 9:
            problem = f"cut inside the record header at offset {pos} (the file ends at {size})"
        else:
            op, length = struct.unpack("<BQ", head)
            if length > size - pos - 9:
                problem = (f"the record at offset {pos} (opcode {op:#04x}) declares {length} bytes, the file "
                           f"has {size - pos - 9} after it: cut there, or its framing is damaged")
            elif op == Opcode.CHUNK and length > MAX_CHUNK_BYTES + 4096:
                if skipped is None:
                    raise RecordingDamage(f"{path}: the chunk at offset {pos} is {length} bytes, more than the "
                                          f"reader's limit of {MAX_CHUNK_BYTES // 2**20} MiB")
                skipped.append(f"{path}: skipped a damaged chunk at offset {pos}: it is {length} bytes, more than the "
                               f"reader's limit of {MAX_CHUNK_BYTES // 2**20} MiB per chunk")
                pos += 9 + length
                continue
        if problem is not None:
            nxt = next((s for s in resume if s > pos and s < size), None)
            if nxt is None or skipped is None:
                raise RecordingDamage(f"{path}: {problem}")
            skipped.append(f"{path}: {problem}; resumed at the next chunk the summary indexes, offset {nxt}")
            pos = nxt
            continue
        if op in (Opcode.DATA_END, Opcode.FOOTER):
            return
        if op not in _READ_OPS or op in (Opcode.STATISTICS, Opcode.CHUNK_INDEX):
            pos += 9 + length
            continue
        body = f.read(length)
        try:
            rec = _parse(op, body)
        except _DAMAGE as e:
            rec, why = None, f"{type(e).__name__}{': ' + str(e) if str(e) else ''}"
        if rec is None or not isinstance(rec, Chunk):
            if rec is None:
                if skipped is None:
                    raise RecordingDamage(f"{path}: the record at offset {pos} (opcode {op:#04x}) does not parse "
                                          f"({why})")
                skipped.append(f"{path}: skipped the record at offset {pos} (opcode {op:#04x}): it does not "
                               f"parse ({why})")
            else:
                yield rec
            pos += 9 + length
            continue
        try:
            data = _chunk_data(rec)
            inner = _chunk_records(data)
        except _DAMAGE as e:
            if skipped is None:
                raise
            why = str(e) if isinstance(e, _ChunkRefused) else f"{type(e).__name__}: {e}"
            skipped.append(f"{path}: skipped a damaged chunk at offset {pos} (messages logged "
                           f"{rec.message_start_time}..{rec.message_end_time} ns): {why}")
        else:
            yield from inner
        pos += 9 + length


def _check_file(p: Path) -> None:
    if not p.exists():
        raise RecordingError(f"{p}: no such file")
    if p.is_dir():
        raise RecordingError(f"{p}: is a directory, not an MCAP recording")
    with open(p, "rb") as f:
        magic = f.read(8)
    if magic != MAGIC:
        raise RecordingError(f"{p}: not an MCAP file (it does not start with the MCAP magic)")


MAGIC = b"\x89MCAP0\r\n"
# What a chunk may declare before it is decompressed (issue 29: a 65 kB zstd chunk declaring
# 2 GiB took 2.19 GB and over a minute).  A humanpt chunk is [runtime] chunk_size (or [record]
# image_chunk_size) plus one message: the largest in the reference runs is 4.3 MB (camera images).
MAX_CHUNK_BYTES = 256 * 2**20
# ... and no more than its compression can make of its compressed bytes: zstd codes a 128 KiB
# block of one byte value in 4 bytes (32 768:1; 2 GiB of zeros is 65 kB, a black image ~16 000:1),
# an LZ4 frame at most ~255:1; stored (no compression): itself.
MAX_RATIO = {"zstd": 32768, "lz4": 256, "": 1}
_RATIO_SLACK = 64 * 1024  # a tiny chunk's frame headers
# Whatever a damaged file makes the MCAP reader raise (struct.error, zstd errors, ...): stop there.
_DAMAGE = Exception


def _channel_table(meta: dict[str, str]) -> dict[int, tuple[str, str, str, dict[str, str]]]:
    """Channels named by a ``humanpt.channels`` metadata record: id -> (topic, direction,
    schema name, channel metadata); malformed items are left out."""
    out = {}
    for key, text in meta.items():
        try:
            d = json.loads(text)
            md = {str(k): str(v) for k, v in dict(d.get("metadata", {})).items()}
            out[int(key)] = (topics.current_topic(str(d["topic"])), md.get("direction", OUT),
                             str(d.get("schema", "raw")), md)
        except (ValueError, TypeError, KeyError, AttributeError, RecursionError):
            continue
    return out


def iter_entries(
    path: str | Path, notes: list[str] | None = None, metadata: dict[str, str] | None = None,
    gaps: list[int] | None = None, snapshots: list[SnapshotEntry] | None = None,
) -> Iterator[Entry]:
    """Messages of a recording in file order, one at a time (constant memory).

    Stops quietly at damage (a truncated file, one not closed) and appends why to ``notes``,
    with every chunk skipped, the messages whose channel is unknown and, when the summary
    counts more messages than were read, how many were; fills ``metadata`` with the
    ``humanpt.run`` record when given.  Channels are known from the summary section (a closed
    file), the chunks, and the ``humanpt.channels`` records the :class:`Recorder` writes
    outside the chunks (a file whose chunk declaring them is damaged and which was never
    closed).  ``gaps`` gets, for each chunk or record skipped, the number of entries yielded
    before it (messages are missing there).  The core's snapshots are never yielded; ``snapshots``
    gets them.
    """
    p = Path(path)
    _check_file(p)
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str, int | str, dict[str, str]]] = {}
    # The schema name of each channel as its humanpt.channels record says: a Channel record read
    # from a later chunk may name a schema whose record was in a skipped chunk (the mcap writer
    # ends a chunk after a large schema record, so the channel goes in the next one).
    named_schemas: dict[int, str] = {}
    n = 0
    n_snapshots = 0
    unknown = 0
    no_schema = 0
    expected: int | None = None
    skipped: list[str] = []
    n_skipped = 0
    try:
        for r in iter_records(p, skipped):
            if gaps is not None and len(skipped) > n_skipped:  # a chunk skipped just before this record
                gaps.append(n)
            n_skipped = len(skipped)
            if isinstance(r, McapMessage):  # (first: nearly every record is one)
                ch = channels.get(r.channel_id)
                if ch is None:  # its channel was in a skipped chunk, and nowhere else
                    unknown += 1
                    if gaps is not None and n not in gaps:
                        gaps.append(n)
                    continue
                topic, direction, sid, meta = ch
                if direction == SNAPSHOT:
                    n_snapshots += 1
                    if snapshots is not None:
                        snapshots.append(SnapshotEntry(n, r.log_time, r.data))
                    continue
                schema = sid if isinstance(sid, str) else "raw" if sid == 0 else (
                    schemas.get(sid) or named_schemas.get(r.channel_id))
                if schema is None:  # its schema was in a skipped chunk, and named nowhere else
                    no_schema += 1
                    if gaps is not None and n not in gaps:
                        gaps.append(n)
                    continue
                yield Entry(n, direction, r.log_time, topic, r.data, schema, meta.get("payload", FULL), meta)
                n += 1
            elif isinstance(r, Schema):
                schemas[r.id] = r.name
            elif isinstance(r, Channel):
                channels[r.id] = (topics.current_topic(r.topic), r.metadata.get("direction", OUT), r.schema_id,
                                  dict(r.metadata))
            elif isinstance(r, Statistics):
                expected = r.message_count
            elif isinstance(r, Metadata) and r.name == CHANNELS_METADATA:
                for cid, ch in _channel_table(r.metadata).items():
                    channels.setdefault(cid, ch)
                    named_schemas.setdefault(cid, str(ch[2]))
            elif isinstance(r, Metadata) and r.name == RUN_METADATA and metadata is not None:
                metadata.update(r.metadata)
    except _DAMAGE as e:
        if notes is not None:
            why = str(e) if isinstance(e, RecordingDamage) else f"{type(e).__name__}{': ' + str(e) if str(e) else ''}"
            notes.append(f"{p}: truncated or damaged after {n} messages ({why})")
    finally:
        if notes is not None:
            notes.extend(skipped)
            if unknown:
                notes.append(f"{p}: {unknown} messages left out: their channel was declared only in a "
                             f"skipped chunk")
            if no_schema:
                notes.append(f"{p}: {no_schema} messages left out: the schema of their channel was declared "
                             f"only in a skipped chunk")
            if expected is not None and n + n_snapshots < expected:
                notes.append(f"{p}: {n + n_snapshots} of the {expected} messages its summary counts were read")


def merge_entries(files: list[Path], notes: list[str], keep: Callable[[Entry], bool] = lambda e: True,
                  *, stripped: bool = False) -> Iterator[tuple[int, Path, Entry]]:
    """(log time ns, file, entry) of several recordings, merged by log time (ties: the
    files' order, then each file's order), for the entries ``keep`` accepts.  A file that
    cannot be read at all is left out with a note; a damaged one is read to the damage and
    past its bad chunks (notes say what was skipped): one bad file does not refuse a run.
    Images recorded without their pixels (a reference, an image ``[record] images`` did not
    keep) are left out unless ``stripped``: each image of the run once, with its pixels."""

    def stream(i: int, f: Path) -> Iterator[tuple[int, int, int, Path, Entry]]:
        try:
            for e in iter_entries(f, notes):
                if (stripped or e.payload == FULL) and keep(e):
                    yield e.t_ns, i, e.index, f, e
        except RecordingError as err:
            notes.append(f"{err} - left out")

    for t_ns, _, _, f, e in heapq.merge(*(stream(i, f) for i, f in enumerate(files)),
                                        key=lambda item: item[:3]):
        yield t_ns, f, e


def resolve_images(rec: Recording) -> list[Entry]:
    """Put back the pixels of the images ``rec`` recorded without them (in place; each entry
    given its pixels becomes FULL): a REFERENCE from the producer's recording in the same
    directory (every segment), matched by topic, stamp and frame_id; a SAME_AS_INPUT from
    the last input on its ``ref_topic`` before it.  Returns the entries left without pixels
    (OMITTED by the policy, or not found: a truncated producer recording), and says why in
    each entry's ``missing``.  A producer recording that is not there at all is a
    :class:`RecordingError` naming the file."""
    wanted: dict[tuple[str, tuple[str, ...]], dict[tuple[int, str], list[Entry]]] = {}
    for e in rec.entries:
        if e.payload == REFERENCE:
            key = (e.channel.get("ref_topic", e.topic), tuple(e.channel.get("producers", "").split(",")))
            ident = image_identity(_parse_image(e))
            wanted.setdefault(key, {}).setdefault(ident, []).append(e)
    run_dir = rec.path.parent
    for (topic, producers), idents in wanted.items():
        files = [f for name in producers for f in segments_of(run_dir, name)]
        if not files:
            names = " or ".join(f"{run_dir / name}.mcap" for name in producers)
            raise RecordingError(
                f"{rec.path}: {sum(len(v) for v in idents.values())} {topic} images of this recording are "
                f"references to the recording of {' or '.join(producers)} in the same run directory, and "
                f"{names} is missing (keep a run's recordings together; [record] image_inputs = \"keep\" "
                f"records the pixels in each consumer)")
        notes: list[str] = []
        found: dict[tuple[int, str], tuple[bytes, bytes]] = {}  # identity -> (message, without pixels)
        omitted: set[tuple[int, str]] = set()
        policy = "?"
        for f in files:
            producer_in: dict[str, Entry] = {}  # the producer's last input image per topic
            for pe in _readable_entries(f, notes):
                if pe.schema != RawImage.DESCRIPTOR.full_name:
                    continue
                if pe.direction == IN:
                    producer_in[pe.topic] = pe
                    continue
                if pe.topic != topic:
                    continue
                msg = _parse_image(pe)
                ident = image_identity(msg)
                if ident not in idents:
                    continue
                src = producer_in.get(pe.channel.get("ref_topic", "")) if pe.payload == SAME_AS_INPUT else None
                if src is not None and src.payload == FULL:
                    # the producer recorded this image as a copy of its own input (the camera
                    # publishes what it captured): its pixels are that input's
                    msg.data = _parse_image(src).data
                    pe = dataclasses.replace(pe, data=msg.SerializeToString(), payload=FULL)
                if pe.payload != FULL:
                    omitted.add(ident)
                    policy = pe.channel.get("policy", "?")
                elif found.setdefault(ident, (pe.data, strip_image(msg).SerializeToString()))[0] != pe.data:
                    raise RecordingError(f"{f}: two different {topic} images share stamp {ident[0]} ns and "
                                         f"frame_id {ident[1]!r}: a reference to them is ambiguous")
        where = ", ".join(f.name for f in files)
        for ident, entries in idents.items():
            data, header = found.get(ident, (None, None))
            for e in entries:
                if data is not None and header == e.data:  # the same image: size, encoding... too
                    e.data, e.payload = data, FULL
                elif data is not None:
                    e.missing = f"{where} holds an image of this stamp and frame_id of another size or encoding"
                elif ident in omitted:
                    e.missing = f"{where} kept its pixels only for [record] images = {policy!r}"
                else:
                    e.missing = f"not in {where}" + (f" ({notes[0]})" if notes else "")
    last_in: dict[str, Entry] = {}
    for e in rec.entries:
        if e.payload == SAME_AS_INPUT:
            src = last_in.get(e.channel.get("ref_topic", ""))
            if src is not None and src.payload == FULL:
                msg = _parse_image(e)
                msg.data = _parse_image(src).data  # the input's pixels
                e.data, e.payload = msg.SerializeToString(), FULL
            else:
                e.missing = (f"a copy of the {e.channel.get('ref_topic')} input before it, which is "
                             f"{'missing' if src is not None else 'not in the recording'}")
        elif e.direction == IN and e.schema == RawImage.DESCRIPTOR.full_name:
            last_in[e.topic] = e
        if e.payload == OMITTED and not e.missing:
            e.missing = f"[record] images = {e.channel.get('policy', '?')!r} did not keep its pixels"
    return [e for e in rec.entries if e.payload != FULL]


def _readable_entries(f: Path, notes: list[str]) -> Iterator[Entry]:
    """``iter_entries(f)``, or nothing (with a note) when ``f`` cannot be read at all."""
    try:
        yield from iter_entries(f, notes)
    except RecordingError as err:
        notes.append(str(err))


def _parse_image(e: Entry) -> RawImage:
    msg = RawImage()
    try:
        msg.ParseFromString(e.data)
    except DecodeError as err:
        raise RecordingError(f"message {e.index} on {e.topic!r} does not decode: {err}") from err
    return msg


def read_metadata(path: str | Path) -> tuple[dict[str, str], bool]:
    """(the ``humanpt.run`` metadata, whether the file was closed properly)."""
    p = Path(path)
    _check_file(p)
    meta: dict[str, str] = {}
    try:
        for r in iter_records(p, []):
            if isinstance(r, Metadata) and r.name == RUN_METADATA:
                meta = dict(r.metadata)
                break
    except _DAMAGE:
        pass
    with open(p, "rb") as f:
        f.seek(-8, 2)
        complete = f.read(8) == MAGIC
    if not meta:
        raise RecordingError(f"{p}: not a humanpt recording: no {RUN_METADATA!r} metadata")
    return meta, complete


def _current_names(meta: dict[str, str]) -> None:
    """A recording of a renamed component (topics.RENAMED_COMPONENTS) reads under its name now:
    its ``component`` and its core's class path (``humanpt.<old>.`` -> ``humanpt.<new>.``, then
    a renamed core class, topics.RENAMED_CORES)."""
    for old, new in topics.RENAMED_COMPONENTS.items():
        if meta.get("component") == old:
            meta["component"] = new
        if meta.get("core", "").startswith(f"humanpt.{old}."):
            meta["core"] = f"humanpt.{new}." + meta["core"][len(f"humanpt.{old}."):]
    if meta.get("core") in topics.RENAMED_CORES:
        meta["core"] = topics.RENAMED_CORES[meta["core"]]


def read(path: str | Path, *, require_humanpt: bool = True) -> Recording:
    """Read a whole recording in file order.

    A truncated or damaged file reads up to the damage and sets ``truncated``.  A missing
    file, a file that is not MCAP, a recording without humanpt metadata or one written by
    a newer or incompatible schema version raises :class:`RecordingError` saying which.
    """
    p = Path(path)
    notes: list[str] = []
    meta: dict[str, str] = {}
    gaps: list[int] = []
    snapshots: list[SnapshotEntry] = []
    entries = list(iter_entries(p, notes, meta, gaps, snapshots))
    _current_names(meta)
    rec = Recording(path=p, metadata=meta, entries=entries, truncated=notes[0] if notes else None, notes=notes,
                    first_gap=min(gaps) if gaps else None, snapshots=snapshots)
    if require_humanpt:
        if not rec.metadata:
            why = f" ({rec.truncated})" if rec.truncated else ""
            raise RecordingError(f"{p}: not a humanpt recording: no {RUN_METADATA!r} metadata{why}")
        version = rec.metadata.get("schema_version", "?")
        if version != str(topics.SCHEMA_VERSION):
            raise RecordingError(
                f"{p}: written with schema version {version}; this humanpt "
                f"reads schema version {topics.SCHEMA_VERSION}"
            )
    return rec

