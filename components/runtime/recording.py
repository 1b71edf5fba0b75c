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
``chunk_size`` bytes).  Each finished chunk is put in the file at once, and the chunk in
progress is ended and put in the file every ``flush_interval_s`` of wall time, so a crash
loses at most the chunk in progress (plus, with ``background=True``, the messages still
queued for the writer thread: at most about one more chunk's worth, see :class:`Recorder`).
"""

from __future__ import annotations

import heapq
import json
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from google.protobuf.message import DecodeError, Message
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Metadata, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema

from humanpt.schemas import topics

RUN_METADATA = "humanpt.run"
IN, OUT, DROPPED = "in", "out", "dropped"


class RecordingError(ValueError):
    """A recording that cannot be read: missing, not MCAP, not a humanpt recording, or
    written by an incompatible schema version.  The message says which."""


def _open_new_segment(path: Path):
    """Open ``path`` for writing, never over an existing file: a component restarted into
    the same run directory writes ``<stem>.1.mcap``, ``<stem>.2.mcap``... beside the first
    recording. Returns (the path opened, the file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    candidate, n = path, 0
    while True:
        try:
            return candidate, open(candidate, "xb")  # noqa: SIM115 - closed by the Recorder
        except FileExistsError:
            n += 1
            candidate = path.with_name(f"{path.stem}.{n}{path.suffix}")


class Recorder:
    """Writes one component's inputs and outputs to an MCAP file.

    Call it from one thread (the shell's worker).  With ``background=True`` the MCAP
    writing and the chunks' compression run on a writer thread of the recorder's own
    (zstd releases the GIL, so compression overlaps the caller's work); the caller only
    appends each message to a batch, handed to the thread when it holds a quarter of
    ``chunk_size`` bytes or :data:`BATCH_MESSAGES` messages, on :meth:`flush` and every
    ``flush_interval_s``.  At most :data:`QUEUED_BATCHES` batches wait for the thread (the
    caller then waits: back-pressure, not unbounded memory), so a crash loses at most the
    chunk in progress and about one chunk's worth of messages not yet written (the batch
    being filled, the queued ones and the one being written).  One thread writes, in the
    order the messages were given: the file holds the same messages in the same order
    as without the thread.  :meth:`close` drains the queue.
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
    ):
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.path, self._file = _open_new_segment(Path(path))
        comp = {
            "zstd": CompressionType.ZSTD,
            "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE,
        }[compression]
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=comp)
        self._writer.start(profile="humanpt", library="humanpt")
        meta = {
            k: v if isinstance(v, str) else json.dumps(v, sort_keys=True)
            for k, v in metadata.items()
        }
        meta.setdefault("schema_version", str(topics.SCHEMA_VERSION))
        self._writer.add_metadata(RUN_METADATA, meta)
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._raw_schema: int | None = None
        self._count = 0
        self._flush_interval_s = flush_interval_s
        self._last_flush = time.monotonic()
        self._stream_pos = self._file.tell()
        self.bytes_written = 0
        self._closed = False
        self._batch: list[tuple] = []
        self._batch_bytes = 0
        self._batch_limit = max(1, chunk_size // 4)
        if background:
            self._queue = queue.Queue(maxsize=self.QUEUED_BATCHES)
            self._thread = threading.Thread(
                target=self._drain, name=f"recorder-{self.path.stem}", daemon=True
            )
            self._thread.start()

    def _drain(self) -> None:
        while True:
            batch = self._queue.get()
            if batch is None:
                return
            try:
                for item in batch:
                    self._do(*item)
            except BaseException as e:  # noqa: BLE001 - reported on close
                self._error = e

    def _do(self, kind: str, *args) -> None:
        if kind == "msg":
            direction, t_ns, topic, msg_type, payload = args
            self._add(self._channel(direction, topic, msg_type), t_ns, payload)
        elif kind == "flush":
            self._flush_now()

    def _submit(self, item: tuple, size: int = 0) -> None:
        """Write ``item`` now, or batch it for the writer thread."""
        due = time.monotonic() - self._last_flush >= self._flush_interval_s
        if due:
            self._last_flush = time.monotonic()
        if self._queue is None:
            self._do(*item)
            if due:
                self._flush_now()
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

    def _channel(self, direction: str, topic: str, msg_type: type[Message] | None) -> int:
        key = (direction, topic)
        cid = self._channels.get(key)
        if cid is None:
            if msg_type is None:
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
                topic=topic, message_encoding=enc, schema_id=sid, metadata={"direction": direction}
            )
            self._channels[key] = cid
        return cid

    def write(
        self, direction: str, t_ns: int, topic: str, msg: Message, data: bytes | None = None
    ) -> None:
        """Record one input (``IN``) or output (``OUT``) at time ``t_ns``.

        ``data`` may pass the already serialised bytes of ``msg`` to save work.
        """
        payload = msg.SerializeToString() if data is None else data
        self._submit(("msg", direction, t_ns, topic, type(msg), payload), len(payload))

    def write_dropped(self, t_ns: int, topic: str, payload: bytes) -> None:
        """Record an input that failed to decode, raw."""
        self._submit(("msg", DROPPED, t_ns, topic, None, payload), len(payload))

    def _add(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        self._writer.add_message(
            channel_id=channel_id,
            log_time=int(t_ns),
            data=payload,
            publish_time=int(t_ns),
            sequence=self._count,
        )
        self._count += 1
        self.bytes_written += len(payload)
        pos = self._file.tell()
        if pos != self._stream_pos:
            # A chunk was finalised into the stream buffer: put it in the file now.
            self._file.flush()
            self._stream_pos = pos

    def flush(self) -> None:
        """End the chunk in progress and put it in the file (with ``background=True``:
        once the writer thread gets there)."""
        if self._queue is None:
            self._flush_now()
        else:
            self._batch.append(("flush",))
            self._hand_over()

    def _flush_now(self) -> None:
        self._writer.flush()
        self._stream_pos = self._file.tell()

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        if not self._closed:
            self._closed = True
            if self._thread is not None:
                self._hand_over()
                self._queue.put(None)
                self._thread.join()
            self._writer.finish()
            self._file.flush()
            self._file.close()
            if self._error is not None:
                raise RecordingError(
                    f"{self.path}: recording failed: {self._error}"
                ) from self._error

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass
class Entry:
    """One recorded message."""

    index: int
    direction: str  # IN, OUT or DROPPED
    t_ns: int
    topic: str
    data: bytes
    schema: str  # full protobuf type name, or "raw"

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


@dataclass
class Recording:
    """A component recording read back: metadata, entries in file order, truncation."""

    path: Path
    metadata: dict[str, str]
    entries: list[Entry] = field(default_factory=list)
    truncated: str | None = None  # why reading stopped early, None when complete

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
        return json.loads(self.metadata.get("config", "{}"))


def iter_records(path: Path, skipped: list[str] | None = None) -> Iterator[Any]:
    """MCAP records of ``path`` in file order, chunks opened; stops (raising McapError,
    EOFError...) where the file itself is cut or its record framing is broken.

    A chunk whose content is damaged (CRC, compression) is skipped, its description appended
    to ``skipped``, and reading goes on with the next record: one bad chunk does not hide
    the rest of the file.  Without ``skipped`` it raises at the bad chunk instead."""
    with open(path, "rb") as f:
        for record in StreamReader(f, skip_magic=False, emit_chunks=True, validate_crcs=True).records:
            if not isinstance(record, Chunk):
                yield record
                continue
            try:
                inner = breakup_chunk(record, validate_crc=True)
            except _DAMAGE as e:
                if skipped is None:
                    raise
                skipped.append(f"{path}: skipped a damaged chunk of messages logged "
                               f"{record.message_start_time}..{record.message_end_time} ns "
                               f"({type(e).__name__}: {e})")
                continue
            yield from inner


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
# Whatever a damaged file makes the MCAP reader raise (struct.error, zstd errors, ...): stop there.
_DAMAGE = (McapError, EOFError, Exception)


def iter_entries(
    path: str | Path, notes: list[str] | None = None, metadata: dict[str, str] | None = None
) -> Iterator[Entry]:
    """Messages of a recording in file order, one at a time (constant memory).

    Stops quietly at damage (a truncated file) and appends why to ``notes``; fills
    ``metadata`` with the ``humanpt.run`` record when given.
    """
    p = Path(path)
    _check_file(p)
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str, int]] = {}
    n = 0
    skipped: list[str] = []
    try:
        for r in iter_records(p, skipped):
            if isinstance(r, Schema):
                schemas[r.id] = r.name
            elif isinstance(r, Channel):
                channels[r.id] = (r.topic, r.metadata.get("direction", OUT), r.schema_id)
            elif isinstance(r, Metadata) and r.name == RUN_METADATA and metadata is not None:
                metadata.update(r.metadata)
            elif isinstance(r, McapMessage):
                if r.channel_id not in channels:  # its channel was in a skipped chunk
                    continue
                topic, direction, sid = channels[r.channel_id]
                yield Entry(n, direction, r.log_time, topic, r.data, schemas.get(sid, "raw"))
                n += 1
    except _DAMAGE as e:
        if notes is not None:
            notes.append(
                f"{p}: truncated or damaged after {n} messages ({type(e).__name__}{': ' + str(e) if str(e) else ''})"
            )
    finally:
        if notes is not None:
            notes.extend(skipped)


def merge_entries(files: list[Path], notes: list[str], keep: Callable[[Entry], bool] = lambda e: True,
                  ) -> Iterator[tuple[int, Path, Entry]]:
    """(log time ns, file, entry) of several recordings, merged by log time (ties: the
    files' order, then each file's order), for the entries ``keep`` accepts.  A file that
    cannot be read at all is left out with a note; a damaged one is read to the damage and
    past its bad chunks (notes say what was skipped): one bad file does not refuse a run."""

    def stream(i: int, f: Path) -> Iterator[tuple[int, int, int, Path, Entry]]:
        try:
            for e in iter_entries(f, notes):
                if keep(e):
                    yield e.t_ns, i, e.index, f, e
        except RecordingError as err:
            notes.append(f"{err} - left out")

    for t_ns, _, _, f, e in heapq.merge(*(stream(i, f) for i, f in enumerate(files)),
                                        key=lambda item: item[:3]):
        yield t_ns, f, e


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


def read(path: str | Path, *, require_humanpt: bool = True) -> Recording:
    """Read a whole recording in file order.

    A truncated or damaged file reads up to the damage and sets ``truncated``.  A missing
    file, a file that is not MCAP, a recording without humanpt metadata or one written by
    a newer or incompatible schema version raises :class:`RecordingError` saying which.
    """
    p = Path(path)
    notes: list[str] = []
    meta: dict[str, str] = {}
    entries = list(iter_entries(p, notes, meta))
    rec = Recording(path=p, metadata=meta, entries=entries, truncated=notes[0] if notes else None)
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

