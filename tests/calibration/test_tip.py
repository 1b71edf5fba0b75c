"""``humanpt calibrate tip``: the pivot calibration's tip into the rig (issue 17.4)."""

from __future__ import annotations

import numpy as np

from humanpt.geometry.rig import Rig
from humanpt.runtime.rigfile import load_rig, write_rig
from tests.conftest import run_cli

TRUE_TIP = np.array([0.0, 0.0, 60.0]) + [0.3, -0.2, 0.4]  # NEEDLE_MM + the world source "tip"


def test_tip_calibration_on_the_twin_writes_the_rig(tmp_path):
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    r = run_cli("calibrate", "tip", "--twin", "--world", "ideal+tip", "--rig", str(rig), timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    tip = load_rig(rig).tip
    assert tip.calibration.method == "pivot" and tip.calibration.date
    assert np.linalg.norm(np.asarray(tip.tob_t_tip_mm) - TRUE_TIP) < 0.15, tip  # 0.045 mm, seed 0
    assert load_rig(tmp_path / "rig.toml.bak") == Rig()  # the old rig kept
    assert "calibrated off by" in r.stdout and "the design value was off by 0.539 mm" in r.stdout


def test_bad_tip_requests_write_nothing(tmp_path):
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    before = rig.read_bytes()
    for args, says in ((["--twin", "--samples", "3"], "--samples must be >= 6"),
                       ([], "give --config FILE (a live cell) or --twin"),
                       (["--twin", "--world", "nosuch"], "not 'ideal', 'realistic'")):
        r = run_cli("calibrate", "tip", "--rig", str(rig), *args)
        assert r.returncode == 2 and says in r.stderr, (args, r.stderr)
    (tmp_path / "bad.toml").write_text("version = 1\n[psvs]\na_u = -1\n")
    r = run_cli("calibrate", "tip", "--twin", "--rig", str(tmp_path / "bad.toml"))
    assert r.returncode == 2 and "a_u" in r.stderr
    assert rig.read_bytes() == before and not (tmp_path / "rig.toml.bak").exists()
