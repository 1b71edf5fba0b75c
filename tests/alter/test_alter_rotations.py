"""The ALTER wire's Z-Y-X angles: the messages and the gateway's safety convert them as
the plain scipy Rotation formulas of the convention do (and as a hand-built Rz Ry Rx)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.robot_gateway.links.alter import ControllerStatus, Correction, StatusBits
from humanpt.robot_gateway.links.alter.messages import NO_FLAGS
from humanpt.robot_gateway.links.alter.quantize import correction_angle_deg
from humanpt.robot_gateway.safety import wire_rotation_deg


def _rz_ry_rx(z_deg: float, y_deg: float, x_deg: float) -> np.ndarray:
    z, y, x = np.radians([z_deg, y_deg, x_deg])
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    return rz @ ry @ rx


def test_status_pose_round_trip_through_the_wire():
    rng = np.random.default_rng(4)
    for _ in range(200):
        ypr = np.round(rng.uniform([-179, -89, -179], [179, 89, 179]), 2)
        T = np.eye(4)
        T[:3, :3] = _rz_ry_rx(*ypr)
        T[:3, 3] = rng.uniform(-500, 500, 3).round(2)
        s = ControllerStatus.from_pose(3, StatusBits.ARM_POWER, T)
        np.testing.assert_allclose(s.ypr_deg, ypr, atol=1e-9)
        np.testing.assert_allclose(s.base_T_flange_mm(), T, atol=1e-12)


def test_wire_conversions_match_the_plain_scipy_formulas():
    rng = np.random.default_rng(5)
    for _ in range(300):
        c = Correction(
            1, NO_FLAGS, *rng.integers(-300, 300, 3).tolist(), *rng.integers(-170, 170, 3).tolist()
        )
        drx, dry, drz = c.rotation_deg
        dR = Rotation.from_euler("ZYX", [drz, dry, drx], degrees=True)
        np.testing.assert_allclose(c.delta_T_mm()[:3, :3], _rz_ry_rx(drz, dry, drx), atol=1e-14)
        assert correction_angle_deg(c) == pytest.approx(np.degrees(dR.magnitude()), abs=1e-12)
        s = ControllerStatus(
            7,
            StatusBits.ARM_POWER,
            1,
            2,
            3,
            *rng.integers([-18000, -9000, -18000], [18000, 9000, 18000]).tolist(),
        )
        np.testing.assert_allclose(s.base_T_flange_mm()[:3, :3], _rz_ry_rx(*s.ypr_deg), atol=1e-14)
        rv = rng.normal(size=3) * 0.01
        drz, dry, drx = Rotation.from_rotvec(rv).as_euler("ZYX", degrees=True)
        np.testing.assert_allclose(wire_rotation_deg(rv), [drx, dry, drz], atol=1e-12)
