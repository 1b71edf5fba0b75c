"""Recording: MCAP with schemas and metadata; truncated files read to the truncation; a crash
loses at most the last chunk; replay on missing or foreign files says so."""

from __future__ import annotations

import random
import subprocess
import sys
import textwrap

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from humanpt.runtime.recording import IN, OUT, Recorder, RecordingError, read, read_metadata
from humanpt.runtime.selftest import PongerConfig, PongerCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from tests.conftest import ROOT, run_cli_here


def _write(path, n, chunk_size=4096, close=True):
    rec = Recorder(path, {"component": "ponger", "core": "humanpt.runtime.selftest:PongerCore",
                          "config": {"prefix": "pong"}}, chunk_size=chunk_size)
    rng = random.Random(5)  # incompressible-ish text, so chunks are spread through the file
    for i in range(n):
        rec.write(IN, i * 1000, "pinger/ping", pb.Tick(header=header(i * 1000, i), period_ns=1000))
        text = "".join(rng.choice("0123456789abcdef") for _ in range(40))
        rec.write(OUT, i * 1000, "ponger/pong", pb.Event(header=header(i * 1000, i), text=text))
    if close:
        rec.close()
    return rec


def _ponger_run(path, n):
    """A recording of the real ponger core on ``n`` pings (so that it replays)."""
    core = PongerCore(PongerConfig())
    with Recorder(path, {"component": "ponger", "core": "humanpt.runtime.selftest:PongerCore",
                         "config": {"prefix": "pong"}}, chunk_size=2048) as rec:
        for i in range(n):
            ping = pb.Tick(header=header(i * 1000, i), period_ns=1000)
            rec.write(IN, i * 1000, "pinger/ping", ping)
            for topic, out in core.step(i * 1000, "pinger/ping", ping):
                rec.write(OUT, i * 1000, topic, out)


def test_recording_reads_back_with_schemas_and_metadata(tmp_path):
    p = tmp_path / "ponger.mcap"
    _write(p, 50)
    rec = read(p)
    assert rec.truncated is None and rec.component == "ponger"
    assert [e.direction for e in rec.entries[:4]] == [IN, OUT, IN, OUT]
    assert rec.inputs[7].decode().header.seq == 7
    assert rec.config() == {"prefix": "pong"}
    # Any MCAP reader sees protobuf schemas (what Foxglove and rerun use to decode).
    with open(p, "rb") as f:
        summary = make_reader(f).get_summary()
    assert {s.name for s in summary.schemas.values()} == {"humanpt.Tick", "humanpt.Event"}
    assert all(s.encoding == "protobuf" for s in summary.schemas.values())
    assert summary.statistics.message_count == 100


@pytest.mark.parametrize("fraction", [0.2, 0.5, 0.8])
def test_truncated_file_reads_up_to_the_truncation(tmp_path, fraction):
    p = tmp_path / "full.mcap"
    _write(p, 400)
    full = read(p).entries
    data = p.read_bytes()
    # Cut within the messages (the chunks), as a crash would: the summary after them (the
    # metadata, indexes) is a fifth of this small file and grows with the metadata.
    with p.open("rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    data_end = max(c.chunk_start_offset + c.chunk_length for c in chunks)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(data_end * fraction)])
    rec = read(cut)
    assert rec.truncated
    assert 0 < len(rec.entries) < len(full)
    assert [(e.topic, e.data) for e in rec.entries] == [(e.topic, e.data) for e in full[: len(rec.entries)]]


def test_file_missing_its_last_bytes_reads_every_message(tmp_path):
    p = tmp_path / "full.mcap"
    _write(p, 100)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(p.read_bytes()[:-1])
    rec = read(cut)
    assert rec.truncated and len(rec.entries) == 200


def test_crash_loses_at_most_the_last_chunk(tmp_path):
    """A writer killed without closing (os._exit) leaves a file that reads all finished chunks."""
    p = tmp_path / "crash.mcap"
    script = textwrap.dedent(f"""
        import os, sys
        sys.path.insert(0, {str(ROOT)!r})
        from tests.runtime.test_recording import _write
        _write({str(p)!r}, 300, chunk_size=4096, close=False)
        os._exit(1)
    """)
    subprocess.run([sys.executable, "-c", script], check=False, timeout=60)
    rec = read(p)
    assert rec.truncated
    # One chunk of 4 KiB holds about 4096 / 70 B ~ 60 messages: at most that is lost.
    assert len(rec.entries) >= 600 - 80, len(rec.entries)


def test_missing_and_foreign_files_say_so(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        read(tmp_path / "nope.mcap")
    txt = tmp_path / "notes.mcap"
    txt.write_text("hello")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        read(txt)
    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    with pytest.raises(RecordingError, match="not a humanpt recording"):
        read(foreign)
    with pytest.raises(RecordingError, match="not a humanpt recording"):
        read_metadata(foreign)


def test_schema_version_mismatch_is_named(tmp_path):
    p = tmp_path / "old.mcap"
    Recorder(p, {"component": "ponger", "schema_version": "0"}).close()
    with pytest.raises(RecordingError, match="written with schema version 0"):
        read(p)


def test_cli_replay_errors_are_clear(tmp_path):
    r = run_cli_here("replay", str(tmp_path / "missing"))
    assert r.returncode == 2 and "no such run directory or file" in r.stderr
    (tmp_path / "run").mkdir()
    r = run_cli_here("replay", str(tmp_path / "run"), "--component", "ponger")
    assert r.returncode == 2 and "no recording of component 'ponger'" in r.stderr
    (tmp_path / "run" / "ponger.mcap").write_text("not mcap")
    r = run_cli_here("replay", str(tmp_path / "run"), "--component", "ponger")
    assert r.returncode == 2 and "not an MCAP file" in r.stderr
    (tmp_path / "run" / "ponger.mcap").write_bytes(b"")
    r = run_cli_here("replay", str(tmp_path / "run"), "--component", "ponger")
    assert r.returncode == 2 and "not an MCAP file" in r.stderr and "MATCH" not in r.stdout


def test_cli_replay_never_says_match_on_nothing(tmp_path):
    """Exit statuses (components/runtime/README.md): 3 for a readable recording without
    inputs, 2 when not one message can be read, 0 only with outputs compared."""
    foreign = tmp_path / "foreign.mcap"  # a valid MCAP file, empty and not humanpt's
    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    r = run_cli_here("replay", str(foreign))
    assert r.returncode == 2 and "not a humanpt recording" in r.stderr and "MATCH" not in r.stdout

    empty = tmp_path / "empty" / "ponger.mcap"
    Recorder(empty, {"component": "ponger", "core": "humanpt.runtime.selftest:PongerCore"}).close()
    r = run_cli_here("replay", str(empty))
    assert r.returncode == 3, (r.stdout, r.stderr)
    assert "NOTHING COMPARED: the recording holds no inputs" in r.stdout and "MATCH:" not in r.stdout

    full = tmp_path / "full.mcap"
    _write(full, 400)
    data = full.read_bytes()
    # Cut inside the first chunk: the metadata is there, not one message can be read.
    with open(full, "rb") as f:
        first_chunk = min(c.chunk_start_offset for c in make_reader(f).get_summary().chunk_indexes)
    unreadable = tmp_path / "unreadable" / "ponger.mcap"
    unreadable.parent.mkdir()
    unreadable.write_bytes(data[: first_chunk + 40])
    assert read(unreadable).entries == [] and read_metadata(unreadable)[0]["component"] == "ponger"
    r = run_cli_here("replay", str(unreadable))
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "no message could be read" in r.stderr and "MATCH" not in r.stdout

    _ponger_run(tmp_path / "ponger.mcap", 400)
    data = (tmp_path / "ponger.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    n_out = len(read(cut).outputs)
    assert 0 < n_out < 400
    r = run_cli_here("replay", str(cut))
    # Not read in full: never a match (issue 29), however identical the part read is.
    assert r.returncode == 4, (r.stdout, r.stderr)
    assert f"{n_out} compared" in r.stdout and "could not be read in full" in r.stdout and "MATCH" not in r.stdout
    assert f"INCOMPLETE: the {n_out} outputs read are identical to the replay's" in r.stdout

    # A run directory with one good and one unreadable recording: the worst verdict.
    (tmp_path / "mixed").mkdir()
    (tmp_path / "mixed" / "a.mcap").write_bytes(data)
    (tmp_path / "mixed" / "b.mcap").write_bytes(unreadable.read_bytes())
    r = run_cli_here("replay", str(tmp_path / "mixed"))
    assert r.returncode == 2 and "MATCH: every output is identical (400 compared)" in r.stdout
    assert "b.mcap" in r.stderr and "no message could be read" in r.stderr


def test_background_recorder_writes_the_same_messages(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    for path, bg in ((a, False), (b, True)):
        rec = Recorder(path, {"component": "ponger"}, chunk_size=4096, background=bg)
        for i in range(300):
            rec.write(IN, i, "pinger/ping", pb.Tick(header=header(i, i)))
        rec.close()
    assert [(e.t_ns, e.data) for e in read(a).entries] == [(e.t_ns, e.data) for e in read(b).entries]
    assert len(read(b).entries) == 300
