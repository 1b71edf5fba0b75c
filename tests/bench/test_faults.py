"""``humanpt bench faults`` end to end (issue 14, acceptance): the attacks against a live twin
(router + seven processes, a real pty), the printed table, and the twin ended cleanly, even on
Ctrl-C."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from humanpt.runtime.recording import read
from humanpt.schemas.convert import from_pose
from tests.conftest import ROOT, humanpt_cmd, run_cli

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
COLUMNS = ["fault", "verdict", "reaction", "robot held", "recovered", "data lost", "note"]
HELD = re.compile(r"yes \(([\d.]+) / ([\d.]+) mm\)")


def table(stdout: str) -> dict[str, dict[str, str]]:
    """{fault: {column: cell}} of the printed table (cells are separated by 2+ spaces)."""
    lines = stdout.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("fault "))
    assert re.split(r"\s{2,}", lines[head].strip()) == COLUMNS, lines[head]
    rows = {}
    for line in lines[head + 1:]:
        if not line.strip():
            break
        cells = re.split(r"\s{2,}", line.strip())
        assert len(cells) == len(COLUMNS), line
        rows[cells[0]] = dict(zip(COLUMNS, cells, strict=True))
    return rows


def leftovers(run_dir: Path) -> list[str]:
    """Command lines of live processes started for ``run_dir`` (each twin process names its
    config or run directory there)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if str(run_dir) in cmd:
            found.append(f"{pid}: {cmd}")
    return found


@pytest.mark.timeout(180)
def test_quick_attacks_are_seen_held_and_recovered(tmp_path):
    run_dir = tmp_path / "run"
    p = run_cli("bench", "faults", "--quick", "--run-dir", str(run_dir), timeout=150)
    assert p.returncode == 0, p.stdout + p.stderr
    rows = table(p.stdout)
    assert list(rows) == QUICK_FAULTS
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
    assert leftovers(run_dir) == []
    # What the twin recorded says the same: the gateway refused the five keys, the controller
    # the three commands.
    assert codes(run_dir, "robot_gateway").count("param_rejected") == 5
    assert codes(run_dir, "controller").count("bad_command") == 3


def codes(run_dir: Path, component: str) -> list[str]:
    """The event codes ``component`` recorded in the run."""
    rec = read(run_dir / f"{component}.mcap")
    return [e.decode().code for e in rec.outputs if e.topic == f"{component}/events"]


@pytest.mark.timeout(120)
def test_ctrl_c_ends_the_twin(tmp_path):
    run_dir = tmp_path / "run"
    p = subprocess.Popen(humanpt_cmd("bench", "faults", "--only", "param,forged,nan", "--run-dir", str(run_dir)),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        for line in p.stderr:
            if "loop running" in line:
                break
        else:
            pytest.fail(f"the bench ended before the loop ran: {p.wait()}")
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


@pytest.mark.timeout(150)
def test_bus_flood_holds_the_robot(tmp_path):
    """Issue 14 item 6 (and issue 31: this row accepted any exit status): 2 s of junk
    commands at full rate on the command key. The verdict is safety: the robot's largest
    flange step in the window within the gateway's per-cycle limit (100 mm/s x 28 ms,
    + 5 %), read from the simulated robot's own recording too; exit status 0 (the verdict
    held). Whether the loop rides out a flood that takes both cores (the bench and the
    router) is liveness, machine-dependent: the row reports it (robot states' largest gap,
    late commands, link restarts) and the README gives the figures; it is not asserted."""
    run_dir = tmp_path / "run"
    p = run_cli("bench", "faults", "--only", "flood", "--run-dir", str(run_dir), timeout=130)
    assert p.returncode == 0, p.stdout + p.stderr
    row = table(p.stdout)["bus flood (2 s junk commands)"]
    assert row["verdict"] == "ok", row
    held = HELD.fullmatch(row["robot held"])
    assert held, row
    limit = 100.0 * 0.028
    assert float(held[2]) == pytest.approx(limit)
    assert float(held[1]) <= 1.05 * limit, row
    assert re.search(r"\| loop: robot_state max gap \d+ ms", row["note"]), row
    assert leftovers(run_dir) == []
    # The robot's own truth: no step over the limit per cycle through the whole run.
    truth = [e.decode() for e in read(run_dir / "sim_robot.mcap").outputs if e.topic == "sim_robot/truth"]
    assert len(truth) > 100
    xyz = np.array([from_pose(t.world_T_flange)[:3, 3] for t in truth])
    stamps = np.array([t.header.stamp_ns for t in truth])
    cycles = np.maximum(1, np.round(np.diff(stamps) / 28e6))
    assert (1e3 * np.linalg.norm(np.diff(xyz, axis=0), axis=1) / cycles).max() <= 1.05 * limit
