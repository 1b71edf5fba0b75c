"""The whole closed loop on the lock-step twin over RSI at 12 ms (build_system with
``rsi_cycle_ms``): the servo tracks the paper's arc, and every core replays exactly."""

from __future__ import annotations

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.runtime.replay import replay
from humanpt.twin.system import build_system, path_points, tracking_errors


def test_the_arc_over_rsi_at_12_ms_is_tracked_and_replays(tmp_path):
    w = build_system("arc", seed=3, robot="puma", rsi_cycle_ms=12.0,
                     controller=ControllerConfig(record_on_start=True), run_dir=tmp_path)
    w.run_for(5.0)
    w.close()
    t, e_mm, e_deg = tracking_errors(w)
    # (the same bounds as over ALTER at 28 ms in tests/e2e/test_servo_twin.py)
    assert e_mm.max() < 1.6 and e_deg.max() < 1.0, (e_mm.max(), e_deg.max())
    assert e_mm[t > 3_000_000_000].max() < 0.2, e_mm[t > 3_000_000_000].max()
    _, xg, _ = path_points(w)
    radius = np.linalg.norm(xg[:, :2] - [147.5, 1378.5], axis=1)
    assert len(xg) > 10 and np.all(np.abs(radius - 246.0) < 1.0), radius
    for comp in ("sim_robot", "robot_gateway", "controller"):
        res = replay(tmp_path / f"{comp}.mcap")
        # a robot cycle every 12 ms for 5 s
        assert res.match and res.compared >= 400, res.report()
