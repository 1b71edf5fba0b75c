"""A component killed with SIGKILL keeps its recording up to the flush interval (issue 29, item 13).

The attack: SIGKILL of the gateway lost the last 0.93 s of robot_gateway.mcap (the chunk in
progress). The recorder now flushes on wall time, every ``[runtime] flush_interval_s``
(default 1 s), whether messages come or not. Here a real ``humanpt pinger`` process (the live
shell, its real recorder, a real router) is SIGKILLed and its file is read: it holds what the
process gave its recorder up to the interval before the kill, and it reads although the
killed writer never wrote the summary - also with its first chunk damaged (the channels come
from the ``humanpt.channels`` records: a killed file has no summary to repeat them)."""

from __future__ import annotations

import io
import queue
import signal
import struct
import time

import pytest
from mcap.opcode import Opcode
from mcap.records import Channel, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import Writer
from mcap_protobuf.schema import register_schema

from humanpt.runtime.recording import IN, OUT, Recorder, iter_entries, read
from humanpt.runtime.replay import EXIT_INCOMPLETE, replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from tests.conftest import run_cli, write_config, zenoh_client

pytestmark = pytest.mark.timeout(180)


def _chunks(data: bytes) -> list[tuple[int, int, list]]:
    """(offset, length with its 9-byte prefix, records inside) of each whole chunk of an MCAP
    file that may end mid-record (a killed writer), parsed by the mcap library."""
    out, pos = [], 8
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        if pos + 9 + length > len(data):
            break
        if op == Opcode.CHUNK:
            rec = next(iter(StreamReader(io.BytesIO(data[pos:pos + 9 + length]), skip_magic=True,
                                         emit_chunks=True).records))
            out.append((pos, 9 + length, breakup_chunk(rec)))
        pos += 9 + length
    return out


def _damage(data: bytes, offset: int, length: int) -> bytes:
    """``data`` with 32 bytes flipped in the middle of the chunk at ``offset`` (its CRC or its
    compression then refuses it)."""
    out = bytearray(data)
    mid = offset + length // 2
    out[mid:mid + 32] = bytes(b ^ 0xA5 for b in out[mid:mid + 32])
    return bytes(out)


def _ping_ids(records) -> list[int]:
    """Channel ids of pinger/ping declared in ``records``."""
    return [r.id for r in records if isinstance(r, Channel) and r.topic == "pinger/ping"]


def _pings(path) -> list[tuple[int, int]]:
    """(seq, stamp ns) of the pings recorded in ``path`` (outputs), read to the damage."""
    out = []
    for e in iter_entries(path, []):
        if e.direction == "out" and e.topic == "pinger/ping":
            m = e.decode()
            out.append((m.header.seq, m.header.stamp_ns))
    return out


def _wait_recorded(path, wanted, timeout: float = 30.0) -> None:
    """Until an entry ``wanted`` accepts is in the file (a bound on a hang: the flush interval
    is far shorter)."""
    deadline = time.monotonic() + timeout
    while not (path.exists() and any(wanted(e) for e in iter_entries(path, []))):
        assert time.monotonic() < deadline, f"the message did not reach {path} in {timeout} s"
        time.sleep(0.02)  # polling the file: no event says a chunk reached the disk


@pytest.mark.parametrize("thread", [True, False], ids=["record_thread", "foreground"])
def test_a_quiet_component_has_its_last_message_in_the_file_when_killed(router, procs, tmp_path, thread):
    """A component that goes quiet: the pinger's period set to a minute. Before, its last
    messages waited in the chunk (or the writer thread's batch) for the next message, a minute
    later, and a kill lost them. Now they are in the file within the interval."""
    port, _ = router
    cfg = write_config(tmp_path / "quiet.toml", port, extra=(
        f"record_thread = {str(thread).lower()}\nflush_interval_s = 0.2\n[pinger]\nperiod_ms = 50\n"))
    run = tmp_path / "run"
    with zenoh_client(port) as s:
        pings: queue.Queue = queue.Queue()
        events: queue.Queue = queue.Queue()
        subs = [s.declare_subscriber("humanpt/test/pinger/ping",
                                     lambda smp: pings.put(pb.Tick.FromString(smp.payload.to_bytes()))),
                s.declare_subscriber("humanpt/test/pinger/events",
                                     lambda smp: events.put(pb.Event.FromString(smp.payload.to_bytes())))]
        pinger = procs.start("pinger", "--config", str(cfg), "--run-dir", str(run))
        pings.get(timeout=60)  # it runs
        r = run_cli("param", "pinger", "period_ms=60000", "--config", str(cfg))
        assert r.returncode == 0, r.stdout + r.stderr
        while (ev := events.get(timeout=30)).code != "param_changed":
            pass
        # The event is an output of the pinger, given to its recorder; the next ping is a
        # minute away. It must reach the file without another message pushing it there.
        _wait_recorded(run / "pinger.mcap", lambda e: e.topic == "pinger/events" and e.data == ev.SerializeToString())
        pinger.send_signal(signal.SIGKILL)
        pinger.wait(timeout=30)
        for sub in subs:
            sub.undeclare()
    assert pinger.returncode == -signal.SIGKILL
    rec = read(run / "pinger.mcap")
    assert any(e.topic == "pinger/events" and e.decode().code == "param_changed" for e in rec.outputs)
    assert rec.truncated and "without its summary" in rec.truncated, rec.truncated
    res = replay(run / "pinger.mcap")
    assert res.exit_code == EXIT_INCOMPLETE and not res.match, res.report()


def test_a_killed_component_loses_at_most_the_flush_interval(router, procs, tmp_path):
    """A ping every 10 ms, the writer thread on (as the gateway's), flush every 0.25 s: after
    SIGKILL the file holds every ping in order up to within the interval of the last one the
    bus saw (plus a margin for the writer's compression and scheduling on a loaded machine)."""
    interval_s, margin_s = 0.25, 1.0
    port, _ = router
    cfg = write_config(tmp_path / "stream.toml", port, extra=(
        f"record_thread = true\nchunk_size = 4096\nflush_interval_s = {interval_s}\n[pinger]\nperiod_ms = 10\n"))
    run = tmp_path / "run"
    with zenoh_client(port) as s:
        got: queue.Queue = queue.Queue()
        sub = s.declare_subscriber("humanpt/test/pinger/ping",
                                   lambda smp: got.put(pb.Tick.FromString(smp.payload.to_bytes())))
        pinger = procs.start("pinger", "--config", str(cfg), "--run-dir", str(run))
        first = got.get(timeout=60)
        while True:  # 2 s of pings: several flush intervals, several chunks
            last = got.get(timeout=30)
            if last.header.stamp_ns - first.header.stamp_ns >= 2e9:
                break
        pinger.send_signal(signal.SIGKILL)
        pinger.wait(timeout=30)
        sub.undeclare()
    pings = _pings(run / "pinger.mcap")
    seqs = [s for s, _ in pings]
    assert seqs == list(range(seqs[0], seqs[-1] + 1)) and seqs[0] <= first.header.seq, "a ping is missing"
    lost_s = (last.header.stamp_ns - pings[-1][1]) / 1e9
    print(f"\nkilled after ping {last.header.seq}: the file holds pings {seqs[0]}..{seqs[-1]}, "
          f"the last {lost_s * 1e3:.0f} ms before the last one published were lost (interval {interval_s} s)")
    assert lost_s <= interval_s + margin_s, lost_s

    # The killed file has no summary: with the first chunk holding pings damaged (found by
    # parsing: which records a chunk holds depends on the run), the channels and schemas
    # declared there or before come from the humanpt.channels records, and the later chunks
    # still read.
    data = (run / "pinger.mcap").read_bytes()
    chunks = _chunks(data)
    ids = {i for _, _, recs in chunks for i in _ping_ids(recs)}
    hit = next(c for c in chunks if any(isinstance(r, McapMessage) and r.channel_id in ids for r in c[2]))
    damaged = tmp_path / "damaged" / "pinger.mcap"
    damaged.parent.mkdir()
    damaged.write_bytes(_damage(data, hit[0], hit[1]))
    rec = read(damaged)
    later = _pings(damaged)
    assert f"damaged chunk at offset {hit[0]}" in " ".join(rec.notes), rec.notes
    assert later and later[-1] == pings[-1] and len(later) < len(pings)
    assert [s for s, _ in later] == seqs[-len(later):]


def _tick(seq: int) -> pb.Tick:
    m = pb.Tick()
    m.header.seq, m.header.stamp_ns = seq, seq * 10_000_000
    return m


def test_a_damaged_chunk_holding_the_schema_hides_no_message_of_later_chunks(tmp_path):
    """The CI failure of issue 31: a schema record sits in one chunk and the channel that
    uses it in a later one (here: the pinger's ``tick`` input registers humanpt.Tick, a
    flush ends the chunk, then ``pinger/ping`` is registered with that schema). With the
    schema's chunk damaged in a file never closed, the pings in later chunks read as
    humanpt.Tick (the schema's name from the humanpt.channels record), not as "raw"; every
    message of the undamaged chunks is read (counted by the mcap library), in order."""
    rec = Recorder(tmp_path / "pinger.mcap", {"component": "pinger"}, chunk_size=4096, flush_interval_s=3600)
    rec.write(IN, 0, "tick", _tick(0))
    rec.flush()  # the chunk with the schema is in the file, the next channel goes in the next chunk
    for i in range(200):
        rec.write(IN, (i + 1) * 10_000_000, "tick", _tick(i + 1))
        rec.write(OUT, (i + 1) * 10_000_000, "pinger/ping", _tick(i + 1))
    rec.flush()
    killed = (tmp_path / "pinger.mcap").read_bytes()  # as a SIGKILL leaves it: no summary
    rec.close()
    chunks = _chunks(killed)
    first = chunks[0]
    assert any(isinstance(r, Schema) and r.name == "humanpt.Tick" for r in first[2])
    assert not _ping_ids(first[2]) and len(chunks) >= 3  # the case: the channel is in a later chunk
    path = tmp_path / "damaged" / "pinger.mcap"
    path.parent.mkdir()
    path.write_bytes(_damage(killed, first[0], first[1]))

    got = read(path)
    assert f"damaged chunk at offset {first[0]}" in " ".join(got.notes), got.notes
    readable = [r for _, _, recs in chunks[1:] for r in recs if isinstance(r, McapMessage)]
    assert len(got.entries) == len(readable) == 400
    pings = [e.decode().header.seq for e in got.entries if e.topic == "pinger/ping"]
    assert pings == list(range(1, 201))
    assert all(e.schema == "humanpt.Tick" for e in got.entries)


def test_a_message_whose_schema_is_nowhere_is_left_out_with_a_note(tmp_path):
    """Without the humanpt.channels records (a file from another writer), a channel whose
    schema record was in a damaged chunk cannot be decoded: its messages are left out with a
    note saying why, never handed on as "raw" (a decode error later); the messages whose
    schema is known still read."""
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=10**6)
        w.start(profile="humanpt", library="other")
        w.add_metadata("humanpt.run", {"component": "pinger", "schema_version": str(topics.SCHEMA_VERSION)})
        tick = register_schema(w, pb.Tick)
        w.add_message(channel_id=w.register_channel("tick", "protobuf", tick, {"direction": IN}),
                      log_time=0, data=_tick(0).SerializeToString(), publish_time=0)
        w.flush()  # the chunk with the schema ends here
        ping = w.register_channel("pinger/ping", "protobuf", tick, {"direction": OUT})
        for i in range(1, 4):
            w.add_message(channel_id=ping, log_time=i, data=_tick(i).SerializeToString(), publish_time=i)
        w.flush()
        ev = register_schema(w, pb.Event)
        w.add_message(channel_id=w.register_channel("pinger/events", "protobuf", ev, {"direction": OUT}),
                      log_time=5, data=pb.Event(code="x").SerializeToString(), publish_time=5)
        w.flush()  # and never finished: no summary repeats the schemas (a killed writer)
    data = path.read_bytes()
    first = _chunks(data)[0]
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(_damage(data, first[0], first[1]))
    got = read(damaged)
    assert [e.topic for e in got.entries] == ["pinger/events"]
    assert got.entries[0].decode().code == "x"
    assert any("3 messages left out: the schema of their channel was declared only in a skipped chunk" in n
               for n in got.notes), got.notes
