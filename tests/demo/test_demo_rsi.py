"""humanpt demo --link rsi: the whole live system over the KUKA RSI-style link at 12 ms
(the simulated RSI controller as sim_robot, the gateway over UDP), end to end."""

from __future__ import annotations

import re
import tomllib

import numpy as np
import pytest

from humanpt.controller import pathfile
from humanpt.robot_gateway.links.rsi.runstats import rsi_cycles
from humanpt.runtime.recording import read
from humanpt.runtime.replay import replay

pytestmark = pytest.mark.cell  # a whole live cell: one at a time (tests/conftest.py)


@pytest.mark.timeout(300)
@pytest.mark.live
def test_live_demo_over_rsi_at_12_ms_records_the_arc(tmp_path, cli):
    run = tmp_path / "rsi"
    # (5 s of the running loop, counted from everything up, and the second before it: 500 cycles of 12 ms)
    # (the demo's shell in this process: the components, and the router, are processes of their own)
    code, out, err = cli("demo", "--link", "rsi", "--cycle-ms", "12", "--scenario", "arc", "--duration", "5",
                         "--run-dir", str(run))
    assert code == 0, out + err + (run / "processes.log").read_text()[-3000:]
    # One cycle period, the link's, in one place: no other section has one (issue 30).
    cfg = tomllib.loads((run / "humanpt.toml").read_text())
    assert cfg["robot_gateway"]["link"] == "rsi" and cfg["sim_robot"]["protocol"] == "rsi"
    assert cfg["robot_gateway"]["cycle_period_ms"] == 12.0
    assert not [(s, k) for s, t in cfg.items() for k in t if "cycle_period" in k and s != "robot_gateway"]
    assert "predict_ahead_ms" not in cfg.get("pose_filter", {})
    # The robot's own count (<Delay> in its datagrams), printed; it is the recording's count.
    # How many were answered in time is a figure of `humanpt bench rsi`, not judged here (issue
    # 31: a loaded machine answers fewer in time; that is no defect of the loop).
    m = re.search(r"RSI at 12 ms: (\d+) cycles, (\d+) answered in time", out)
    assert m, out
    stats = rsi_cycles(run)
    assert stats is not None and (stats.cycles, stats.cycles - stats.late) == (int(m[1]), int(m[2]))
    assert stats.cycles > 400 and stats.cycles - stats.late > 0  # the loop closed
    # The servo kept the target: the recorded path follows the paper's arc (radius 246 mm).
    path = pathfile.read(run / "paths" / "path-1.csv")
    assert len(path) > 5
    radius = np.linalg.norm(path.x_g[:, :2] - [147.5, 1378.5], axis=1)
    assert np.all(np.abs(radius - 246.0) < 1.0)
    for comp in ("robot_gateway", "sim_robot"):  # the RSI cores replay from their recordings
        res = replay(run / f"{comp}.mcap")
        assert res.match and res.compared > 400, res.report()
    # ... and every robot state carried the link's 12 ms to the controller and the pose filter
    states = [e.decode() for e in read(run / "pose_filter.mcap").inputs if e.topic == "robot_gateway/robot_state"]
    assert len(states) > 100 and {s.cycle_period_ns for s in states} == {12_000_000}


def test_cycle_ms_is_for_rsi(tmp_path, cli):
    # (each before anything starts: no router, no process)
    code, out, err = cli("demo", "--cycle-ms", "4", "--run-dir", str(tmp_path / "r"))
    assert code != 0 and "ALTER link runs the Puma's 28 ms cycle" in err
    code, out, err = cli("demo", "--link", "rsi", "--lockstep", "--robot", "standin", "--run-dir", str(tmp_path / "r2"))
    assert code != 0 and "simulated Puma" in err
    code, out, err = cli("demo", "--robot", "alter", "--link", "rsi", "--run-dir", str(tmp_path / "r3"))
    assert code != 0 and "--robot alter and --link rsi disagree" in err


def test_lockstep_demo_over_rsi_at_4_ms_is_deterministic(tmp_path, cli):
    """`humanpt demo --lockstep --link rsi --cycle-ms 4`: two runs give the same path (the
    second spelt as issue 22 does, `--robot rsi`: the same run)."""
    paths = []
    for k, link in ((1, ["--link", "rsi"]), (2, ["--robot", "rsi"])):
        # (3 s: the path recorded from the operator's start delay, 2 s, on)
        code, out, err = cli("demo", "--lockstep", *link, "--cycle-ms", "4", "--scenario", "arc", "--duration", "3",
                             "--run-dir", str(tmp_path / f"r{k}"))
        assert code == 0, out + err
        paths.append((tmp_path / f"r{k}" / "paths" / "path-1.csv").read_text())
    assert paths[0] == paths[1] and len(paths[0].splitlines()) > 3
