"""humanpt demo --link abb: the whole live system over ABB EGM at 4 ms (the simulated EGM
controller as the sim_robot process, the gateway's abb link over UDP on loopback), end to
end: it records, and the EGM cores replay from their recordings."""

from __future__ import annotations

import re
import tomllib

import numpy as np
import pytest

from humanpt.controller import pathfile
from humanpt.robot_gateway.links.abb.runstats import egm_cycles
from humanpt.runtime.recording import read
from humanpt.runtime.replay import replay

pytestmark = pytest.mark.cell  # a whole live cell: one at a time (tests/conftest.py)


@pytest.mark.timeout(300)
@pytest.mark.live
def test_live_demo_over_abb_records_the_arc_and_replays(tmp_path, cli):
    run = tmp_path / "abb"
    # (6 s counted from everything up: the operator holds its start pose 3 s from its own start,
    # and on a loaded machine it is the last up (CI: 31 s of start-up, the arc began 3 s after
    # it, and 3 s left no moving path to record); 1500 cycles of 4 ms and more)
    # (the demo's shell in this process: the components, and the router, are processes of their own)
    code, out, err = cli("demo", "--link", "abb", "--scenario", "arc", "--duration", "6", "--run-dir", str(run))
    assert code == 0, out + err + (run / "processes.log").read_text()[-3000:]
    cfg = tomllib.loads((run / "humanpt.toml").read_text())
    assert cfg["robot_gateway"]["link"] == "abb" and cfg["sim_robot"]["protocol"] == "egm"
    assert cfg["robot_gateway"]["cycle_period_ms"] == 4.0
    assert cfg["sim_robot"]["egm_gateway"] == cfg["robot_gateway"]["udp_bind"]
    # The cycles answered in time are printed (a figure, not judged here: the machine's load
    # decides it), and they are the recording's count.
    m = re.search(r"EGM at 4 ms: (\d+) cycles, (\d+) answered in time", out)
    assert m, out
    stats = egm_cycles(run)
    assert stats is not None and (stats.cycles, stats.cycles - stats.late) == (int(m[1]), int(m[2]))
    assert stats.cycles > 500  # 4 s and more at 4 ms, counted from the gateway's first answer
    # The servo kept the target: the recorded path follows the paper's arc (radius 246 mm).
    path = pathfile.read(run / "paths" / "path-1.csv")
    assert len(path) > 5, f"{len(path)} points recorded\n" + (run / "processes.log").read_text()[-3000:]
    radius = np.linalg.norm(path.x_g[:, :2] - [147.5, 1378.5], axis=1)
    assert np.all(np.abs(radius - 246.0) < 1.0)
    for comp in ("robot_gateway", "sim_robot"):  # the EGM cores replay from their recordings
        res = replay(run / f"{comp}.mcap")
        assert res.match and res.compared > 500, res.report()
    # every robot state carried the link's 4 ms to the pose filter
    states = [e.decode() for e in read(run / "pose_filter.mcap").inputs if e.topic == "robot_gateway/robot_state"]
    assert len(states) > 100 and {s.cycle_period_ns for s in states} == {4_000_000}
