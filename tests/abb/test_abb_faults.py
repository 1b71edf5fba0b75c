"""``humanpt bench faults --link abb``: the rows of the link fault suite that run over ABB EGM
against the live twin (router, processes, real UDP on loopback): the gateway SIGKILLed while
the robot plays a line at 40 mm/s (EGM goes on to the last target, at most the lead ahead,
then stops after its communication timeout). Verdicts only, never rates. (The junk flood row
runs with `--only junk`; in the suite a foreign sender's messages are tests/abb/test_abb_udp.py's,
to keep CI's time.)"""

from __future__ import annotations

import re

import pytest

from humanpt.robot_gateway.links.abb.config import AbbConfig
from tests.bench.test_faults import HELD, leftovers, table
from tests.conftest import run_cli


@pytest.mark.timeout(600)
def test_kill_row_over_abb(tmp_path):
    run_dir = tmp_path / "run"
    p = run_cli("bench", "faults", "--link", "abb", "--only", "kill", "--run-dir", str(run_dir), timeout=560)
    rows = table(p.stdout)
    assert len(rows) == 1, p.stdout + p.stderr
    kill = rows["gateway killed mid-motion (40 mm/s)"]
    # Killed: the flange moved at most 2 cycles at the gateway's limit + the lead (the twin's
    # gateway: 100 mm/s x 4 ms, max_lead_mm 5) after the kill; EGM then stopped at the robot.
    held = HELD.fullmatch(kill["robot held"])
    assert held, kill
    assert float(held[2]) == pytest.approx(2 * 100.0 * 0.004 + AbbConfig().max_lead_mm)
    assert float(held[1]) <= float(held[2]), kill
    assert re.search(r"killed at [\d.]+ mm/s", kill["note"]) and "sim_robot: egm_stopped" in kill["note"], kill
    assert kill["verdict"] == "ok", kill
    assert leftovers(run_dir) == []
    assert p.returncode == 0, p.stdout + p.stderr
