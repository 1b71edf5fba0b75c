"""The fast kinematics give the very numbers of the plain per-branch numpy formulation.

The reference below is the straightforward implementation (one numpy expression per
formula, one branch at a time); PumaKinematics batches numpy calls and does scalar
arithmetic in plain floats for speed. Replays of recorded runs compare outputs byte for
byte, so the two must agree to the last bit, not approximately.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry.puma import (
    TWO_PI,
    PumaKinematics,
    PumaModel,
    RobotModelConfig,
    UnreachableError,
    dh_transform,
)


def _wrap(angle):
    a = (angle + np.pi) % TWO_PI - np.pi
    return np.pi if a == -np.pi else a


class Reference:
    """The plain formulation of forward, inverse_all and inverse."""

    def __init__(self, kin: PumaKinematics):
        self.kin, self.g, self.dh, self.limits = kin, kin.geometry, kin.dh, kin.limits_rad

    def forward(self, q):
        out = np.empty((7, 4, 4))
        out[0] = np.eye(4)
        for i, (link, theta) in enumerate(zip(self.dh, q, strict=True)):
            out[i + 1] = out[i] @ dh_transform(link, theta)
        return out[6]

    def fit(self, q, q_ref, tol=1e-9):
        out = np.empty(6)
        for j in range(6):
            lo, hi = self.limits[j]
            k_lo = np.ceil((lo - tol - q[j]) / TWO_PI)
            k_hi = np.floor((hi + tol - q[j]) / TWO_PI)
            if k_lo > k_hi:
                return None
            candidates = q[j] + TWO_PI * np.arange(k_lo, k_hi + 1)
            out[j] = candidates[np.argmin(np.abs(candidates - q_ref[j]))]
        return out

    def wrist(self, R, q1, q2, q3, q4_ref):
        R03 = np.eye(3)
        for link, theta in zip(self.dh[:3], (q1, q2, q3), strict=True):
            R03 = R03 @ dh_transform(link, theta)[:3, :3]
        M = R03.T @ R
        s5 = np.hypot(M[0, 2], M[1, 2])
        if s5 < PumaKinematics.WRIST_SINGULAR_SIN:
            if M[2, 2] > 0:
                q5, q6 = 0.0, np.arctan2(M[1, 0], M[0, 0]) - q4_ref
            else:
                q5, q6 = np.pi, np.arctan2(M[1, 0], M[1, 1]) + q4_ref
            return [((q4_ref, q5, q6), "noflip"), ((q4_ref + np.pi, -q5, q6 + np.pi), "flip")]
        q4 = np.arctan2(M[1, 2], M[0, 2])
        q5 = np.arctan2(s5, M[2, 2])
        q6 = np.arctan2(M[2, 1], -M[2, 0])
        return [((q4, q5, q6), "noflip"), ((q4 + np.pi, -q5, q6 + np.pi), "flip")]

    def inverse_all(self, T, q_ref):
        g = self.g
        R = T[:3, :3]
        px, py, pz = T[:3, 3] - g.d6_mm * R[:, 2]
        r2 = px * px + py * py - g.d2_mm**2
        if r2 < -1e-10 * max(1.0, g.d2_mm**2):
            return []
        r = np.sqrt(max(r2, 0.0))
        L3 = np.hypot(g.a3_mm, g.d4_mm)
        phi = np.arctan2(g.d4_mm, g.a3_mm)
        out = []
        for arm, x2 in (("lefty", r), ("righty", -r)):
            q1 = np.arctan2(py, px) - np.arctan2(g.d2_mm, x2)
            X, Y = x2, -pz
            D = (X * X + Y * Y - g.a2_mm**2 - L3**2) / (2.0 * g.a2_mm * L3)
            if abs(D) > 1.0 + 1e-10:
                continue
            D = float(np.clip(D, -1.0, 1.0))
            for beta in (np.arccos(D), -np.arccos(D)):
                q2 = np.arctan2(Y, X) - np.arctan2(L3 * np.sin(beta), g.a2_mm + L3 * np.cos(beta))
                e_h, e_z = g.a2_mm * np.cos(q2), -g.a2_mm * np.sin(q2)
                above = (x2 * e_z - pz * e_h) * (1.0 if x2 >= 0 else -1.0) > 0
                for wrist_q, wrist in self.wrist(R, q1, q2, phi + beta, q_ref[3]):
                    q = np.array([_wrap(v) for v in np.array([q1, q2, phi + beta, *wrist_q])])
                    fitted = self.fit(q, q_ref)
                    config = (arm, "above" if above else "below", wrist)
                    out.append((q if fitted is None else fitted, config, fitted is not None))
        return out

    def inverse(self, T, q_now):
        solutions = self.inverse_all(T, q_now)
        valid = [q for q, _, ok in solutions if ok]
        if not solutions or not valid:
            return None
        return min(valid, key=lambda q: float(np.linalg.norm(q - q_now)))


def _cases(kin: PumaKinematics, n: int, seed: int):
    """(pose, q_ref) pairs: poses of random joints, some with exact zeros or a singular
    wrist, some stepped by a wire-quantised correction as sim_robot does, some out of
    reach; q_ref near the joints or anywhere."""
    rng = np.random.default_rng(seed)
    lim = kin.limits_rad
    for t in range(n):
        kind = t % 5
        q = rng.uniform(lim[:, 0] - 0.2, lim[:, 1] + 0.2)
        if kind == 1:
            q[rng.integers(0, 6, size=2)] = 0.0
        elif kind == 2:
            q[4] = rng.choice([0.0, 1e-12, -1e-12, np.pi])
        T = kin.forward(q)
        if kind in (0, 3):
            dR = Rotation.from_euler("ZYX", rng.integers(-170, 170, 3) * 0.01, degrees=True)
            step = np.eye(4)
            step[:3, :3] = dR.as_matrix() @ T[:3, :3]
            step[:3, 3] = T[:3, 3] + rng.integers(-280, 280, 3) * 0.01
            T = step
        elif kind == 4:
            T[:3, 3] += rng.normal(size=3) * 800.0
        q_ref = q + rng.normal(size=6) * 0.05 if t % 2 else rng.uniform(lim[:, 0], lim[:, 1])
        yield q, T, q_ref


def _same(a, b) -> bool:
    return np.asarray(a).tobytes() == np.asarray(b).tobytes()


@pytest.mark.parametrize("model", [PumaModel.PUMA_762, PumaModel.PUMA_560])
def test_kinematics_bit_for_bit_as_the_plain_formulation(model):
    kin = PumaKinematics(RobotModelConfig(model=model))
    ref = Reference(kin)
    for q, T, q_ref in _cases(kin, 600, seed=1 if model == PumaModel.PUMA_762 else 2):
        assert _same(kin.forward(q), ref.forward(q))
        assert _same(kin.link_transforms(q)[6], ref.forward(q))
        expected = ref.inverse_all(T, q_ref)
        got = kin.inverse_all(T, q_ref)
        assert [(s.config, s.within_limits) for s in got] == [(c, ok) for _, c, ok in expected]
        assert all(_same(s.q_rad, e[0]) for s, e in zip(got, expected, strict=True))
        best = ref.inverse(T, q_ref)
        if best is None:
            with pytest.raises(UnreachableError):
                kin.inverse(T, q_ref)
        else:
            assert _same(kin.inverse(T, q_ref), best)
