"""twin.run: the one way the demo, the experiments and the bench run the closed loop."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.operator import OperatorConfig
from humanpt.twin.run import OverrideError, SystemConfig, flange_T_desired_mm, run

# The static scenario's start (Table 1) with a 60 mm driver.
TIP_SCENARIO = """\
scenario tipped
driver 0 0 60
path tob
start 236.132 1248.772 85.284 -2.598 -0.883 -4.535
"""


def test_the_desired_point_is_dz_out_along_the_camera_axis():
    # The default hand-eye (geometry/rig.py): camera axes parallel to the flange's, its
    # centre at (0, 60, 100) mm. D lies dz further along the camera z axis, same axes.
    T = flange_T_desired_mm(ControllerConfig(dz_mm=450.0))
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [0.0, 60.0, 550.0], atol=1e-9)
    # The controller drives the same D (it works in metres).
    core = ControllerCore(ControllerConfig(dz_mm=450.0))
    np.testing.assert_allclose(core.flange_T_desired[:3, 3], [0.0, 0.060, 0.550], atol=1e-12)


def test_overrides_apply_over_the_given_configs_and_a_bad_key_is_named():
    cfg = SystemConfig.for_scenario("arc", 3, {"controller": {"dz_mm": 500.0}, "pose_filter": {"still_detect": False}},
                                    controller=ControllerConfig(law="paper"))
    assert (cfg.seed, cfg.operator.seed, cfg.sim_camera.seed) == (3, 3, 3)
    assert cfg.controller.dz_mm == 500.0 and cfg.controller.law == "paper"  # override and base both kept
    assert cfg.pose_filter.still_detect is False
    with pytest.raises(OverrideError, match="nosuch"):
        SystemConfig.for_scenario("arc", 0, {"pose_filter": {"nosuch": 1}})


def test_a_scenario_with_a_driver_makes_the_controller_record_the_tip(tmp_path):
    scn = tmp_path / "tip.scn"
    scn.write_text(TIP_SCENARIO)
    cfg = SystemConfig.for_scenario(OperatorConfig(scenario_file=str(scn)))
    assert cfg.controller.has_driver and cfg.rig.tip.tob_t_tip_mm == (0.0, 0.0, 60.0)


def test_run_records_the_path_from_record_start_only():
    cfg = SystemConfig.for_scenario("static", 0)
    res = run(cfg, robot="standin", duration_s=2.5, record_from_s=1.0)
    assert res.world.now_ns == 2_500_000_000 and res.twin_s == 2.5
    stamps, xg, _ = res.path_points()
    # A point every 10 cycles of 28 ms (ControllerConfig defaults) in the 1.5 s recorded:
    # 1.5 / 0.28 = 5.4 points.
    assert 5 <= len(stamps) <= 6, stamps
    assert stamps.min() >= 1_000_000_000
    # Not told to record: no path.
    quiet = run(cfg, robot="standin", duration_s=2.5)
    assert len(quiet.path_points()[0]) == 0
