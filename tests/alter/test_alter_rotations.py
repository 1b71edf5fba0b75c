"""humanpt.alter.rotations gives scipy's Rotation numbers bit for bit (and the cached wire
conversions of messages and the gateway's safety too)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.alter import ControllerStatus, Correction, StatusBits
from humanpt.alter.messages import NO_FLAGS
from humanpt.alter.rotations import (
    angle_from_euler_zyx_deg,
    euler_zyx_deg_from_matrix,
    euler_zyx_deg_from_rotvec,
    matrix_from_euler_zyx_deg,
)
from humanpt.alter_gateway.safety import correction_angle_deg, wire_rotation_deg


def _same(a, b) -> bool:
    return np.asarray(a, dtype=float).tobytes() == np.asarray(b, dtype=float).tobytes()


@pytest.mark.filterwarnings("ignore:Gimbal lock detected")
def test_euler_conversions_are_scipys_bit_for_bit():
    rng = np.random.default_rng(3)
    for i in range(2000):
        ypr = rng.uniform([-180, -90, -180], [180, 90, 180])
        if i % 4 == 0:
            ypr = np.round(ypr * 100) / 100  # wire values
        if i % 7 == 0:
            ypr[1] = rng.choice([90.0, -90.0, 0.0])  # gimbal lock, zeros
        R = Rotation.from_euler("ZYX", ypr, degrees=True).as_matrix()
        assert _same(matrix_from_euler_zyx_deg(ypr), R)
        assert _same(
            angle_from_euler_zyx_deg(ypr), Rotation.from_euler("ZYX", ypr, degrees=True).magnitude()
        )
        for M in (R, R[:, [0, 1, 2]] @ Rotation.from_rotvec(rng.normal(size=3)).as_matrix()):
            assert _same(
                euler_zyx_deg_from_matrix(M), Rotation.from_matrix(M).as_euler("ZYX", degrees=True)
            )
        rv = rng.normal(size=3) * (1e-4 if i % 3 == 0 else 1.0)
        assert _same(
            euler_zyx_deg_from_rotvec(rv), Rotation.from_rotvec(rv).as_euler("ZYX", degrees=True)
        )


def test_a_matrix_that_is_not_quite_a_rotation_gets_scipys_repair():
    rng = np.random.default_rng(4)
    for scale in (1e-12, 1e-9, 1e-3):
        M = Rotation.from_rotvec(rng.normal(size=3)).as_matrix() + rng.normal(size=(3, 3)) * scale
        assert _same(
            euler_zyx_deg_from_matrix(M), Rotation.from_matrix(M).as_euler("ZYX", degrees=True)
        )


def test_wire_conversions_match_the_plain_scipy_formulas():
    rng = np.random.default_rng(5)
    for _ in range(300):
        c = Correction(
            1, NO_FLAGS, *rng.integers(-300, 300, 3).tolist(), *rng.integers(-170, 170, 3).tolist()
        )
        drx, dry, drz = c.rotation_deg
        dR = Rotation.from_euler("ZYX", [drz, dry, drx], degrees=True)
        assert _same(c.delta_T_mm()[:3, :3], dR.as_matrix())
        assert _same(correction_angle_deg(c), np.degrees(dR.magnitude()))
        s = ControllerStatus(
            7,
            StatusBits.ARM_POWER,
            1,
            2,
            3,
            *rng.integers([-18000, -9000, -18000], [18000, 9000, 18000]).tolist(),
        )
        assert _same(
            s.base_T_flange_mm()[:3, :3],
            Rotation.from_euler("ZYX", s.ypr_deg, degrees=True).as_matrix(),
        )
        rv = rng.normal(size=3) * 0.01
        drz, dry, drx = Rotation.from_rotvec(rv).as_euler("ZYX", degrees=True)
        assert _same(wire_rotation_deg(rv), [drx, dry, drz])
