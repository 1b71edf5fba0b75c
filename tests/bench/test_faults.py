"""``humanpt bench faults`` end to end (issue 14, acceptance; issue 29's rows over ALTER):
the attacks against a live twin (router + seven processes, a real pty), the printed table,
and the twin ended cleanly, even on Ctrl-C.

The default run (every row: issue 14's, issue 29's over ALTER, the rows that need RSI or
mTLS skipped with the reason) is run once, in this process, by :func:`alter_bench`, and
its table and recordings are checked by several tests (one live twin for all of them);
the verb itself (its process, its Ctrl-C) by :func:`test_ctrl_c_ends_the_twin`."""

from __future__ import annotations

import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from humanpt.bench.faults import ATTACKS, QUICK, SECURE_ATTACKS, all_attacks, format_table
from humanpt.runtime.recording import read
from humanpt.schemas.convert import from_pose
from tests.bench.faults_rows import (
    HELD,
    LINK_ROWS,
    Bench,
    bench_run,
    kill_within_bound,
    leftovers,
    seam_played_or_refused,
)
from tests.conftest import ROOT, humanpt_cmd

# run_faults starts the twin's processes, a router and a pty; the timeout bounds a hang (the
# first test to use the module's run waits for all of it)
pytestmark = [pytest.mark.live, pytest.mark.cell, pytest.mark.timeout(600)]

# The rows --quick must print, in order: the attack set of issue 14 without the bus flood.
QUICK_FAULTS = [
    "param loosening (speed, envelope, watchdog)",
    "forged robot_state, future stamp",
    "NaN / 1e308 measurement",
    "absurd command (1.7e305 m, tool frame)",
    "forged STRT on the serial line",
    "bad console commands",
    "reset_fault without operator",
]
@pytest.fixture(scope="module")
def alter_bench(tmp_path_factory) -> Bench:
    """``humanpt bench faults`` (every row: the default run, over ALTER), once for this file."""
    return bench_run(tmp_path_factory.mktemp("faults") / "run", None)


def test_the_default_run_has_every_row_and_ends_its_twin(alter_bench):
    """Every attack's row in its order (the verb's table, exit status 0: no twin failure, no
    verdict failed); those that need RSI or mTLS skipped, with the reason; no process left."""
    assert alter_bench.failure == ""
    # the rows run over ALTER in their order, then those skipped (RSI's, mTLS's) in theirs
    ran = [a.fault for a in all_attacks() if "alter" in a.links and a not in SECURE_ATTACKS]
    assert list(alter_bench.table) == ran + [a.fault for a in all_attacks() if a.fault not in ran]
    assert all(r.ok for r in alter_bench.rows), format_table(alter_bench.rows)
    assert alter_bench.leftovers == []
    assert [a.fault for a in ATTACKS if a.key in QUICK] == QUICK_FAULTS  # what --quick runs


def test_quick_attacks_are_seen_held_and_recovered(alter_bench):
    run_dir = alter_bench.run_dir
    rows = {f: alter_bench.table[f] for f in QUICK_FAULTS}
    for fault, row in rows.items():
        # The verdicts: each attack answered as it should, the robot held. (Whether the loop
        # stayed up, "recovered", is liveness: reported, not asserted; issue 31.)
        assert row["verdict"] == "ok", (fault, row)
        assert row["reaction"].endswith(" ms"), (fault, row)
        # held: "yes (largest step / limit mm)", the limit the demo gateway's 100 mm/s x 28 ms
        held = HELD.fullmatch(row["robot held"])
        assert held, (fault, row)
        assert float(held[2]) == pytest.approx(100.0 * 0.028)
        assert float(held[1]) <= 1.05 * float(held[2])
        assert re.fullmatch(r"robot_state \d+, tob_state \d+", row["data lost"]), (fault, row)
        assert not row["note"].startswith("UNEXPECTED"), (fault, row)
    assert "5/5 keys refused" in rows[QUICK_FAULTS[0]]["note"]
    assert "3/3 refused" in rows["bad console commands"]["note"]
    assert "link_down" in rows["forged STRT on the serial line"]["note"]
    # What the twin recorded says the same: the gateway refused the five keys (its first
    # segment: the "gateway killed" row starts a second one), the controller the three
    # commands (and the 1795-point seam, had it refused it before sending).
    assert codes(run_dir, "robot_gateway").count("param_rejected") == 5
    seam_refused = alter_bench.table["path play of a 1795-point seam"]["note"].startswith("refused before sending")
    assert codes(run_dir, "controller").count("bad_command") == 3 + seam_refused


def codes(run_dir: Path, component: str) -> list[str]:
    """The event codes ``component`` recorded in the run."""
    rec = read(run_dir / f"{component}.mcap")
    return [e.decode().code for e in rec.outputs if e.topic == f"{component}/events"]


@pytest.mark.timeout(120)
def test_ctrl_c_ends_the_twin(tmp_path):
    run_dir = tmp_path / "run"
    # (SIGINT at its default in the child: a process started where it is ignored inherits that,
    # and Python then never raises KeyboardInterrupt; seen in the whole suite under load)
    p = subprocess.Popen(humanpt_cmd("bench", "faults", "--only", "param,forged,nan", "--run-dir", str(run_dir)),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # Ctrl-C while the twin comes up (its router and processes started, the servo loop not
        # yet running: seconds on any machine). Sent once the loop ran, it could come after the
        # three quick attacks and the bench's end on a loaded machine, where the twin's realtime
        # processes starve this one (exit 0 at load 8 with two CPU hogs).
        for line in p.stderr:
            if "starting the live twin" in line:
                break
        else:
            pytest.fail(f"the bench ended before it started its twin: {p.wait()}")
        deadline = time.monotonic() + 60
        while not leftovers(run_dir) and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)  # the twin's first process, spawned by the bench's thread
        assert leftovers(run_dir), "no twin processes while the bench runs"
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=60) == 130
    finally:
        if p.poll() is None:
            p.kill()
        p.communicate()
    deadline = time.monotonic() + 5
    while leftovers(run_dir) and time.monotonic() < deadline:
        time.sleep(0.1)  # a child reaped by init a moment after its parent's wait
    assert leftovers(run_dir) == []


def test_bus_flood_holds_the_robot(alter_bench):
    """Issue 14 item 6 (and issue 31: this row accepted any exit status): 2 s of junk
    commands at full rate on the command key. The verdict is safety: the robot's largest
    flange step in the window within the gateway's per-cycle limit (100 mm/s x 28 ms,
    + 5 %), read from the simulated robot's own recording too; exit status 0 (the verdict
    held). Whether the loop rides out a flood that takes both cores (the bench and the
    router) is liveness, machine-dependent: the row reports it (robot states' largest gap,
    late commands, link restarts) and the README gives the figures; it is not asserted."""
    run_dir = alter_bench.run_dir
    row = alter_bench.table["bus flood (2 s junk commands)"]
    assert row["verdict"] == "ok", row
    held = HELD.fullmatch(row["robot held"])
    assert held, row
    limit = 100.0 * 0.028
    assert float(held[2]) == pytest.approx(limit)
    assert float(held[1]) <= 1.05 * limit, row
    assert re.search(r"\| loop: robot_state max gap \d+ ms", row["note"]), row
    # The robot's own truth: no step over the limit per cycle through the whole run (every
    # row's, the flood's among them).
    truth = [e.decode() for e in read(run_dir / "sim_robot.mcap").outputs if e.topic == "sim_robot/truth"]
    assert len(truth) > 100
    xyz = np.array([from_pose(t.world_T_flange)[:3, 3] for t in truth])
    stamps = np.array([t.header.stamp_ns for t in truth])
    cycles = np.maximum(1, np.round(np.diff(stamps) / 28e6))
    assert (1e3 * np.linalg.norm(np.diff(xyz, axis=0), axis=1) / cycles).max() <= 1.05 * limit


def test_link_rows_over_alter(alter_bench):
    """Issue 29's rows over ALTER: the gateway killed mid-motion (the robot moved at most two
    cycles at the gateway's limit after it), the 1795-point seam played (or refused) without
    a fault latched; the RSI-only rows skipped, with the reason."""
    rows = alter_bench.table
    kill_within_bound(rows[LINK_ROWS["kill"]], 100.0 * 0.028)  # 100 mm/s x 28 ms
    assert rows[LINK_ROWS["kill"]]["verdict"] == "ok"
    for key, links in (("inject", "rsi"), ("junk", "rsi or abb"), ("ipoc", "rsi")):
        assert rows[LINK_ROWS[key]]["verdict"] == "skipped"
        assert rows[LINK_ROWS[key]]["note"] == f"skipped: not over ALTER (--link {links})", rows[LINK_ROWS[key]]
    seam_played_or_refused(rows[LINK_ROWS["bigseam"]])
    assert rows[LINK_ROWS["bigseam"]]["verdict"] == "ok"
