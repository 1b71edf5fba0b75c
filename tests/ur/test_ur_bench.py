"""``humanpt bench ur`` (issue 34): the gateway <-> the simulated UR controller (its own process,
a real TCP connection on loopback) at the CB3's 8 ms for 2 s. Its counts are reported, not
judged against a rate: each cycle is answered in time or late, the histogram holds the answer
times, every answer the robot read is one the gateway sent, and the scripted controller's
circle reached the arm. The table the verb prints carries the run's counts."""

from __future__ import annotations

import re

import numpy as np
import pytest

from humanpt.bench.ur import run_ur
from humanpt.cli.bench import link_table
from humanpt.sim_robot.rsi import LATENCY_EDGES_MS
from tests.conftest import run_cli_here

pytestmark = pytest.mark.live  # a child process, TCP sockets

SECONDS = 2.0


@pytest.fixture(scope="module")
def run():
    return run_ur(8.0, SECONDS)


def test_every_cycle_is_answered_in_time_or_late_and_every_answer_was_the_gateways(run):
    assert run.cycles >= 1 and run.on_time + run.late == run.cycles
    buckets = [run.histogram[f"<={e:g} ms"] for e in LATENCY_EDGES_MS]
    assert sum(buckets) == sum(ms <= 12.0 for ms in run.latency_ms) and run.histogram["late"] == run.late
    answered = len(run.latency_ms)  # one per cycle answered (+1: the last cycle's, not judged)
    assert run.on_time <= answered <= run.on_time + 1
    gw = run.gateway
    sent = gw["fresh"] + gw["reused"] + gw["zero"]
    assert answered <= sent <= gw["statuses"]  # the robot read only what the gateway sent, one per cycle
    assert gw["link_errors"] == 0 and gw["faults"] == 0
    # The scripted controller's circle (20 mm/s) moved the arm: the answers carried its commands.
    assert gw["fresh"] > 0 and float(np.linalg.norm(run.moved_mm)) > 0.0
    assert 0 < run.latency_pct(50) <= run.latency_pct(99) and 0 < run.work_pct(50) <= run.work_pct(99)


def test_the_printed_table_carries_the_runs_counts(run):
    lines = link_table([run]).splitlines()
    header, row = lines[0], next(line for line in lines if re.match(r"\s*8 ms\s", line))

    def cell(name: str) -> str:  # right-aligned: a cell ends where its column's name does
        return row[:header.index(name) + len(name)].split()[-1]

    assert (int(cell("cycles")), int(cell("on time")), int(cell("late"))) == (run.cycles, run.on_time, run.late)
    assert float(cell("latency p50 ms")) == pytest.approx(run.latency_pct(50), abs=0.006)


@pytest.mark.parametrize("args, says", [
    (("--cycles", "4"), "--cycles takes 8 (CB3, 125 Hz) and/or 2 (e-Series, 500 Hz)"),
    (("--cycles", "x"), "--cycles must be numbers"),
])
def test_a_cycle_a_ur_does_not_run_is_refused_in_one_line(args, says):
    r = run_cli_here("bench", "ur", *args)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().count("\n") == 0 and says in r.stderr and "Traceback" not in r.stderr, r.stderr
