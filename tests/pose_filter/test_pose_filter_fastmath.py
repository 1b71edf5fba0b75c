"""The filter's rotation helpers give scipy's numbers bit for bit, and the filter's F and Q
are the block products they replace."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from humanpt.pose_filter import fastmath
from humanpt.pose_filter.kalman import process_noise, transition
from humanpt.schemas import convert


def _same(a, b) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _rotations(rng, n):
    for k in range(n):
        R = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
        if k % 4 == 1:
            R = Rotation.from_rotvec(rng.normal(0, 1e-7, 3)).as_matrix()
        elif k % 4 == 2:  # near pi
            axis = rng.normal(size=3)
            R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * (np.pi - 1e-9)).as_matrix()
        elif k % 4 == 3:  # not quite orthonormal: scipy orthogonalises (SVD) first
            R = R + rng.normal(0, 1e-9, (3, 3))
        yield R


def test_rotation_vector_and_slerp_match_scipy():
    rng = np.random.default_rng(2)
    for R in _rotations(rng, 400):
        assert _same(fastmath.rotvec_of(R), convert.rotvec_from_matrix(R))
        R1 = R @ Rotation.from_rotvec(rng.normal(0, 0.05, 3)).as_matrix()
        for s in (0.0, float(rng.uniform()), 1.0):
            expected = Slerp([0.0, 1.0], Rotation.from_matrix([R, R1]))(s).as_matrix()
            assert _same(fastmath.slerp(R, R1, s), expected)


def test_matrix_of_a_rotation_vector_matches_scipy():
    rng = np.random.default_rng(3)
    for k in range(3000):
        v = rng.normal(0.0, [1e-9, 1e-4, 9e-4, 1e-3, 0.01, 0.3, 2.0, 10.0][k % 8], 3)
        if k % 8 == 3:
            v *= 1e-3 / np.linalg.norm(v)  # the series' edge
        assert _same(fastmath.matrix_of(v), convert.matrix_from_rotvec(v))
    for v in (np.zeros(3), np.array([np.nan, 0.0, 0.0]), np.array([np.inf, 0.0, 0.0])):
        assert _same(fastmath.matrix_of(v), convert.matrix_from_rotvec(v))


def test_transition_and_process_noise_are_the_block_products():
    I3 = np.eye(3)
    for dt in (0.033, 0.0, -0.02, 1e-9):
        F = np.eye(12)
        F[0:3, 6:9] = dt * I3
        F[3:6, 9:12] = dt * I3
        assert _same(transition(dt), F)
        Q = np.zeros((12, 12))
        for pos, vel, q in (
            (slice(0, 3), slice(6, 9), 0.1**2),
            (slice(3, 6), slice(9, 12), 0.2**2),
        ):
            Q[pos, pos] = q * abs(dt) ** 3 / 3 * I3
            Q[pos, vel] = q * abs(dt) ** 2 / 2 * I3
            Q[vel, pos] = q * abs(dt) ** 2 / 2 * I3
            Q[vel, vel] = q * abs(dt) * I3
        assert _same(process_noise(abs(dt), 0.1, 0.2), Q)
