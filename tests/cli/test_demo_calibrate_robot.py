"""``humanpt demo --calibrate`` runs the job on the robot asked for (issue 33.2): the
simulated Puma behind the gateway and its ALTER line by default (the run records
robot_gateway.mcap and sim_robot.mcap), never silently another robot."""

from __future__ import annotations

import sys

import pytest

from humanpt.cli.main import main
from humanpt.twin import teach


@pytest.fixture(autouse=True)
def _switch_interval():
    """demo tunes the interpreter as a run does (runtime.tuning): set back afterwards."""
    before = sys.getswitchinterval()
    yield
    sys.setswitchinterval(before)


# A trapezium a third of the paper's (b1 = 120 mm, b2 = 80 mm, h = 45 mm; the paper's is 451,
# 361, 45 mm) at the same place and torch angle: which robot runs the job is what is checked
# here (tests/twin/test_teach.py plays the paper's trapezium back on the Puma).
SMALL_TRAPEZIUM = """scenario small-trapezium
driver 0 0 60
path tip
start 176.132 1226.272 0 0 15 180
speed 20
line 296.132 1226.272 0
line 276.132 1271.272 0
line 196.132 1271.272 0
line 176.132 1226.272 0
dwell 1
"""


@pytest.mark.twin  # (main runs the lock-step twin: the conftest cannot see it by name)
@pytest.mark.timeout(900)  # bounds a hang only: ~30 s alone, several times that on a loaded machine
def test_the_job_runs_on_the_puma_by_default(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(teach, "STAGES", {})  # no calibration stage: teach and play back only
    seam = tmp_path / "small-trapezium.txt"
    seam.write_text(SMALL_TRAPEZIUM)
    run_dir = tmp_path / "run"
    assert main(["demo", "--calibrate", "--world", "ideal", "--scenario", str(seam), "--run-dir", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "robot the simulated Puma" in out
    assert (run_dir / "robot_gateway.mcap").is_file() and (run_dir / "sim_robot.mcap").is_file()
    assert not (run_dir / "standin_robot.mcap").exists()
    assert "REFUSED" not in out and "played back (the torch's true path)" in out
    assert "largest joint step of a cycle (the Puma)" in out


def test_a_link_the_job_does_not_run_over_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="--calibrate: the job runs over the ALTER link, not --link rsi"):
        main(["demo", "--calibrate", "--link", "rsi", "--run-dir", str(tmp_path)])
    assert not any(tmp_path.iterdir())  # nothing ran
