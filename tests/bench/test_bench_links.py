"""`humanpt bench alter` reports what `bench rsi` does (issue 22): cycles on time, the
reply-latency histogram and the gateway's per-cycle work, in microseconds."""

from __future__ import annotations

import re

from humanpt.bench.alter import AlterRun
from tests.conftest import run_cli


def test_the_histogram_buckets_replies_by_their_upper_edge_and_counts_the_missed():
    run = AlterRun(28.0, 1.0, cycles=5, on_time=4, latency_ms=[0.1, 0.25, 0.3, 3.0, 20.0])
    assert run.histogram == {"<=0.25 ms": 2, "<=0.5 ms": 1, "<=1 ms": 0, "<=2 ms": 0, "<=4 ms": 1,
                             "<=12 ms": 0, "late": 1}  # 20 ms is beyond the last edge: in no bucket


def test_bench_alter_prints_the_histogram_and_the_gateways_work():
    p = run_cli("bench", "alter", "--duration", "2", "--periods", "28", "--search-seconds", "1", timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    lines = p.stdout.splitlines()
    header = next(line for line in lines if "reply p50" in line)
    row = next(line for line in lines if re.match(r"\s*28 ms\s+2 s", line))

    def cell(name: str) -> str:  # right-aligned: a cell ends where its column's name does
        return row[:header.index(name) + len(name)].split()[-1]

    cycles = int(cell("cycles"))
    assert cycles >= 60  # 2 s of 28 ms cycles
    buckets = [int(cell(f"<={e} ms")) for e in ("0.25", "0.5", "1", "2", "4", "12")]
    assert sum(buckets) <= cycles + 2  # every reply at most once (two in flight at the ends)
    work_p50, work_p99 = float(cell("work p50 us")), float(cell("work p99 us"))
    assert 0 < work_p50 <= work_p99
