"""Snapshots from the live shell (issue 30 item 6): real processes on a real router record
their cores' state every ``[record] snapshot_period_s``, and ``humanpt replay --last``
starts from one and matches."""

from __future__ import annotations

import json
import queue

import pytest

from humanpt.runtime.recording import IN, read
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli_here, write_config, zenoh_client

pytestmark = pytest.mark.timeout(180)


def test_live_shells_record_snapshots_and_replay_starts_from_one(router, procs, tmp_path):
    port, _ = router
    cfg = write_config(tmp_path / "snap.toml", port, extra="[record]\nsnapshot_period_s = 0.3\n")
    run_dir = tmp_path / "run"
    pongs: queue.Queue = queue.Queue()
    with zenoh_client(port) as s:
        sub = s.declare_subscriber("humanpt/test/ponger/pong",
                                   lambda smp: pongs.put(pb.Event.FromString(smp.payload.to_bytes())))
        pinger = procs.start("pinger", "--config", str(cfg), "--run-dir", str(run_dir))
        ponger = procs.start("ponger", "--config", str(cfg), "--run-dir", str(run_dir))
        # 30 pongs: 3 s of pings at the default 100 ms, ~10 periods of 0.3 s of input time.
        got = [pongs.get(timeout=60) for _ in range(30)]
        assert all(p.code == "pong" for p in got)
        sub.undeclare()
    procs.stop(pinger)
    procs.stop(ponger)
    for comp in ("pinger", "ponger"):
        f = run_dir / f"{comp}.mcap"
        rec = read(f)
        assert rec.truncated is None and len(rec.snapshots) >= 5
        for snap in rec.snapshots:
            table = json.loads(snap.data)
            assert table["component"] == comp and table["t_ns"] == snap.t_ns
            assert table["inputs"] == sum(1 for e in rec.entries[:snap.at] if e.direction == IN)
        res = replay(f, last_s=0.5)
        assert res.match and "from the snapshot at t_ns=" in res.report(), res.report()
        assert res.inputs < len(rec.inputs) / 2
    # The CLI too, on the whole run.
    out = run_cli_here("replay", str(run_dir), "--last", "0.5")
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.count("from the snapshot at t_ns=") == 2 and out.stdout.count("MATCH") == 2
