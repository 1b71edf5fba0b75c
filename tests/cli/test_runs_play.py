"""`humanpt runs play`, `runs info` and `runs merge` on one recorded lock-step run (issue 20
items 2-4), and the encoding of every sample on the bus, read by a plain zenoh session that
knows nothing of humanpt but the shipped .proto files."""

from __future__ import annotations

import queue
import threading
from collections import Counter

import pytest
import zenoh
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tests.conftest import ROOT, run_cli, run_cli_here, wait_for

SCHEMAS = ROOT / "schemas"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """One 3 s lock-step demo run, recorded (about 2 s)."""
    d = tmp_path_factory.mktemp("play") / "run"
    r = run_cli_here("demo", "--lockstep", "--duration", "3", "--run-dir", str(d))  # (the twin, in this process)
    assert r.returncode == 0, r.stdout + r.stderr
    return d


@pytest.fixture(scope="module")
def proto_pool(tmp_path_factory) -> descriptor_pool.DescriptorPool:
    """Every message type of schemas/humanpt.proto and schemas/foxglove/*.proto, compiled by a
    plain protoc: what a client in another language would have."""
    out = tmp_path_factory.mktemp("protos") / "set.pb"
    protos = ["humanpt.proto"] + sorted(f"foxglove/{p.name}" for p in (SCHEMAS / "foxglove").glob("*.proto"))
    from grpc_tools import protoc  # the plain protoc, in this process (as its entry point calls it)

    wkt = protoc._get_resource_file_name("grpc_tools", "_proto")  # protobuf's well-known types
    assert protoc.main(["protoc", f"-I{SCHEMAS}", "--include_imports", f"--descriptor_set_out={out}",
                        *(str(SCHEMAS / p) for p in protos), f"-I{wkt}"]) == 0
    pool = descriptor_pool.DescriptorPool()
    for f in descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()).file:
        pool.Add(f)
    return pool


def plain_decode(pool, sample: zenoh.Sample):
    """Decode a sample by the schema its encoding names (application/protobuf;<type>)."""
    mime, _, schema = str(sample.encoding).partition(";")
    assert mime == "application/protobuf" and schema, str(sample.encoding)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema))
    return schema, cls.FromString(sample.payload.to_bytes())


def plain_session(port: int) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{port}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def recorded_outputs(run_dir) -> Counter:
    """(topic) -> messages the components recorded as outputs, read with the mcap library."""
    n: Counter = Counter()
    for f in run_dir.glob("*.mcap"):
        with open(f, "rb") as fh:
            s = make_reader(fh).get_summary()
        for cid, c in s.channels.items():
            if c.metadata.get("direction") == "out":
                n[c.topic] += s.statistics.channel_message_counts.get(cid, 0)
    return n


def test_play_is_seen_by_echo_console_and_a_plain_zenoh_client(run_dir, router, procs, proto_pool):
    port, cfg = router
    got: queue.Queue = queue.Queue()
    with plain_session(port) as s:
        sub = s.declare_subscriber("humanpt/test/**", lambda smp: got.put((str(smp.key_expr), *plain_decode(proto_pool, smp))))
        play = procs.start("runs", "play", str(run_dir), "--config", str(cfg), "--loop", "--clock")
        seen: dict[str, list] = {}

        def have_all() -> bool:
            while not got.empty():
                key, schema, msg = got.get()
                seen.setdefault(key, []).append((schema, msg))
            return all(k in seen for k in ("humanpt/test/controller/status", "humanpt/test/camera/image",
                                           "humanpt/test/player/clock"))

        wait_for(have_all, 30, "status, images and the clock from runs play")
        # echo and console, while it plays (--loop)
        r = run_cli_here("echo", "controller/status", "-n", "3", "--config", str(cfg), "--duration", "60")
        assert r.returncode == 0 and r.stdout.count("--- humanpt/test/controller/status (humanpt.ControllerStatus)") == 3, r.stdout + r.stderr
        # (a process: the console prints through a stream bound when its module was imported)
        r = run_cli("console", "status", "--config", str(cfg), "--timeout", "10", timeout=30)
        assert r.returncode == 0 and "controller  mode" in r.stdout and "robot       cycle" in r.stdout, r.stdout + r.stderr
        sub.undeclare()
    out = procs.stop(play)  # SIGTERM: a clean stop
    assert play.returncode == 0 and "humanpt runs play: stopped;" in out, out
    # the type names on the wire are the recorded ones (the MCAP schema names)
    schema, img = seen["humanpt/test/camera/image"][0]
    assert (schema, img.width, img.height, img.encoding) == ("foxglove.RawImage", 640, 480, "mono8")
    assert seen["humanpt/test/controller/status"][0][0] == "humanpt.ControllerStatus"
    ticks = [m for _, m in seen["humanpt/test/player/clock"]]
    assert all(m.period_ns == 100_000_000 for m in ticks)
    stamps = [m.header.stamp_ns for m in ticks[:5]]
    assert all(b - a == 100_000_000 for a, b in zip(stamps, stamps[1:], strict=False)), stamps
    # never a local topic (serial bytes, ticks)
    assert not [k for k in seen if "serial" in k or k.endswith("/tick")]


def test_play_at_rate_puts_every_recorded_output_once(run_dir, router, procs, proto_pool):
    port, cfg = router
    want = {t: n for t, n in recorded_outputs(run_dir).items() if "/" in t}
    counts: Counter = Counter()
    lock = threading.Lock()

    def cb(smp):
        with lock:
            counts[str(smp.key_expr).split("/", 2)[2]] += 1

    with plain_session(port) as s:
        sub = s.declare_subscriber("humanpt/test/**", cb)
        r = run_cli_here("runs", "play", str(run_dir), "--config", str(cfg), "--rate", "4")
        assert r.returncode == 0, r.stdout + r.stderr
        wait_for(lambda: sum(counts.values()) >= sum(want.values()), 10, "every message delivered")
        sub.undeclare()
    assert dict(counts) == want


def test_play_refuses_bad_options(run_dir, cli_main, capsys):
    """Said before any connection (no router needed)."""
    assert cli_main(["runs", "play", str(run_dir), "--rate", "0"]) == 2
    err = capsys.readouterr().err
    assert "--rate 0: must be > 0" in err and len(err.splitlines()) == 1
    assert cli_main(["runs", "play", str(run_dir), "--topics", "controller/nothing"]) == 2
    assert "controller/nothing not in the topic table" in capsys.readouterr().err


def test_live_shell_samples_carry_their_type(router, procs, proto_pool):
    """A component's own puts (the live shell), not only the player's."""
    port, cfg = router
    got: queue.Queue = queue.Queue()
    with plain_session(port) as s:
        sub = s.declare_subscriber("humanpt/test/ponger/pong", lambda smp: got.put(plain_decode(proto_pool, smp)))
        procs.start("ponger", "--config", str(cfg))
        ping_cls = message_factory.GetMessageClass(proto_pool.FindMessageTypeByName("humanpt.Tick"))
        pub = s.declare_publisher("humanpt/test/pinger/ping")
        wait_for(lambda: pub.matching_status.matching, 30, "the ponger's subscriber")
        pub.put(ping_cls(header={"seq": 7, "stamp_ns": 7}).SerializeToString())
        schema, pong = got.get(timeout=10)
        sub.undeclare()
    assert schema == "humanpt.Event" and pong.source == "ponger"


def test_runs_info_summarises_the_run(run_dir, cli_main, capsys):
    assert cli_main(["runs", "info", str(run_dir)]) == 0
    r = capsys.readouterr()
    mcap_bytes = sum(f.stat().st_size for f in run_dir.glob("*.mcap"))
    # duration: the demo's 3 s of twin time (first to last message of any recording)
    line = next(ln for ln in r.out.splitlines() if ln.startswith("run: "))
    dur = float(line.split()[1])
    assert 2.8 <= dur <= 3.0, line
    assert f"{mcap_bytes / 1e6:.2f} MB (" in line, line
    per_min = float(line.split("(")[1].split()[0])
    assert per_min == pytest.approx(mcap_bytes / 1e6 / (dur / 60), rel=0.02), line  # dur printed to 0.1 s
    assert "rig: rig.toml: nominal (psvs nominal" in r.out
    # topics with the type they were recorded with
    assert any(ln.split()[:3] == ["out", "camera/image", "foxglove.RawImage"] for ln in r.out.splitlines()), r.out
    # warnings: what the recordings hold, counted here with the mcap library's own decoder
    want: Counter = Counter()
    for f in run_dir.glob("*.mcap"):
        with open(f, "rb") as fh:
            for _, ch, _, msg in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                if ch.topic.endswith("/events") and ch.metadata.get("direction") == "out" and msg.severity >= 3:
                    want[msg.code] += 1
    if want:
        for code, n in want.items():
            assert any(code in ln and ln.split()[-1] == str(n) for ln in r.out.splitlines()), (code, r.out)
    else:
        assert "warnings and errors published: none" in r.out
    assert "messages dropped by the shells: none" in r.out


def test_runs_merge_keeps_local_topics_apart(run_dir, tmp_path, cli_main):
    out = tmp_path / "merged.mcap"
    assert cli_main(["runs", "merge", str(run_dir), str(out)]) == 0
    with open(out, "rb") as fh:
        s = make_reader(fh).get_summary()
    counts = {c.topic: s.statistics.channel_message_counts.get(cid, 0) for cid, c in s.channels.items()}
    rec = recorded_outputs(run_dir)
    # both ends of the ALTER link write serial_tx: two channels, never one
    assert counts["humanpt/cell0/robot_gateway/local/serial_tx"] > 0
    assert counts["humanpt/cell0/sim_robot/local/serial_tx"] > 0
    assert "humanpt/cell0/serial_tx" not in counts
    assert sum(counts.values()) == sum(rec.values())
    assert counts["humanpt/cell0/controller/status"] == rec["controller/status"]


def test_runs_info_counts_warnings_by_code_and_dropped_messages(tmp_path, cli_main, capsys):
    """A recording written here with known events and drops: the counts are these."""
    from humanpt.runtime.recording import OUT, Recorder
    from humanpt.schemas import humanpt_pb2 as pb

    run = tmp_path / "run"
    run.mkdir()
    with Recorder(run / "controller.mcap", {"component": "controller", "cell": "test"}) as rec:
        severities = [(pb.SEVERITY_WARNING, "stale_command")] * 3 + [(pb.SEVERITY_ERROR, "core_error")] \
            + [(pb.SEVERITY_INFO, "mode")] * 5
        for i, (sev, code) in enumerate(severities):
            rec.write(OUT, i * 60_000_000_000 // len(severities), "controller/events",
                      pb.Event(header=pb.Header(seq=i), severity=sev, code=code))
        for i in range(4):
            rec.write_dropped(i, "perception/tob", b"")
    assert cli_main(["runs", "info", str(run)]) == 0
    r = capsys.readouterr()
    rows = {tuple(ln.split()) for ln in r.out.splitlines()}
    assert ("controller", "warning", "stale_command", "3") in rows
    assert ("controller", "error", "core_error", "1") in rows
    assert not any("mode" in row for row in rows if "warning" in row or "error" in row)  # info is not counted
    assert ("controller", "perception/tob", "4") in rows
    assert "messages dropped by the shells (4):" in r.out
    assert "rig: none recorded" in r.out
