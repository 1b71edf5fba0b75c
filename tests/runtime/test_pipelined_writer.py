"""PipelinedWriter (chunk compression on a helper thread) writes the same bytes as mcap's Writer."""

import io

from mcap.writer import CompressionType, Writer

from humanpt.runtime.recording import PipelinedWriter


def _write(writer_factory) -> bytes:
    buf = io.BytesIO()
    w = writer_factory(buf)
    w.start(profile="humanpt", library="humanpt")
    w.add_metadata("m", {"k": "v"})
    sid = w.register_schema(name="raw", encoding="", data=b"")
    chans = [
        w.register_channel(topic=f"t{i}", message_encoding="raw", schema_id=sid) for i in range(3)
    ]
    for n in range(400):
        size = 300_000 if n % 37 == 0 else 50 + n
        payload = bytes((n * 7 + k) % 251 for k in range(min(size, 64))) * (size // 64 + 1)
        w.add_message(
            chans[n % 3], log_time=n * 1000, data=payload[:size], publish_time=n * 1000, sequence=n
        )
        if isinstance(w, PipelinedWriter) and n % 5 == 0:
            w.write_ready()
        if n % 150 == 149:
            w.flush()
    w.add_metadata("late", {"a": "b"})
    w.finish()
    return buf.getvalue()


def test_pipelined_writer_is_byte_identical():
    plain = _write(lambda f: Writer(f, chunk_size=16 * 1024, compression=CompressionType.ZSTD))
    piped = _write(lambda f: PipelinedWriter(f, chunk_size=16 * 1024))
    assert piped == plain
