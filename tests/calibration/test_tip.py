"""``humanpt calibrate tip``: the pivot calibration's tip into the rig (issue 17.4). The CLI
runs in this process (the process boundary is not what is tested)."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.geometry.rig import Rig
from humanpt.runtime.rigfile import load_rig, write_rig

TRUE_TIP = np.array([0.0, 0.0, 60.0]) + [0.3, -0.2, 0.4]  # NEEDLE_MM + the world source "tip"


def _cli(main, capsys, *args) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``humanpt ARGS`` run by ``main``."""
    try:
        rc = main(list(args))
    except SystemExit as e:  # argparse's refusals
        rc = e.code if isinstance(e.code, int) else 1
    out = capsys.readouterr()
    return rc, out.out, out.err


@pytest.mark.twin  # (main runs the lock-step twin: the conftest cannot see it by name)
def test_tip_calibration_on_the_twin_writes_the_rig(tmp_path, capsys, cli_main):
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    rc, out, err = _cli(cli_main, capsys, "calibrate", "tip", "--twin", "--world", "ideal+tip", "--rig", str(rig))
    assert rc == 0, out + err
    tip = load_rig(rig).tip
    assert tip.calibration.method == "pivot" and tip.calibration.date
    assert np.linalg.norm(np.asarray(tip.tob_t_tip_mm) - TRUE_TIP) < 0.15, tip  # 0.045 mm, seed 0
    assert load_rig(tmp_path / "rig.toml.bak") == Rig()  # the old rig kept
    assert "calibrated off by" in out and "the design value was off by 0.539 mm" in out


def test_bad_tip_requests_write_nothing(tmp_path, capsys, cli_main):
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    before = rig.read_bytes()
    for args, says in ((["--twin", "--samples", "3"], "--samples must be >= 6"),
                       ([], "give --config FILE (a live cell) or --twin"),
                       (["--twin", "--world", "nosuch"], "not 'ideal', 'realistic'"),
                       (["--method", "paper", "--config", "c.toml"], "--method paper runs on the twin"),
                       (["--twin", "--method", "paper", "--pattern-poses", "0"], "--pattern-poses must be >= 1")):
        rc, _, err = _cli(cli_main, capsys, "calibrate", "tip", "--rig", str(rig), *args)
        assert rc == 2 and says in err, (args, err)
    (tmp_path / "bad.toml").write_text("version = 1\n[psvs]\na_u = -1\n")
    rc, _, err = _cli(cli_main, capsys, "calibrate", "tip", "--twin", "--rig", str(tmp_path / "bad.toml"))
    assert rc == 2 and "a_u" in err
    assert rig.read_bytes() == before and not (tmp_path / "rig.toml.bak").exists()


@pytest.mark.twin  # (main runs the lock-step twin: the conftest cannot see it by name)
def test_the_papers_procedure_on_the_twin_writes_the_rig(tmp_path, capsys, cli_main):
    """Issue 33.4: --method paper (P' measured as a printed circle's centre through the PSVS,
    eq. 10-11, then eq. 12-13 while pivoting on it) within 0.3 mm of the world's true tip."""
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    rc, out, err = _cli(cli_main, capsys, "calibrate", "tip", "--twin", "--world", "ideal+tip", "--method", "paper",
                        "--pattern-poses", "6", "--rig", str(rig))
    assert rc == 0, out + err
    tip = load_rig(rig).tip
    assert tip.calibration.method == "paper" and "eq. (12)-(13)" in tip.calibration.note
    assert np.linalg.norm(np.asarray(tip.tob_t_tip_mm) - TRUE_TIP) < 0.3, tip  # 0.035 mm, seed 0, 10 poses
    assert "P' = (" in out and "eq. 12-13 on P'" in out


def test_the_printed_circles_centre_is_found_where_it_was_drawn():
    """A disc drawn here (area-sampled, 16 x 16 per pixel) at a known sub-pixel centre, on
    noise: pattern_centre_px finds it to a few hundredths of a pixel."""
    from humanpt.calibration.tip import pattern_centre_px

    rng = np.random.default_rng(0)
    h, w, n = 120, 160, 16
    centre, radius = np.array([71.37, 52.81]), 7.5
    s = (np.arange(n) + 0.5) / n - 0.5
    v, u = np.mgrid[0:h, 0:w]
    cover = np.zeros((h, w))
    for dy in s:
        for dx in s:
            cover += np.hypot(u + dx - centre[0], v + dy - centre[1]) <= radius
    image = np.clip(200 - 190 * cover / n**2 + rng.normal(0, 1.0, (h, w)), 0, 255)
    np.testing.assert_allclose(pattern_centre_px(image), centre, atol=0.03)


def test_the_pivot_point_is_measured_through_the_psvs():
    """Eq. 10-11 on the twin's rendered circle: P' within 0.1 mm of where it is printed
    (0.027 mm with 10 poses, seed 0)."""
    from humanpt.twin.cal_tip import PIVOT_X, measure_pivot_point_on_twin
    from humanpt.twin.worlds import World

    p, lines, off = measure_pivot_point_on_twin(World.named("ideal+tip"), Rig(), 0, 10)
    assert np.linalg.norm(p - np.asarray(PIVOT_X[:3])) < 0.1 and off < 0.1
    assert "10 robot poses" in lines[0]
