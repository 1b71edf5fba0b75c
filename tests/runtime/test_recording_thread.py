"""Recording on a writer thread (``Recorder(background=True)``, what the lock-step and live
shells use): the same file as writing in the caller's thread, and a crash loses at most
what the Recorder documents."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from humanpt.runtime.recording import IN, OUT, Recorder, read
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from tests.conftest import ROOT

META = {"component": "ponger", "core": "humanpt.runtime.selftest:PongerCore"}


def _payload(n: int) -> bytes:
    """Message n's event text: every 37th one 300 kB (several chunks' worth), else short."""
    size = 300_000 if n % 37 == 0 else 50 + n
    return bytes((n * 7 + k) % 251 for k in range(64)) * (size // 64 + 1)


def _record(path, background: bool, n: int = 400, chunk_size: int = 16 * 1024, close=True):
    # flush_interval_s: no wall-time flush, so that chunk boundaries depend on the data alone.
    rec = Recorder(path, META, chunk_size=chunk_size, flush_interval_s=1e9, background=background)
    for i in range(n):
        rec.write(IN, i * 1000, "pinger/ping", pb.Tick(header=header(i * 1000, i), period_ns=1000))
        rec.write(OUT, i * 1000, "ponger/pong", pb.Event(header=header(i * 1000, i),
                                                         text=_payload(i).hex()[:2 * (50 + i)]))
        if i % 37 == 0:
            rec.write_dropped(i * 1000, "pinger/ping", _payload(i))
        if i % 150 == 149:
            rec.flush()
    if close:
        rec.close()
    return rec


def test_writer_thread_writes_the_same_file(tmp_path):
    inline, threaded = tmp_path / "inline.mcap", tmp_path / "threaded.mcap"
    _record(inline, background=False)
    _record(threaded, background=True)
    # Same messages, same order, same chunks: byte for byte the same file.
    assert threaded.read_bytes() == inline.read_bytes()
    rec = read(threaded)
    assert rec.truncated is None
    n_dropped = len(range(0, 400, 37))
    assert len(rec.entries) == 2 * 400 + n_dropped
    assert [e.decode().header.seq for e in rec.inputs] == list(range(400))


def test_writer_thread_crash_loses_at_most_two_chunks(tmp_path):
    """Killed without closing (os._exit), a background recorder loses at most the chunk in
    progress and about one chunk queued for its thread (Recorder's docstring)."""
    p = tmp_path / "crash.mcap"
    script = textwrap.dedent(f"""
        import os, sys
        sys.path.insert(0, {str(ROOT)!r})
        from humanpt.runtime.recording import IN, Recorder
        from humanpt.schemas import humanpt_pb2 as pb
        rec = Recorder({str(p)!r}, {{"component": "ponger"}}, chunk_size=4096, background=True)
        for i in range(3000):
            rec.write(IN, i, "ponger/pong", pb.Event(text=f"{{i:08d}}" * 8))
        os._exit(1)
    """)
    subprocess.run([sys.executable, "-c", script], check=False, timeout=60)
    rec = read(p)
    assert rec.truncated
    size = len(rec.entries[0].data) + 16  # payload + the MCAP message record's fields, roughly
    # Two chunks of 4 KiB, plus the few messages past a batch's quarter-chunk limit.
    lost = 3000 - len(rec.entries)
    assert lost <= 2 * 4096 // size + 4 * 2, (lost, size)
