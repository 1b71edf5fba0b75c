"""`humanpt runs info`: what a subscriber never received is visible (issue 14, item 12).

A real ponger process records the pings it consumes; the test publishes pings whose sequence
numbers skip 10 (what a subscriber sees of a partition that ate 10 messages) and then start
again (a restarted publisher). The ponger's recording shows the gap and the restart."""

from __future__ import annotations

import queue

from humanpt.runtime.runinfo import run_info
from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli_here, wait_for, wait_matching, zenoh_client


def test_runs_info_reports_the_messages_a_subscriber_missed(router, procs, tmp_path):
    port, cfg = router
    run_dir = tmp_path / "run"
    ponger = procs.start("ponger", "--config", str(cfg), "--run-dir", str(run_dir))
    pongs: queue.Queue = queue.Queue()
    with zenoh_client(port) as s:
        sub = s.declare_subscriber("humanpt/test/ponger/pong", lambda smp: pongs.put(1))
        pub = s.declare_publisher("humanpt/test/pinger/ping")
        wait_matching(pub)
        seqs = list(range(0, 10)) + list(range(20, 30)) + list(range(0, 5))  # lost 10; restart
        for k in seqs:
            pub.put(pb.Tick(header=pb.Header(seq=k, stamp_ns=k)).SerializeToString())
        wait_for(lambda: pongs.qsize() >= len(seqs), 20, "every ping answered")
        pub.undeclare()
        sub.undeclare()
    procs.stop(ponger)
    (info,) = run_info(run_dir)
    pings = info.topics[("in", "pinger/ping")]
    assert (pings.count, pings.missing, pings.gaps, pings.largest_gap, pings.restarts) == (25, 10, 1, 10, 1)
    r = run_cli_here("runs", "info", str(run_dir))
    assert r.returncode == 1, r.stdout + r.stderr
    assert "MISSED 10 in 1 gap(s), largest 10" in r.stdout and "publisher restarted 1x" in r.stdout
    assert "inputs missed: 10" in r.stdout


def test_runs_info_of_a_complete_run_says_nothing_was_missed():
    r = run_cli_here("runs", "info", "recordings/static")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "inputs missed: 0" in r.stdout and "component pose_filter" in r.stdout
    assert "recordings with write losses: 0" in r.stdout


def test_runs_info_reports_write_losses(tmp_path):
    """A full disk's losses file (written by the Recorder, runtime/README.md) is reported."""
    import json
    import shutil

    run_dir = tmp_path / "run"
    shutil.copytree("recordings/static", run_dir)
    (run_dir / "perception.losses.json").write_text(json.dumps(
        {"component": "perception", "lost": 7, "outages": [{"error": "[Errno 28] No space left on device"}]}))
    r = run_cli_here("runs", "info", str(run_dir))
    assert r.returncode == 1, r.stdout + r.stderr
    assert "RECORDING LOST 7 messages of perception in 1 write outage(s)" in r.stdout
