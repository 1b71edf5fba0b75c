"""Runs with a bad file or a damaged chunk still merge, view and read (issue 14, item 13),
and a lock-step run merges (issue 20: it crashed on a late-bound generator variable)."""

from __future__ import annotations

import pytest
from mcap.reader import make_reader

from humanpt.runtime.recording import IN, OUT, Recorder, read
from humanpt.runtime.selftest import PingerConfig, PingerCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.twin.run import SystemConfig, run
from tests.conftest import run_cli, run_cli_here


@pytest.fixture(scope="module")
def lockstep_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("lockstep")
    run(SystemConfig.for_scenario("static", 0), robot="puma", duration_s=1.0, run_dir=d)
    return d


def _channels(path):
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = summary.statistics.channel_message_counts
    return {c.topic: counts.get(cid, 0) for cid, c in summary.channels.items()}


def test_a_lockstep_run_merges_with_local_outputs_apart(lockstep_run, tmp_path):
    out = tmp_path / "merged.mcap"
    r = run_cli_here("runs", "merge", str(lockstep_run), str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    ch = _channels(out)
    # Each end of the ALTER line keeps its own serial bytes; the bus topics are there once.
    serial = sorted(k for k in ch if k.endswith("/local/serial_tx"))
    assert serial == ["humanpt/cell0/robot_gateway/local/serial_tx", "humanpt/cell0/sim_robot/local/serial_tx"]
    assert ch["humanpt/cell0/robot_gateway/robot_state"] > 20  # 1 s of 28 ms cycles
    assert ch["humanpt/cell0/camera/image"] > 20  # 30 images/s


def test_an_empty_and_a_foreign_file_do_not_refuse_the_run(lockstep_run, tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    for f in lockstep_run.glob("*.mcap"):
        (run_dir / f.name).write_bytes(f.read_bytes())
    (run_dir / "empty.mcap").write_bytes(b"")
    (run_dir / "notes.mcap").write_text("not an MCAP file")
    out = tmp_path / "merged.mcap"
    r = run_cli_here("runs", "merge", str(run_dir), str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "empty.mcap" in r.stderr and "notes.mcap" in r.stderr and "left out" in r.stderr
    assert _channels(out)["humanpt/cell0/robot_gateway/robot_state"] > 20
    r = run_cli("view", str(run_dir), "--save", str(tmp_path / "run.rrd"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "run.rrd").stat().st_size > 10_000


def _many_chunks(path, n=300):
    """A recording of ``n`` pings (and their outputs) in many small chunks."""
    core = PingerCore(PingerConfig())
    rec = Recorder(path, {"component": "pinger", "core": "humanpt.runtime.selftest:PingerCore",
                          "config": {}, "version": "test"}, chunk_size=1024)
    for k in range(n):
        tick = pb.Tick(header=header(k * 100_000_000))
        rec.write(IN, k * 100_000_000, "tick", tick)
        for topic, msg in core.step(k * 100_000_000, "tick", tick):
            rec.write(OUT, k * 100_000_000, topic, msg)
    rec.close()
    return rec.path


def test_one_corrupt_chunk_hides_only_its_own_messages(tmp_path):
    path = _many_chunks(tmp_path / "pinger.mcap")
    whole = read(path)
    data = bytearray(path.read_bytes())
    # Corrupt the compressed payload of a chunk in the middle of the file (its framing, the
    # record's opcode and length, stays intact: a bad sector, not a cut).
    with open(path, "rb") as f:
        chunks = [ci for ci in make_reader(f).get_summary().chunk_indexes]
    mid = chunks[len(chunks) // 2]
    # opcode (1) and length (8), then start and end times, size, crc, "zstd", records length (44)
    start = mid.chunk_start_offset + 9 + 44 + 8
    data[start:start + 16] = bytes(b ^ 0xFF for b in data[start:start + 16])
    path.write_bytes(bytes(data))
    damaged = read(path)
    assert damaged.truncated and "skipped a damaged chunk" in damaged.truncated
    lost = len(whole.entries) - len(damaged.entries)
    assert 0 < lost < len(whole.entries) // 4  # one chunk's worth, not everything after it
    last = [e.t_ns for e in damaged.entries][-1]
    assert last == whole.entries[-1].t_ns  # the messages after the bad chunk are all there
