"""Recording a component's run to MCAP, and reading it back (even when truncated).

A component's recording ``<run dir>/<component>.mcap`` holds, in the order the core saw
them, every input it consumed (channel metadata ``direction=in``, log time = the time
given to the core) and every output it produced (``direction=out``, log time = the
time of the step that produced it).  Inputs that failed to decode are kept raw on a
``direction=dropped`` channel, so nothing is lost.  Schemas are registered as protobuf
FileDescriptorSets so Foxglove and rerun open the files.  A metadata record
``humanpt.run`` holds the component, its core class, its config, the version and the
start time; replay builds the core from it.

The stream is flushed to the file whenever a chunk is finalised, and the writer is flushed every ``flush_interval_s`` of
wall time and whenever a chunk fills, so a crash loses at most the chunk in progress.
"""

from __future__ import annotations

import json
import queue
import struct
import threading
import time
import zlib
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zstandard
from google.protobuf.message import DecodeError, Message
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, MessageIndex, Metadata, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer
from mcap_protobuf.schema import register_schema

from humanpt.schemas import topics

RUN_METADATA = "humanpt.run"
IN, OUT, DROPPED = "in", "out", "dropped"


class RecordingError(ValueError):
    """A recording that cannot be read: missing, not MCAP, not a humanpt recording, or
    written by an incompatible schema version.  The message says which."""


_local = threading.local()


def _zstd_chunk(data: bytes) -> tuple[bytes, int]:
    """(zstd of ``data`` as ``zstandard.compress`` makes it, crc32 of ``data``)."""
    compressor = getattr(_local, "zstd", None)
    if compressor is None:
        compressor = _local.zstd = zstandard.ZstdCompressor()  # = zstandard.compress's, reused
    return compressor.compress(data), zlib.crc32(data)


_compressor: ThreadPoolExecutor | None = None
_compressor_lock = threading.Lock()


def _compressor_pool() -> ThreadPoolExecutor:
    global _compressor
    with _compressor_lock:
        if _compressor is None:
            _compressor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcap-zstd")
        return _compressor


def _pipeline_ok() -> bool:
    """PipelinedWriter overrides private methods of mcap's Writer as they are in mcap 1.6;
    with another mcap the plain writer is used (same file, no helper thread)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("mcap")
    except PackageNotFoundError:
        return False
    return (v.startswith("1.6.") and hasattr(Writer, "_Writer__finalize_chunk")
            and hasattr(Writer, "_Writer__maybe_finalize_chunk"))


class PipelinedWriter(Writer):
    """An MCAP writer (zstd chunks) that compresses each finished chunk on a helper thread
    (zstd and crc32 release the GIL) while the caller carries on.

    The file is byte for byte what :class:`mcap.writer.Writer` writes: a chunk goes into the
    stream, with its message indexes, before anything written after it (the next chunk,
    metadata, a flush, the summary).  Until then it is *pending*: :meth:`write_ready`
    writes it once its compression is done.  Relies on the internals of mcap's Writer
    (name-mangled attributes; checked against mcap 1.6).
    """

    def __init__(self, output, *, chunk_size: int):
        super().__init__(output, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._pending: tuple[Future, int, int, int, dict] | None = None
        self._pool = _compressor_pool()
        self.chunks_written = 0

    def _Writer__finalize_chunk(self) -> None:  # replaces Writer.__finalize_chunk
        self._write_pending()
        builder = self._Writer__chunk_builder
        if not builder or builder.num_messages == 0:
            return
        self._Writer__statistics.chunk_count += 1
        data = builder.end()
        self._pending = (
            self._pool.submit(_zstd_chunk, data),
            len(data),
            builder.message_start_time,
            builder.message_end_time,
            dict(builder.message_indices),
        )
        builder.reset()

    def write_ready(self) -> None:
        """Write the pending chunk if its compression is done."""
        if self._pending is not None and self._pending[0].done():
            self._write_pending()

    def _write_pending(self) -> None:
        if self._pending is None:
            return
        future, size, start, end, indices = self._pending
        self._pending = None
        compressed, crc = future.result()
        chunk = Chunk(
            compression="zstd",
            data=compressed,
            message_start_time=start,
            message_end_time=end,
            uncompressed_crc=crc if self._Writer__enable_crcs else 0,
            uncompressed_size=size,
        )
        # From here on exactly as Writer.__finalize_chunk.
        stream, records = self._Writer__stream, self._Writer__record_builder
        self._Writer__flush()
        chunk_start_offset = stream.tell()
        chunk.write(records)
        chunk_index = ChunkIndex(
            message_start_time=start,
            message_end_time=end,
            chunk_start_offset=chunk_start_offset,
            chunk_length=records.count,
            message_index_offsets={},
            message_index_length=0,
            compression=chunk.compression,
            compressed_size=len(compressed),
            uncompressed_size=size,
        )
        self._Writer__flush()
        message_index_start_offset = stream.tell()
        if self._Writer__index_types & IndexType.MESSAGE:
            for cid, index in indices.items():
                chunk_index.message_index_offsets[cid] = message_index_start_offset + records.count
                index.write(records)
        chunk_index.message_index_length = records.count
        self._Writer__flush()
        self._Writer__chunk_indices.append(chunk_index)
        self.chunks_written += 1

    _MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        """Writer.add_message's bookkeeping and bytes (a chunked writer's path), without a
        Message record object and five small writes per message: the same file."""
        stats = self._Writer__statistics
        if stats.message_count == 0:
            stats.message_start_time = log_time
        else:
            stats.message_start_time = min(log_time, stats.message_start_time)
        stats.message_end_time = max(log_time, stats.message_end_time)
        stats.channel_message_counts[channel_id] += 1
        stats.message_count += 1
        b = self._Writer__chunk_builder
        if b.num_messages == 0:
            b.message_start_time = log_time
        else:
            b.message_start_time = min(b.message_start_time, log_time)
        b.message_end_time = max(b.message_end_time, log_time)
        index = b.message_indices.get(channel_id)
        if not index:
            index = b.message_indices[channel_id] = MessageIndex(channel_id=channel_id, records=[])
        buf = b.record_writer._buffer
        index.records.append((log_time, buf.tell()))
        b.num_messages += 1
        buf.write(self._MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + len(data), channel_id, sequence, log_time,
                                          publish_time))
        buf.write(data)
        self._Writer__maybe_finalize_chunk()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._write_pending()
        super().add_metadata(name, data)

    def add_attachment(self, *args, **kwargs) -> None:
        self._write_pending()
        super().add_attachment(*args, **kwargs)

    def flush(self) -> None:
        self._Writer__finalize_chunk()
        self._write_pending()
        super().flush()

    def finish(self) -> None:
        self._Writer__finalize_chunk()
        self._write_pending()
        super().finish()


class Recorder:
    """Writes one component's inputs and outputs to an MCAP file.

    Call it from one thread (the shell's worker).  With ``background=True`` the MCAP
    writing and compression happen on a writer thread of their own (zstd releases the
    GIL), so recording costs the core's thread only a queue put; the queue is bounded
    (back-pressure rather than unbounded memory) and :meth:`close` drains it.  With
    ``pipeline=True`` (zstd only) the caller's thread does the MCAP writing but each
    chunk's compression runs on a helper thread (:class:`PipelinedWriter`, same bytes);
    a chunk reaches the file once compressed, so a crash may lose one more chunk.
    """

    def __init__(
        self,
        path: str | Path,
        metadata: dict[str, Any],
        *,
        chunk_size: int = 1024 * 1024,
        flush_interval_s: float = 1.0,
        compression: str = "zstd",
        background: bool = False,
        pipeline: bool = False,
    ):
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        comp = {
            "zstd": CompressionType.ZSTD,
            "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE,
        }[compression]
        if pipeline and comp == CompressionType.ZSTD and _PIPELINE_OK:
            self._pipelined: PipelinedWriter | None = PipelinedWriter(
                self._file, chunk_size=chunk_size
            )
            self._writer: Writer = self._pipelined
        else:
            self._pipelined = None
            self._writer = Writer(self._file, chunk_size=chunk_size, compression=comp)
        self._chunks_seen = 0
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
        if background:
            self._queue = queue.Queue(maxsize=512)
            self._thread = threading.Thread(
                target=self._drain, name=f"recorder-{self.path.stem}", daemon=True
            )
            self._thread.start()

    def _drain(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                self._do(*item)
            except BaseException as e:  # noqa: BLE001 - reported on close
                self._error = e

    def _do(self, kind: str, *args) -> None:
        if kind == "msg":
            direction, t_ns, topic, msg_type, payload = args
            self._add(self._channel(direction, topic, msg_type), t_ns, payload)
        elif kind == "flush":
            self._flush_now()

    def _submit(self, *item) -> None:
        if self._queue is not None:
            self._queue.put(item)
        else:
            self._do(*item)

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
        self._submit("msg", direction, t_ns, topic, type(msg), payload)

    def write_dropped(self, t_ns: int, topic: str, payload: bytes) -> None:
        """Record an input that failed to decode, raw."""
        self._submit("msg", DROPPED, t_ns, topic, None, payload)

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
        if self._pipelined is not None:
            self._pipelined.write_ready()
            if self._pipelined.chunks_written != self._chunks_seen:
                # A chunk went into the stream buffer: put it in the file now.
                self._file.flush()
                self._chunks_seen = self._pipelined.chunks_written
        else:
            pos = self._file.tell()
            if pos != self._stream_pos:
                # A chunk was finalised into the stream buffer: put it in the file now.
                self._file.flush()
                self._stream_pos = pos
        now = time.monotonic()
        if now - self._last_flush >= self._flush_interval_s:
            self._flush_now()

    def flush(self) -> None:
        """End the chunk in progress and put it in the file."""
        self._submit("flush")

    def _flush_now(self) -> None:
        self._writer.flush()
        self._stream_pos = self._file.tell()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        if not self._closed:
            self._closed = True
            if self._thread is not None:
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


def iter_records(path: Path) -> Iterator[Any]:
    """MCAP records of ``path`` in file order; stops (raising McapError/EOFError) at damage."""
    with open(path, "rb") as f:
        yield from StreamReader(f, skip_magic=False, emit_chunks=False, validate_crcs=True).records


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
    try:
        for r in iter_records(p):
            if isinstance(r, Schema):
                schemas[r.id] = r.name
            elif isinstance(r, Channel):
                channels[r.id] = (r.topic, r.metadata.get("direction", OUT), r.schema_id)
            elif isinstance(r, Metadata) and r.name == RUN_METADATA and metadata is not None:
                metadata.update(r.metadata)
            elif isinstance(r, McapMessage):
                topic, direction, sid = channels[r.channel_id]
                yield Entry(n, direction, r.log_time, topic, r.data, schemas.get(sid, "raw"))
                n += 1
    except _DAMAGE as e:
        if notes is not None:
            notes.append(
                f"{p}: truncated or damaged after {n} messages ({type(e).__name__}{': ' + str(e) if str(e) else ''})"
            )


def read_metadata(path: str | Path) -> tuple[dict[str, str], bool]:
    """(the ``humanpt.run`` metadata, whether the file was closed properly)."""
    p = Path(path)
    _check_file(p)
    meta: dict[str, str] = {}
    try:
        for r in iter_records(p):
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


_PIPELINE_OK = _pipeline_ok()
