"""Puma kinematics: standard (classic Paul) DH, forward, analytic inverse, Jacobian.

Pure numpy. Lengths in mm, angles in radians unless a name says ``_deg``.

DH convention: standard/distal (Paul 1981; Fu, Gonzalez & Lee 1987, table 2.2), link
transform ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, joint i rotating about
z_{i-1}. The Puma table in this convention (the shoulder offset sits in d2):

    i | alpha_i | a_i | d_i
    1 |  -90 deg | 0   | 0
    2 |    0     | a2  | d2
    3 |  +90 deg | a3  | 0
    4 |  -90 deg | 0   | d4
    5 |  +90 deg | 0   | 0
    6 |    0     | 0   | d6

    Puma 761/762: d2 = 190, a2 = 650, a3 = 0,      d4 = 600,    d6 = 125
    Puma 560:     d2 = 149.09, a2 = 431.8, a3 = -20.32, d4 = 433.07, d6 = 56.25
                  (Fu/Gonzalez/Lee values; Corke's table is the same arm in another
                  sign convention, with the offset in d3 and a3 = +20.32)

The base frame is DH frame 0: origin where the joint-1 axis meets the shoulder (joint-2)
axis, z up. The flange frame is DH frame 6. Joint angles are the DH thetas (no VAL
offsets): q = 0 has the upper arm horizontal and the forearm pointing up; q = (0, -90,
90, 0, 0, 0) deg is the arm straight up.

Inverse kinematics: wrist centre p_w = p - d6 * z_flange fixes joints 1-3 (arm
lefty/righty x elbow above/below), the wrist (spherical) gives joints 4-6 two ways
(noflip/flip). Config names follow VAL and Lee's definitions: RIGHTY when a positive
joint-2 rotation (joint 3 still) raises the wrist; ABOVE when the elbow is above the
shoulder-wrist line; FLIP when joint 5 is negative.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

import numpy as np

TWO_PI = 2.0 * np.pi


class PumaModel(StrEnum):
    PUMA_762 = "puma762"  # the 761/762 family (the paper's Puma 761)
    PUMA_560 = "puma560"


@dataclass(frozen=True)
class DhLink:
    """One row of a standard DH table (mm, rad)."""

    alpha_rad: float
    a_mm: float
    d_mm: float


@dataclass(frozen=True)
class PumaGeometry:
    """The five lengths that define a Puma in the DH table above (mm)."""

    d2_mm: float
    a2_mm: float
    a3_mm: float
    d4_mm: float
    d6_mm: float

    def dh(self) -> tuple[DhLink, ...]:
        h = np.pi / 2
        return (
            DhLink(-h, 0.0, 0.0),
            DhLink(0.0, self.a2_mm, self.d2_mm),
            DhLink(h, self.a3_mm, 0.0),
            DhLink(-h, 0.0, self.d4_mm),
            DhLink(h, 0.0, 0.0),
            DhLink(0.0, 0.0, self.d6_mm),
        )


GEOMETRY = {
    PumaModel.PUMA_762: PumaGeometry(d2_mm=190.0, a2_mm=650.0, a3_mm=0.0, d4_mm=600.0, d6_mm=125.0),
    PumaModel.PUMA_560: PumaGeometry(
        d2_mm=149.09, a2_mm=431.8, a3_mm=-20.32, d4_mm=433.07, d6_mm=56.25
    ),
}

# Puma 560-like limits (Corke's mdl_puma560 qlim, mapped to this table's signs: joints 2
# and 3 turn the other way here). Assumed for the 761/762 as well; no verified 762 values.
PUMA_JOINT_LIMITS_DEG: tuple[tuple[float, float], ...] = (
    (-160.0, 160.0),
    (-225.0, 45.0),
    (-45.0, 225.0),
    (-110.0, 170.0),
    (-100.0, 100.0),
    (-266.0, 266.0),
)


class UnreachableError(ValueError):
    """No inverse-kinematics solution (out of reach, or none within the joint limits)."""


@dataclass(frozen=True)
class RobotModelConfig:
    """Which Puma and its joint limits ((lo, hi) deg per joint, in DH angles)."""

    model: PumaModel = PumaModel.PUMA_762
    joint_limits_deg: tuple[tuple[float, float], ...] = PUMA_JOINT_LIMITS_DEG

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "model", PumaModel(self.model))
        except ValueError:
            names = ", ".join(m.value for m in PumaModel)
            raise ValueError(f"unknown robot model {self.model!r}; choose one of {names}") from None
        limits = tuple(tuple(float(v) for v in pair) for pair in self.joint_limits_deg)
        if len(limits) != 6 or any(len(pair) != 2 for pair in limits):
            raise ValueError(
                f"joint_limits_deg needs 6 (lo, hi) pairs, got {self.joint_limits_deg!r}"
            )
        for i, (lo, hi) in enumerate(limits, start=1):
            if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
                raise ValueError(f"joint {i} limits must be finite with lo < hi, got ({lo}, {hi})")
            if hi - lo > 720.0:
                raise ValueError(f"joint {i} range {hi - lo} deg exceeds two turns")
        object.__setattr__(self, "joint_limits_deg", limits)

    @property
    def geometry(self) -> PumaGeometry:
        return GEOMETRY[self.model]

    @property
    def joint_limits_rad(self) -> np.ndarray:
        """(6, 2) lower and upper limits in radians."""
        return np.radians(np.array(self.joint_limits_deg))


@dataclass(frozen=True)
class IkSolution:
    """One inverse-kinematics branch. ``q_rad``: (6,) joint angles."""

    q_rad: np.ndarray
    arm: Literal["lefty", "righty"]
    elbow: Literal["above", "below"]
    wrist: Literal["noflip", "flip"]
    within_limits: bool

    @property
    def config(self) -> tuple[str, str, str]:
        return (self.arm, self.elbow, self.wrist)


def dh_transform(link: DhLink, theta_rad: float) -> np.ndarray:
    """(4, 4) A_i = Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    ct, st = np.cos(theta_rad), np.sin(theta_rad)
    ca, sa = np.cos(link.alpha_rad), np.sin(link.alpha_rad)
    return np.array(
        [
            [ct, -st * ca, st * sa, link.a_mm * ct],
            [st, ct * ca, -ct * sa, link.a_mm * st],
            [0.0, sa, ca, link.d_mm],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _wrap(angle: float) -> float:
    """Angle in (-pi, pi]."""
    a = (angle + np.pi) % TWO_PI - np.pi
    return np.pi if a == -np.pi else a


class PumaKinematics:
    """Forward and inverse kinematics of one Puma model."""

    # Below this |sin q5| the wrist is singular: only q4 + q6 (or q6 - q4) is defined.
    WRIST_SINGULAR_SIN = 1e-10
    # Reach tolerance: a pose this close (mm^2-relative) outside the workspace still solves.
    _REACH_EPS = 1e-10

    def __init__(self, config: RobotModelConfig | None = None) -> None:
        self.config = config or RobotModelConfig()
        self.geometry = self.config.geometry
        self.dh = self.geometry.dh()
        self.limits_rad = self.config.joint_limits_rad

    # --- forward -------------------------------------------------------------------------

    def link_transforms(self, q_rad: np.ndarray) -> np.ndarray:
        """(7, 4, 4) base_T_link_i for i = 0..6 (i = 0 is the identity, 6 the flange)."""
        q = self._check_q(q_rad)
        out = np.empty((7, 4, 4))
        out[0] = np.eye(4)
        for i, (link, theta) in enumerate(zip(self.dh, q, strict=True)):
            out[i + 1] = out[i] @ dh_transform(link, theta)
        return out

    def forward(self, q_rad: np.ndarray) -> np.ndarray:
        """(4, 4) base_T_flange for joint angles q_rad (6,), translation in mm."""
        return self.link_transforms(q_rad)[6]

    def jacobian(self, q_rad: np.ndarray) -> np.ndarray:
        """(6, 6) geometric Jacobian in the base frame: rows vx, vy, vz [mm/rad] of the
        flange origin, then wx, wy, wz [rad/rad]; column j is joint j."""
        T = self.link_transforms(q_rad)
        p_e = T[6, :3, 3]
        J = np.empty((6, 6))
        for j in range(6):
            z = T[j, :3, 2]
            J[:3, j] = np.cross(z, p_e - T[j, :3, 3])
            J[3:, j] = z
        return J

    # --- limits --------------------------------------------------------------------------

    def within_limits(self, q_rad: np.ndarray, tol_rad: float = 1e-9) -> bool:
        q = self._check_q(q_rad)
        lo, hi = self.limits_rad[:, 0], self.limits_rad[:, 1]
        return bool(np.all(q >= lo - tol_rad) and np.all(q <= hi + tol_rad))

    def _fit_limits(
        self, q: np.ndarray, q_ref: np.ndarray, tol_rad: float = 1e-9
    ) -> np.ndarray | None:
        """Per joint, the 2*pi-equivalent of q within the limits closest to q_ref (None if
        some joint has none). Why: joints 4 and 6 turn more than a full circle."""
        out = np.empty(6)
        for j in range(6):
            lo, hi = self.limits_rad[j]
            k_lo = np.ceil((lo - tol_rad - q[j]) / TWO_PI)
            k_hi = np.floor((hi + tol_rad - q[j]) / TWO_PI)
            if k_lo > k_hi:
                return None
            candidates = q[j] + TWO_PI * np.arange(k_lo, k_hi + 1)
            out[j] = candidates[np.argmin(np.abs(candidates - q_ref[j]))]
        return out

    # --- inverse -------------------------------------------------------------------------

    def inverse_all(
        self, base_T_flange: np.ndarray, q_ref_rad: np.ndarray | None = None
    ) -> list[IkSolution]:
        """Every analytic branch reaching base_T_flange (4x4, mm): up to 8.

        ``q_ref_rad`` (6,) picks, per joint, the 2*pi-equivalent inside the limits closest
        to it, and the free q4 at a wrist singularity. Branches outside the limits are
        returned with ``within_limits=False`` (angles wrapped to (-pi, pi]). Returns [] when
        the pose is out of reach.
        """
        T = np.asarray(base_T_flange, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"base_T_flange must be a finite 4x4 array, got shape {T.shape}")
        q_ref = np.zeros(6) if q_ref_rad is None else self._check_q(q_ref_rad)
        g = self.geometry
        R = T[:3, :3]
        p_w = T[:3, 3] - g.d6_mm * R[:, 2]  # wrist centre
        px, py, pz = p_w
        r2 = px * px + py * py - g.d2_mm**2
        if r2 < -self._REACH_EPS * max(1.0, g.d2_mm**2):
            return []  # wrist centre inside the shoulder-offset cylinder
        r = np.sqrt(max(r2, 0.0))
        L3 = np.hypot(g.a3_mm, g.d4_mm)  # elbow -> wrist centre
        phi = np.arctan2(g.d4_mm, g.a3_mm)
        solutions = []
        for arm, x2 in (("lefty", r), ("righty", -r)):
            q1 = np.arctan2(py, px) - np.arctan2(g.d2_mm, x2)
            X, Y = x2, -pz  # the wrist centre in the arm plane (frame-1 x, -z)
            D = (X * X + Y * Y - g.a2_mm**2 - L3**2) / (2.0 * g.a2_mm * L3)
            if abs(D) > 1.0 + self._REACH_EPS:
                continue
            D = float(np.clip(D, -1.0, 1.0))
            for beta in (np.arccos(D), -np.arccos(D)):
                q2 = np.arctan2(Y, X) - np.arctan2(L3 * np.sin(beta), g.a2_mm + L3 * np.cos(beta))
                q3 = phi + beta
                elbow = self._elbow_label(q2, x2, pz)
                for wrist_q, wrist in self._wrist(R, q1, q2, q3, q_ref[3]):
                    q = np.array([q1, q2, q3, *wrist_q])
                    q = np.array([_wrap(v) for v in q])
                    fitted = self._fit_limits(q, q_ref)
                    solutions.append(
                        IkSolution(
                            q_rad=q if fitted is None else fitted,
                            arm=arm,
                            elbow=elbow,
                            wrist=wrist,
                            within_limits=fitted is not None,
                        )
                    )
        return solutions

    def inverse(self, base_T_flange: np.ndarray, q_current_rad: np.ndarray) -> np.ndarray:
        """(6,) the joint solution within limits closest (Euclidean) to q_current_rad.

        Raises UnreachableError when the pose is out of reach or no branch is in limits.
        """
        q_now = self._check_q(q_current_rad)
        solutions = self.inverse_all(base_T_flange, q_now)
        if not solutions:
            p = np.asarray(base_T_flange, dtype=float)[:3, 3]
            raise UnreachableError(f"pose at {np.round(p, 3).tolist()} mm is out of reach")
        valid = [s for s in solutions if s.within_limits]
        if not valid:
            configs = ", ".join("/".join(s.config) for s in solutions)
            raise UnreachableError(
                f"no inverse-kinematics branch within the joint limits (tried {configs})"
            )
        best = min(valid, key=lambda s: float(np.linalg.norm(s.q_rad - q_now)))
        return best.q_rad.copy()

    def _wrist(self, R: np.ndarray, q1: float, q2: float, q3: float, q4_ref: float):
        """Joints 4-6 from R36 = Rz(q4) Ry(q5) Rz(q6) (what alpha4 = -90, alpha5 = +90 give)."""
        R03 = np.eye(3)
        for link, theta in zip(self.dh[:3], (q1, q2, q3), strict=True):
            R03 = R03 @ dh_transform(link, theta)[:3, :3]
        M = R03.T @ R
        s5 = np.hypot(M[0, 2], M[1, 2])
        if s5 < self.WRIST_SINGULAR_SIN:
            # Joints 4 and 6 are coaxial: keep q4 where it is, q6 takes the rest.
            if M[2, 2] > 0:  # q5 = 0: R36 = Rz(q4 + q6)
                q5 = 0.0
                q6 = np.arctan2(M[1, 0], M[0, 0]) - q4_ref
            else:  # q5 = pi: R36 = Ry(pi) Rz(q6 - q4)
                q5 = np.pi
                q6 = np.arctan2(M[1, 0], M[1, 1]) + q4_ref
            yield (q4_ref, q5, q6), "noflip"
            yield (q4_ref + np.pi, -q5, q6 + np.pi), "flip"
            return
        q4 = np.arctan2(M[1, 2], M[0, 2])
        q5 = np.arctan2(s5, M[2, 2])
        q6 = np.arctan2(M[2, 1], -M[2, 0])
        yield (q4, q5, q6), "noflip"
        yield (q4 + np.pi, -q5, q6 + np.pi), "flip"

    def _elbow_label(self, q2: float, x2: float, pz: float) -> Literal["above", "below"]:
        """ABOVE when the elbow lies above the shoulder -> wrist-centre line."""
        g = self.geometry
        e_h, e_z = g.a2_mm * np.cos(q2), -g.a2_mm * np.sin(q2)  # elbow in the arm plane
        cross = x2 * e_z - pz * e_h
        side = 1.0 if x2 >= 0 else -1.0
        return "above" if cross * side > 0 else "below"

    @staticmethod
    def _check_q(q_rad: np.ndarray) -> np.ndarray:
        q = np.asarray(q_rad, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ValueError(f"joint angles must be a finite (6,) array, got {q_rad!r}")
        return q
