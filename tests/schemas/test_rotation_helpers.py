"""The single-rotation helpers of convert give scipy Rotation's numbers bit for bit."""

import numpy as np
from scipy.spatial.transform import Rotation

from humanpt.schemas.convert import (
    matrix_from_rotvec,
    rotation_angle,
    rotvec_from_matrix,
    slerp_matrix,
)


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_rotation_helpers_match_scipy_bit_for_bit():
    rng = np.random.default_rng(0)
    for i in range(2000):
        T0, T1 = np.eye(4), np.eye(4)
        T0[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        T1[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        if i % 3 == 0:  # tiny rotations
            T0[:3, :3] = Rotation.from_rotvec(
                rng.normal(size=3) * 10.0 ** rng.integers(-12, 0)
            ).as_matrix()
        if i % 7 == 0:  # not quite orthonormal
            T0[:3, :3] += rng.normal(size=(3, 3)) * 1e-9
        R0, R1 = T0[:3, :3], T1[:3, :3]  # strided views, as on the hot paths
        rv = rng.normal(size=3) * 10.0 ** rng.integers(-12, 1)
        s = float(rng.uniform(-0.5, 1.5))
        assert _same(rotvec_from_matrix(R0), Rotation.from_matrix(R0).as_rotvec())
        assert _same(matrix_from_rotvec(rv), Rotation.from_rotvec(rv).as_matrix())
        assert _same(rotation_angle(R0), Rotation.from_matrix(R0).magnitude())
        r0, r1 = Rotation.from_matrix(R0), Rotation.from_matrix(R1)
        ref = (r0 * Rotation.from_rotvec(s * (r0.inv() * r1).as_rotvec())).as_matrix()
        assert _same(slerp_matrix(R0, R1, s), ref)
