"""A component killed with SIGKILL keeps its recording up to the flush interval (issue 29, item 13).

The attack: SIGKILL of the gateway lost the last 0.93 s of robot_gateway.mcap (the chunk in
progress). The recorder now flushes on wall time, every ``[runtime] flush_interval_s``
(default 1 s), whether messages come or not. Here a real ``humanpt pinger`` process (the live
shell, its real recorder, a real router) is SIGKILLed and its file is read: it holds what the
process gave its recorder up to the interval before the kill, and it reads although the
killed writer never wrote the summary - also with its first chunk damaged (the channels come
from the ``humanpt.channels`` records: a killed file has no summary to repeat them)."""

from __future__ import annotations

import queue
import signal
import struct
import time

import pytest

from humanpt.runtime.recording import iter_entries, read
from humanpt.runtime.replay import EXIT_INCOMPLETE, replay
from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli, write_config, zenoh_client

pytestmark = pytest.mark.timeout(180)


def _first_chunk(data: bytes) -> int:
    """Offset of the first chunk record (MCAP framing: opcode 1 byte, length 8 bytes)."""
    pos = 8
    while data[pos] != 0x06:
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    return pos


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

    # The killed file has no summary: with its first chunk damaged, the channels declared
    # there come from the humanpt.channels records, and the other chunks still read.
    data = bytearray((run / "pinger.mcap").read_bytes())
    first_chunk = _first_chunk(bytes(data))
    body = first_chunk + 9 + 28 + 8 + 8 + 40  # 40 bytes into its compressed records
    data[body:body + 32] = bytes(b ^ 0xA5 for b in data[body:body + 32])
    damaged = tmp_path / "damaged" / "pinger.mcap"
    damaged.parent.mkdir()
    damaged.write_bytes(bytes(data))
    rec = read(damaged)
    later = _pings(damaged)
    assert any("damaged chunk at offset" in n for n in rec.notes), rec.notes
    assert later and later[-1] == pings[-1] and len(later) < len(pings)
    assert [s for s, _ in later] == seqs[-len(later):]
