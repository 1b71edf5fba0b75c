"""`humanpt topics --hz`: a block per interval with each key's rate, bandwidth and size."""

from __future__ import annotations

import threading

from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli_here, zenoh_client


def test_topics_hz_reports_rate_and_bandwidth_of_a_known_publisher(router):
    port, cfg = router
    payload = pb.Tick(header=pb.Header(seq=1, stamp_ns=123, frame_id="x" * 200), period_ns=50_000_000).SerializeToString()
    stop = threading.Event()
    period_s = 0.05  # 20 Hz

    def publish(pub):
        while not stop.wait(period_s):
            pub.put(payload)

    with zenoh_client(port) as s:
        pub = s.declare_publisher("humanpt/test/pinger/ping")
        th = threading.Thread(target=publish, args=(pub,), daemon=True)
        th.start()
        try:
            r = run_cli_here("topics", "--hz", "--duration", "3.2", "--interval", "1", "--config", str(cfg))
        finally:
            stop.set()
            th.join(5)
    assert r.returncode == 0, r.stdout + r.stderr
    blocks = [b for b in r.stdout.split("cell test, ") if b.strip()]
    assert len(blocks) == 4, r.stdout  # 1, 2, 3 and the last 0.2 s
    rows = [ln.split() for ln in blocks[1].splitlines() if ln.startswith("humanpt/test/pinger/ping")]
    assert rows, blocks[1]
    key, tname, rate, kbs, avg = rows[0]
    assert tname == "humanpt.Tick" and int(avg) == len(payload)
    assert 10 <= float(rate) <= 25, rows  # 20 Hz put by a thread on a shared machine
    assert abs(float(kbs) - float(rate) * len(payload) / 1e3) < 0.1


def test_echo_decodes_a_key_outside_the_table_by_its_encoding(router):
    """A wildcard echo meets a key this version's table lacks (another version's topic): the
    sample's encoding (application/protobuf;<type>) names the type to decode it with."""
    import zenoh

    port, cfg = router
    stop = threading.Event()
    log = pb.Event(header=pb.Header(seq=3), code="from_elsewhere", text="hello").SerializeToString()

    def publish(s):
        pub = s.declare_publisher("humanpt/test/newcomer/log",
                                  encoding=zenoh.Encoding.APPLICATION_PROTOBUF.with_schema("humanpt.Event"))
        while not stop.wait(0.05):
            pub.put(log)

    with zenoh_client(port) as s:
        th = threading.Thread(target=publish, args=(s,), daemon=True)
        th.start()
        try:
            r = run_cli_here("echo", "newcomer/*", "-n", "1", "--config", str(cfg), "--duration", "30")
        finally:
            stop.set()
            th.join(5)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "--- humanpt/test/newcomer/log (humanpt.Event)" in r.stdout and 'code: "from_elsewhere"' in r.stdout
