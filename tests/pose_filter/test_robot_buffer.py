"""The robot pose at an image's stamp, as the pose filter looks it up in the cell's frame
graph (geometry.frames, policy ``segment_reach``): linear in translation and at a constant
angular rate between the two robot states around it (by hand: a turn about one fixed axis),
extrapolated from the last two by at most the allowed time, None beyond; the camera is the
hand-eye transform on from the flange."""

from __future__ import annotations

import numpy as np

from humanpt.geometry.frames import TimedPoses, segment_reach
from humanpt.geometry.rig import Rig
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore


def _pose(angle_rad: float, x_m: float) -> np.ndarray:
    """A turn about the world axis (1, 1, 0)/sqrt(2), by Rodrigues' formula by hand."""
    k = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle_rad) * kx + (1 - np.cos(angle_rad)) * kx @ kx
    T[:3, 3] = [x_m, 0.2, 0.5]
    return T


def test_interpolates_and_extrapolates_at_constant_rates():
    buf = TimedPoses(64)
    for k in range(4):  # states every 28 ms turning 0.1 rad and moving 2 mm per state
        assert buf.add(28_000_000 * k, _pose(0.3 + 0.1 * k, 1.0 + 0.002 * k))
    assert not buf.add(28_000_000, _pose(9.0, 9.0))  # out of order: refused
    assert not buf.add(84_000_000, _pose(9.0, 9.0))  # a repeat: refused
    reach = segment_reach(20_000_000)
    for t_ms, (angle, x) in ((14, (0.35, 1.001)), (28, (0.4, 1.002)), (70, (0.55, 1.005)),
                             (84, (0.6, 1.006)), (98, (0.65, 1.007)), (-7, (0.275, 0.9995))):
        np.testing.assert_allclose(buf.at(t_ms * 1_000_000, reach), _pose(angle, x), atol=1e-12)
    assert buf.at(110_000_000, reach) is None  # 26 ms beyond the last state
    assert buf.at(-30_000_000, reach) is None
    assert len(buf) == 4 and buf.latest[0] == 84_000_000


def test_a_single_state_holds_within_reach():
    buf = TimedPoses(64)
    assert buf.at(0, segment_reach(10)) is None
    buf.add(5, _pose(0.2, 0.0))
    np.testing.assert_array_equal(buf.at(10, segment_reach(10)), _pose(0.2, 0.0))
    assert buf.at(20, segment_reach(10)) is None


def test_the_core_places_the_camera_from_the_flange_at_the_stamp():
    """world_T_camera at an image stamp halfway between two states: the interpolated flange
    (by hand) times the rig's hand-eye; None 61 ms past the last state (reach 60 ms)."""
    core = PoseFilterCore(PoseFilterConfig(max_extrapolation_ms=60.0), Rig())
    core.robot.add(0, _pose(0.3, 1.0))
    core.robot.add(28_000_000, _pose(0.4, 1.002))
    F = Rig().hand_eye.flange_T_camera_m()
    np.testing.assert_allclose(core.frames.lookup("world", "camera", 14_000_000), _pose(0.35, 1.001) @ F,
                               atol=1e-12)
    assert core.frames.lookup("world", "camera", 89_000_000) is None
    assert core.frames.lookup("world", "camera", 88_000_000) is not None
