"""`humanpt topics --hz`: a block per interval with each key's rate, bandwidth and size."""

from __future__ import annotations

import threading

from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli, zenoh_client


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
            r = run_cli("topics", "--hz", "--duration", "3.2", "--interval", "1", "--config", str(cfg), timeout=30)
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
