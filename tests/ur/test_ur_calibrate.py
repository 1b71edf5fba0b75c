"""``humanpt demo --calibrate --robot ur`` (issue 34 item 6): the job teaches and plays back on
the simulated UR5e behind the gateway's RTDE link on the lock-step twin (the run records the
gateway and sim_robot; the simulated controller is UR's), at a CB3's 8 ms (the e-Series' 2 ms,
the default, is the same code at four times the cycles). The calibration stages are the Puma
job's (tests/twin/test_teach.py): here teach and play back only, on a trapezium small enough
to be short (b1 = 40 mm, b2 = 20 mm, h = 15 mm), one seed."""

from __future__ import annotations

import re
import sys

import pytest

from humanpt.cli.main import main
from humanpt.runtime.recording import read
from humanpt.twin import teach


@pytest.fixture(autouse=True)
def _switch_interval():
    """demo tunes the interpreter as a run does (runtime.tuning): set back afterwards."""
    before = sys.getswitchinterval()
    yield
    sys.setswitchinterval(before)


TINY_TRAPEZIUM = """scenario tiny-trapezium
driver 0 0 60
path tip
start 176.132 1226.272 0 0 15 180
speed 20
line 216.132 1226.272 0
line 211.132 1241.272 0
line 181.132 1241.272 0
line 176.132 1226.272 0
dwell 1
"""


@pytest.mark.twin  # (main runs the lock-step twin: the conftest cannot see it by name)
@pytest.mark.timeout(900)  # bounds a hang only
def test_the_job_teaches_and_plays_back_on_the_ur5e(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(teach, "STAGES", {})  # no calibration stage: teach and play back only
    seam = tmp_path / "tiny-trapezium.txt"
    seam.write_text(TINY_TRAPEZIUM)
    run_dir = tmp_path / "run"
    assert main(["demo", "--calibrate", "--robot", "ur", "--cycle-ms", "8", "--world", "ideal", "--scenario",
                 str(seam), "--run-dir", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "robot the simulated UR5e (robot_gateway + RTDE + sim_robot)" in out
    assert "REFUSED" not in out and "played back (the torch's true path)" in out
    assert not (run_dir / "standin_robot.mcap").exists()
    # The robot was the UR over RTDE: the gateway's link and the controller's cycle in the recording.
    states = [e.decode() for e in read(run_dir / "robot_gateway.mcap").outputs if e.topic == "robot_gateway/robot_state"]
    assert len(states) > 250 and {m.cycle_period_ns for m in states} == {8_000_000}
    assert not any(re.search(r"sim_robot: (watchdog_stop|protective_stop)", line) for line in out.splitlines())


def test_the_job_refuses_a_link_it_does_not_run_over_and_a_cycle_a_ur_does_not_run(tmp_path):
    with pytest.raises(SystemExit, match="--calibrate: the job runs over the ALTER link, not --link abb"):
        main(["demo", "--calibrate", "--link", "abb", "--run-dir", str(tmp_path)])
    with pytest.raises(SystemExit, match="--calibrate: --cycle-ms 4: UR RTDE runs at 2 ms"):
        main(["demo", "--calibrate", "--robot", "ur", "--cycle-ms", "4", "--run-dir", str(tmp_path)])
    with pytest.raises(SystemExit, match="--calibrate: --cycle-ms is not taken"):  # (the Puma's job: 28 ms)
        main(["demo", "--calibrate", "--cycle-ms", "8", "--run-dir", str(tmp_path)])
    assert not any(tmp_path.iterdir())
