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


@pytest.mark.twin  # (main runs the lock-step twin: the conftest cannot see it by name)
@pytest.mark.timeout(900)  # bounds a hang only: ~100 s alone, several times that on a loaded machine
def test_the_job_runs_on_the_puma_by_default(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(teach, "STAGES", {})  # no calibration stage: teach and play back only
    assert main(["demo", "--calibrate", "--world", "ideal", "--run-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "robot the simulated Puma" in out
    assert (tmp_path / "robot_gateway.mcap").is_file() and (tmp_path / "sim_robot.mcap").is_file()
    assert not (tmp_path / "standin_robot.mcap").exists()
    assert "REFUSED" not in out and "played back (the torch's true path)" in out
    assert "largest joint step of a cycle (the Puma)" in out


def test_a_link_the_job_does_not_run_over_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="--calibrate: the job runs over the ALTER link, not --link rsi"):
        main(["demo", "--calibrate", "--link", "rsi", "--run-dir", str(tmp_path)])
    assert not any(tmp_path.iterdir())  # nothing ran
