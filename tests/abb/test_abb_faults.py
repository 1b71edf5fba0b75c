"""``humanpt bench faults --link abb``: the rows of the link fault suite that run over ABB EGM
against the live twin (router, processes, real UDP on loopback): the gateway SIGKILLed while
the robot plays a line at 40 mm/s (EGM goes on to the last target, at most the lead ahead,
then stops after its communication timeout) and a junk flood from another port (EGM keeps
running). Verdicts only, never rates. The rows not written for EGM yet are skipped, named."""

from __future__ import annotations

import re

import pytest

from humanpt.robot_gateway.links.abb.config import AbbConfig
from tests.bench.test_faults import HELD, leftovers, table
from tests.conftest import run_cli


@pytest.mark.timeout(600)
def test_kill_and_junk_rows_over_abb(tmp_path):
    run_dir = tmp_path / "run"
    p = run_cli("bench", "faults", "--link", "abb", "--only", "kill,junk,inject", "--run-dir", str(run_dir),
                timeout=560)
    rows = table(p.stdout)
    assert len(rows) == 3, p.stdout + p.stderr
    kill = rows["gateway killed mid-motion (40 mm/s)"]
    junk = rows["junk UDP flood from another port (3 s)"]
    inject = rows["<Rob> injection from another UDP port (80)"]
    assert inject["verdict"] == "skipped", inject  # (RSI's <Rob>: not an EGM attack)
    # Killed: the flange moved at most 2 cycles at the gateway's limit + the lead (the twin's
    # gateway: 100 mm/s x 4 ms, max_lead_mm 5) after the kill; EGM then stopped at the robot.
    held = HELD.fullmatch(kill["robot held"])
    assert held, kill
    assert float(held[2]) == pytest.approx(2 * 100.0 * 0.004 + AbbConfig().max_lead_mm)
    assert float(held[1]) <= float(held[2]), kill
    assert re.search(r"killed at [\d.]+ mm/s", kill["note"]) and "sim_robot: egm_stopped" in kill["note"], kill
    assert kill["verdict"] == "ok", kill
    assert "EGM still running" in junk["note"] and junk["verdict"] == "ok", junk
    assert leftovers(run_dir) == []
    assert p.returncode == 0, p.stdout + p.stderr
