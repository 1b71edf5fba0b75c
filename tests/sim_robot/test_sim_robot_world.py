"""The world's arm of the simulated Puma: kinematic errors (joint zero offsets, link
lengths) move the true flange but not the reported pose, and the arm can lag its setpoint
by a first-order response; every error off by default. Expected values by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from humanpt.runtime.config import ConfigError, build
from humanpt.sim_robot.config import SimRobotConfig
from tests.sim_robot.test_sim_robot_core import CYCLE_NS, SimRig


def _true_and_reported(**kw):
    rig = SimRig(**kw)
    rig.tick()
    return rig.world_T_flange_mm(), rig.sim.base_T_flange_mm, rig


def test_the_ideal_arm_is_the_default_and_its_truth_is_the_reported_pose():
    cfg = SimRobotConfig()
    assert cfg.ideal_arm and cfg.lag_time_constant_ms == 0.0
    true, reported, _ = _true_and_reported()
    np.testing.assert_allclose(true, reported, atol=1e-9)  # world = base (via a quaternion)


def test_a_base_joint_offset_turns_the_true_flange_about_the_base_axis():
    """Joint 1 turns about the base z axis: an offset of d deg moves the flange, at r =
    |(786, 190)| = 808.6 mm from that axis, sideways by 2 r sin(d / 2) ~ r d pi / 180 =
    0.706 mm for d = 0.05 deg, at the same height; the reported pose does not move."""
    d_deg = 0.05
    true, reported, rig = _true_and_reported(joint_offsets_deg=(d_deg, 0, 0, 0, 0, 0))
    _, ideal, _ = _true_and_reported()
    np.testing.assert_array_equal(reported, ideal)  # the encoders and the model agree
    p, q = ideal[:3, 3], true[:3, 3]
    r = math.hypot(p[0], p[1])
    assert r == pytest.approx(808.6, abs=0.1)
    c, s = math.cos(math.radians(d_deg)), math.sin(math.radians(d_deg))
    np.testing.assert_allclose(q, [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]], atol=1e-9)
    assert np.linalg.norm(q - p) == pytest.approx(r * math.radians(d_deg), rel=1e-6)
    assert np.linalg.norm(q - p) == pytest.approx(0.706, abs=0.001)
    # The STATUS the gateway receives is the nominal pose (0.01 mm codec).
    np.testing.assert_allclose(rig.statuses[-1].position_mm, p, atol=0.005 + 1e-9)


def test_a_flange_length_error_moves_the_true_flange_along_its_axis():
    """d6 is the last link's length along the flange's z axis: an error of e mm puts the
    true flange e mm further along that axis (here straight down: z lower by e)."""
    e = 0.4
    true, reported, _ = _true_and_reported(link_length_errors_mm=(0, 0, 0, 0, e))
    np.testing.assert_allclose(true[:3, 3], reported[:3, 3] + e * reported[:3, 2], atol=1e-9)
    np.testing.assert_allclose(true[:3, :3], reported[:3, :3], atol=1e-12)
    assert reported[2, 2] == pytest.approx(-1.0, abs=1e-9)  # the flange points down


def test_the_arm_lags_its_setpoint_by_a_first_order_response():
    """A 2 mm correction with tau = 28 ms (one cycle): after n cycles the flange has covered
    2 (1 - e^-n) mm; with tau = 0 all of it at once."""
    tau_rig = SimRig(lag_time_constant_ms=28.0)
    rig0 = SimRig()
    for rig in (tau_rig, rig0):
        rig.tick()
        start = rig.world_T_flange_mm()[:3, 3]
        rig.correct((2.0, 0.0, 0.0))
        moved = []
        for _ in range(4):
            rig.tick()
            moved.append(rig.world_T_flange_mm()[0, 3] - start[0])
        rig.moved = moved
    np.testing.assert_allclose(rig0.moved, [2.0] * 4, atol=1e-9)
    expected = [2.0 * (1.0 - math.exp(-n)) for n in range(1, 5)]
    # The joints lag, so the Cartesian path is nearly (not exactly) the straight line: 2 mm
    # at ~800 mm from the joints is ~2.5e-3 rad, bending it by ~800 mm x (2.5e-3)^2 = 0.005 mm.
    np.testing.assert_allclose(tau_rig.moved, expected, atol=2e-3)
    assert tau_rig.truths()[-1].header.stamp_ns == (len(tau_rig.truths()) - 1) * CYCLE_NS


def test_the_world_fields_are_checked():
    with pytest.raises(ValueError, match="joint_offsets_deg"):
        SimRobotConfig(joint_offsets_deg=(0.0,) * 5)
    with pytest.raises(ValueError, match="link_length_errors_mm"):
        SimRobotConfig(link_length_errors_mm=(0.0, float("nan"), 0.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="lag_time_constant_ms"):
        build(SimRobotConfig, {"lag_time_constant_ms": -1.0}, source="x.toml", section="sim_robot")
