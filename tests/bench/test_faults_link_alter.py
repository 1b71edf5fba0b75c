"""``humanpt bench faults`` rows of issue 29 over ALTER (the gateway killed mid-motion, a
1795-point seam played; the RSI-only rows skipped): a file of its own so that its live twin
and the RSI one (tests/bench/test_faults_link.py) run on different test workers."""

from __future__ import annotations

import pytest

from tests.bench.test_faults import leftovers, table
from tests.bench.test_faults_link import ROWS, _kill_within_bound, _seam_played_or_refused
from tests.conftest import run_cli


@pytest.mark.timeout(300)
def test_link_rows_over_alter(tmp_path):
    run_dir = tmp_path / "run"
    p = run_cli("bench", "faults", "--only", "kill,bigseam,inject", "--run-dir", str(run_dir), timeout=280)
    rows = table(p.stdout)
    assert list(rows) == [ROWS["kill"], ROWS["bigseam"], ROWS["inject"]], p.stdout + p.stderr
    assert leftovers(run_dir) == []
    _kill_within_bound(rows[ROWS["kill"]], 100.0 * 0.028)  # 100 mm/s x 28 ms
    assert rows[ROWS["inject"]]["verdict"] == "skipped"
    assert rows[ROWS["inject"]]["note"] == "skipped: not over ALTER (--link rsi)"
    _seam_played_or_refused(rows[ROWS["bigseam"]])
    assert p.returncode == 0, p.stdout + p.stderr


