"""The robot pose at an image's stamp: linear in translation and at a constant angular rate
between the two robot states around it (by hand: a turn about one fixed axis), extrapolated
from the last two by at most the allowed time, None beyond."""

from __future__ import annotations

import numpy as np

from humanpt.pose_filter.robot_buffer import RobotPoseBuffer


def _pose(angle_rad: float, x_m: float) -> np.ndarray:
    """A turn about the world axis (1, 1, 0)/sqrt(2), by Rodrigues' formula by hand."""
    k = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle_rad) * kx + (1 - np.cos(angle_rad)) * kx @ kx
    T[:3, 3] = [x_m, 0.2, 0.5]
    return T


def test_interpolates_and_extrapolates_at_constant_rates():
    buf = RobotPoseBuffer()
    for k in range(4):  # states every 28 ms turning 0.1 rad and moving 2 mm per state
        buf.add(28_000_000 * k, _pose(0.3 + 0.1 * k, 1.0 + 0.002 * k))
    buf.add(28_000_000, _pose(9.0, 9.0))  # out of order: ignored
    for t_ms, (angle, x) in ((14, (0.35, 1.001)), (28, (0.4, 1.002)), (70, (0.55, 1.005)),
                             (84, (0.6, 1.006)), (98, (0.65, 1.007)), (-7, (0.275, 0.9995))):
        np.testing.assert_allclose(buf.at(t_ms * 1_000_000, 20_000_000), _pose(angle, x), atol=1e-12)
    assert buf.at(110_000_000, 20_000_000) is None  # 26 ms beyond the last state
    assert buf.at(-30_000_000, 20_000_000) is None
    assert len(buf) == 4 and buf.latest[0] == 84_000_000


def test_a_single_state_holds_within_reach():
    buf = RobotPoseBuffer()
    assert buf.at(0, 10) is None
    buf.add(5, _pose(0.2, 0.0))
    np.testing.assert_array_equal(buf.at(10, 10), _pose(0.2, 0.0))
    assert buf.at(20, 10) is None
