"""Issue 32.3: `humanpt demo --calibrate` passes on every option it accepts (--set, --speed,
--robot standin) or refuses it, naming it, before anything runs (it dropped --set, --speed
and --robot)."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.twin import teach
from humanpt.twin.worlds import World
from tests.conftest import run_cli_here


@pytest.mark.parametrize("extra, names", [
    (["--viewer"], "--viewer"), (["--port", "7447"], "--port"), (["--secure"], "--secure"),
    (["--duration", "5"], "--duration"), (["--link", "rsi", "--cycle-ms", "12"], "--cycle-ms"),
    (["--link", "rsi"], "--link"), (["--robot", "rsi"], "--robot"), (["--robot", "abb"], "--robot abb"),
    (["--set", "controller.nosuch=1"], "nosuch"), (["--set", "nosection.key=1"], "nosection"),
    (["--speed", "2000"], "speed_mm_s"),
])
def test_an_option_the_job_does_not_take_is_refused_before_anything_runs(tmp_path, extra, names):
    # (the verb in this process: what is checked is its status, its message and that nothing
    # ran, not its process)
    run_dir = tmp_path / "job"
    r = run_cli_here("demo", "--calibrate", "--run-dir", str(run_dir), *extra)
    assert r.returncode != 0, r.stdout
    assert names in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not run_dir.exists() or not any(run_dir.iterdir())  # nothing ran, nothing written


def test_the_teach_and_play_run_takes_the_overrides_speed_and_law(tmp_path):
    """--speed 60 (operator.speed_mm_s) and --set controller.recording_spacing_mm=6 reach the
    teach-and-play run: its recorded points are 6-8 mm apart and the tip moved at 60 mm/s
    between them (the defaults: 4 mm, 20 mm/s)."""
    from humanpt.runtime.recording import read
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import from_pose

    res = teach.calibrate_then_teach("scurve", World.ideal(), 0, stages=(), run_dir=tmp_path,
                                     overrides={"operator": {"speed_mm_s": 60.0},
                                                "controller": {"recording_spacing_mm": 6.0}}, law="thetau")
    rec = read(tmp_path / "controller.mcap")
    pts = [pb.PathPoint.FromString(e.data) for e in rec.outputs if e.topic == "controller/path"]
    assert len(pts) == len(res.taught_path_mm) > 50
    p_mm = np.array([from_pose(p.world_T_tip)[:3, 3] * 1e3 for p in pts])
    t_s = np.array([p.header.stamp_ns for p in pts]) * 1e-9
    gaps = np.linalg.norm(np.diff(p_mm, axis=0), axis=1)
    moving = gaps > 1.0
    # at least 6 mm, and at most one image's motion more (2 mm at 60 mm/s, 30 frames/s)
    assert 5.8 <= np.median(gaps[moving]) <= 8.2, np.median(gaps[moving])
    speed = gaps[moving] / np.diff(t_s)[moving]
    assert np.median(speed) == pytest.approx(60.0, rel=0.1)
    assert rec.config()["recording_spacing_mm"] == 6.0 and rec.config()["law"] == "thetau"
