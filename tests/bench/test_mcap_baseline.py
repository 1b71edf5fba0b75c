"""The recording bench's baseline (issue 37.1): mcap's own Writer on the same messages,
measured beside humanpt's Recorder; the CLI prints the ratio."""

from __future__ import annotations

import pytest

from humanpt.bench.measure import raw_mcap_throughput, write_rates
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from tests.conftest import run_cli_here


def test_both_writers_are_measured_on_the_same_messages():
    ev = pb.Event(header=header(1, 2, "world"), severity=2, source="bench", code="x", text="y" * 150)
    size = len(ev.SerializeToString())
    (ours_mb_s, ours_rate, ours_bytes), (raw_mb_s, raw_rate, raw_bytes) = write_rates(lambda k: ev, 0.05, rounds=1)
    assert ours_rate > 0 and raw_rate > 0 and ours_bytes > 0 and raw_bytes > 0
    # payload MB/s is messages/s x the message's bytes for the baseline (by construction)
    assert raw_mb_s == pytest.approx(raw_rate * size / 1e6, rel=1e-9)
    mb_s, rate, nbytes = raw_mcap_throughput(lambda k: ev, 0.05, compression="none")
    assert nbytes > rate * 0.05 * size  # uncompressed: the file holds every payload (>= 0.05 s of them)


@pytest.mark.live  # a router and two sessions (the round trips)
def test_bench_runtime_prints_the_ratio_to_the_raw_writer():
    r = run_cli_here("bench", "runtime", "--n", "3", "--seconds", "0.05")
    assert r.returncode == 0, r.stdout + r.stderr
    rows = [ln for ln in r.stdout.splitlines() if ln.startswith("MCAP write")]
    assert len(rows) == 2 and all("x the raw mcap Writer (" in ln for ln in rows), rows
