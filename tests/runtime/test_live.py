"""Live, on loopback, in separate processes: a real router and components over Zenoh. The
tools (param, topics, echo, replay, runs merge) run in this process (``run_cli_here``): their
process boundary is not what is checked, the components' is."""

from __future__ import annotations

import csv
import io
import json
import queue
import signal
import time

import pytest
import zenoh

from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import (
    free_port,
    run_cli_here,
    wait_for,
    wait_matching,
    wait_port,
    write_config,
    zenoh_client,
)

pytestmark = pytest.mark.timeout(120)


def _collect(q: queue.Queue, n: int, timeout: float = 20.0) -> list:
    out, deadline = [], time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        try:
            out.append(q.get(timeout=0.2))
        except queue.Empty:
            pass
    return out


def _pongs(session) -> tuple[queue.Queue, object]:
    q: queue.Queue = queue.Queue()
    sub = session.declare_subscriber("humanpt/test/ponger/pong",
                                     lambda s: q.put(pb.Event.FromString(s.payload.to_bytes())))
    return q, sub


def test_components_exchange_messages_and_liveliness_follows_the_process(router, procs, tmp_path):
    port, cfg = router
    run_dir = tmp_path / "run"
    with zenoh_client(port) as s:
        alive: queue.Queue = queue.Queue()
        live_sub = s.liveliness().declare_subscriber("humanpt/test/*", lambda smp: alive.put(
            (str(smp.key_expr), str(smp.kind))), history=True)
        q, sub = _pongs(s)
        pinger = procs.start("pinger", "--config", str(cfg), "--run-dir", str(run_dir))
        ponger = procs.start("ponger", "--config", str(cfg), "--run-dir", str(run_dir))
        pongs = _collect(q, 5)
        assert len(pongs) == 5, "no pongs: the components did not exchange messages"
        assert all(p.code == "pong" and p.source == "ponger" for p in pongs)
        seqs = [int(p.text.split()[1]) for p in pongs]
        assert seqs == sorted(seqs)
        events = _collect(alive, 2)
        assert {(k, kind) for k, kind in events} == {("humanpt/test/pinger", str(zenoh.SampleKind.PUT)),
                                                     ("humanpt/test/ponger", str(zenoh.SampleKind.PUT))}
        ponger.send_signal(signal.SIGKILL)  # no clean exit: the token must still vanish
        gone = _collect(alive, 1, timeout=30)
        assert gone == [("humanpt/test/ponger", str(zenoh.SampleKind.DELETE))]
        sub.undeclare()
        live_sub.undeclare()
    procs.stop(pinger)


def test_malformed_payload_is_dropped_counted_and_the_component_lives_on(router, procs, tmp_path):
    port, cfg = router
    run_dir = tmp_path / "run"
    ponger = procs.start("ponger", "--config", str(cfg), "--run-dir", str(run_dir))
    with zenoh_client(port) as s:
        q, sub = _pongs(s)
        pub = s.declare_publisher("humanpt/test/pinger/ping")
        wait_matching(pub)  # the ponger subscribes: what we put now reaches it
        pub.put(b"\xff\xff\xff garbage")
        pub.put(pb.Tick(header=pb.Header(seq=41, stamp_ns=5)).SerializeToString())
        got = _collect(q, 1)
        assert got and got[0].text.startswith("pong 41"), "the ponger did not survive the bad payload"
        replies = list(s.get("humanpt/test/ponger/params", timeout=5.0))
        body = json.loads(replies[0].ok.payload.to_bytes())
        assert body["counters"]["dropped"] == 1 and body["counters"]["consumed"] == 1
        pub.undeclare()
        sub.undeclare()
    out = procs.stop(ponger)
    assert "dropped a message on pinger/ping" in out and "does not decode as humanpt.Tick" in out
    assert ponger.returncode == 0
    from humanpt.runtime.recording import read

    rec = read(run_dir / "ponger.mcap")
    dropped = [e for e in rec.entries if e.direction == "dropped"]
    assert [e.data for e in dropped] == [b"\xff\xff\xff garbage"]  # kept, raw
    res = replay(run_dir / "ponger.mcap")
    assert res.match and res.compared >= 1, res.report()  # at least the pong to ping 41


def test_live_run_replays_to_identical_outputs_and_params_change_at_run_time(router, procs, tmp_path):
    port, cfg = router
    run_dir = tmp_path / "run"
    pinger = procs.start("pinger", "--config", str(cfg), "--run-dir", str(run_dir))
    ponger = procs.start("ponger", "--config", str(cfg), "--run-dir", str(run_dir))
    with zenoh_client(port) as s:
        q, sub = _pongs(s)
        assert len(_collect(q, 3)) == 3
        r = run_cli_here("param", "ponger", "prefix=PONG", "--config", str(cfg))
        assert r.returncode == 0, r.stderr
        assert '"prefix": "PONG"' in r.stdout
        # (KEY=VALUE after an option too, as ros2 param takes it)
        r = run_cli_here("param", "pinger", "--config", str(cfg), "period_ms=-5")
        assert r.returncode == 1 and "REJECTED" in r.stdout and "period_ms: -5.0 is outside its range" in r.stdout
        while not q.empty():
            q.get()
        later = _collect(q, 4)
        # (the first may have left before the change)
        assert len(later) == 4 and all(p.text.startswith("PONG ") for p in later[1:]), later
        sub.undeclare()
    procs.stop(ponger)
    procs.stop(pinger)
    r = run_cli_here("replay", str(run_dir))
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.count("MATCH: every output is identical") == 2
    from humanpt.runtime.recording import read

    params = [e.decode() for e in read(run_dir / "ponger.mcap").inputs if e.topic == "param"]
    assert [(p.key, p.value_json) for p in params] == [("prefix", '"PONG"')]


def test_param_for_an_absent_component_says_so(router):
    port, cfg = router
    r = run_cli_here("param", "ponger", "--config", str(cfg), "--timeout", "1")
    assert r.returncode == 1 and "no component 'ponger' answered" in r.stderr


def test_up_runs_a_profile_and_merge_and_topics_work(procs, tmp_path):
    port = free_port()
    cfg = write_config(tmp_path / "h.toml", port)
    run_dir = tmp_path / "up"
    # Stopped (SIGTERM, as Ctrl-C) once its components talk, not after a guessed duration: on
    # a loaded machine they may take longer than that to start.
    up = procs.start("up", "--profile", "selftest", "--config", str(cfg), "--run-dir", str(run_dir))
    wait_port(port, timeout=60.0)
    with zenoh_client(port) as s:
        q, sub = _pongs(s)
        assert len(_collect(q, 3, timeout=60.0)) == 3, "the profile's components did not talk"
        sub.undeclare()
    out = procs.stop(up, timeout=30.0)
    assert up.returncode == 0, out
    assert f"recording to {run_dir}/" in out
    assert {p.name for p in run_dir.glob("*.mcap")} == {"pinger.mcap", "ponger.mcap"}
    out = tmp_path / "merged.mcap"
    r = run_cli_here("runs", "merge", str(run_dir), str(out))
    assert r.returncode == 0, r.stderr
    from mcap.reader import make_reader

    with open(out, "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert topics == {"humanpt/test/pinger/ping", "humanpt/test/ponger/pong"}


@pytest.mark.live  # (up in this process starts its children)
def test_up_exits_non_zero_when_a_child_dies(tmp_path):
    port = free_port()
    cfg = write_config(tmp_path / "h.toml", port, extra="")
    cfg.write_text(cfg.read_text().replace("connect_timeout_s = 5.0", "connect_timeout_s = 0.5"))
    r = run_cli_here("up", "--profile", "selftest", "--no-router", "--config", str(cfg), "--duration", "20",
                     "--run-dir", str(tmp_path / "run"))  # (its children are processes)
    assert r.returncode == 1
    assert "stopped because a child died" in r.stderr


def test_topics_and_echo_show_live_traffic(router, procs, tmp_path):
    port, cfg = router
    procs.start("pinger", "--config", str(cfg), "--run-dir", str(tmp_path / "run"))
    with zenoh_client(port) as s:  # the pinger is up and publishing
        pings: queue.Queue = queue.Queue()
        sub = s.declare_subscriber("humanpt/test/pinger/ping", lambda smp: pings.put(1))
        assert _collect(pings, 1), "the pinger never published"
        sub.undeclare()
    r = run_cli_here("topics", "--config", str(cfg), "--duration", "1.5")
    assert r.returncode == 0, r.stderr
    assert "components up: pinger" in r.stdout
    assert "humanpt/test/pinger/ping" in r.stdout and "humanpt.Tick" in r.stdout
    r = run_cli_here("echo", "pinger/ping", "--config", str(cfg), "--count", "2", "--duration", "10")
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("--- humanpt/test/pinger/ping (humanpt.Tick)") == 2
    assert "period_ns: 100000000" in r.stdout
    # Fields as CSV (ros2 topic echo --field, --csv): the header row, then one row per
    # message with its stamp; consecutive ticks of the pinger's 100 ms period.
    r = run_cli_here("echo", "pinger/ping", "--config", str(cfg), "--count", "3", "--duration", "10",
                "--field", "period_ns", "--field", "header.seq", "--csv")
    assert r.returncode == 0, r.stderr
    rows = list(csv.reader(io.StringIO(r.stdout)))
    assert rows[0] == ["stamp_ns", "key", "period_ns", "header.seq"] and len(rows) == 4, rows
    assert all(row[1] == "humanpt/test/pinger/ping" and row[2] == "100000000" for row in rows[1:])
    seqs = [int(row[3]) for row in rows[1:]]
    stamps = [int(row[0]) for row in rows[1:]]
    assert seqs == list(range(seqs[0], seqs[0] + 3)) and all(b > a for a, b in zip(stamps, stamps[1:], strict=False))


def test_peer_mode_links_components_directly_and_they_still_talk(router, procs, tmp_path):
    """mode = "peer": sessions meet at the router, then link to each other directly (one hop)."""
    from humanpt.runtime.bus import zenoh_config
    from humanpt.runtime.config import RuntimeConfig

    port, _ = router
    rt = RuntimeConfig(cell="test", mode="peer", connect=(f"tcp/127.0.0.1:{port}",))
    with zenoh.open(zenoh_config(rt)) as a, zenoh.open(zenoh_config(rt)) as b:
        wait_for(lambda: str(b.info.zid()) in {str(z) for z in a.info.peers_zid()}, 10.0,
                 "the peers to link directly")
        q: queue.Queue = queue.Queue()
        sub = b.declare_subscriber("humanpt/test/x", lambda s: q.put(s.payload.to_bytes()))
        pub = a.declare_publisher("humanpt/test/x")
        wait_matching(pub, timeout=10.0)
        pub.put(b"hello")
        assert q.get(timeout=5.0) == b"hello"
        pub.undeclare()
        sub.undeclare()
    # The processes of a peer-mode config exchange messages as clients do.
    cfg = write_config(tmp_path / "peer.toml", port, extra='mode = "peer"\n')
    with zenoh_client(port) as s:
        q2, sub2 = _pongs(s)
        pinger = procs.start("pinger", "--config", str(cfg), "--run-dir", str(tmp_path / "run"))
        ponger = procs.start("ponger", "--config", str(cfg), "--run-dir", str(tmp_path / "run"))
        assert len(_collect(q2, 3)) == 3
        sub2.undeclare()
    procs.stop(ponger)
    procs.stop(pinger)
