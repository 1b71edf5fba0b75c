"""One kinematics core for any serial 6R arm from a standard DH table.

A model of a robot, not a simulator (product code: planning and the simulated robots use
it alike). Lengths in mm, angles in radians unless a name says ``_deg``.

DH convention: standard/distal (Paul 1981), link transform
``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, joint i rotating about z_{i-1}, with
``theta_i = q_i + theta_offset_i`` (the controller's joint angle q plus the table's offset:
zero for the Puma and the UR, ABB's axis 2 and 6 are offset). The base frame is DH frame
0, the flange DH frame 6.

:class:`ArmKinematics` gives, for any table, the forward kinematics, the geometric
Jacobian, joint limits (a joint that turns more than a circle takes the 2*pi-equivalent
closest to the current joints) and the wrist and elbow singularity measure
(:meth:`ArmKinematics.singularity`); its inverse is a damped-least-squares iteration
seeded by the current joints (the closest solution, as a controller tracking a continuous
path finds it). Two analytic solvers take the arms that have them:

* :class:`SphericalWristKinematics`: joints 4-6 meet in one point (a4 = a5 = d5 = a6 = 0,
  alpha4 = -alpha5 = +-90 deg, alpha6 = 0) and alpha1, alpha3 = +-90, alpha2 = 0: the
  wrist centre p - d6 z fixes joints 1-3 (two shoulders x two elbows), the wrist gives
  4-6 two ways. The ABB IRB 1600 here, and the Puma's table (whose own solver,
  :class:`humanpt.geometry.puma.PumaKinematics`, keeps its bit-exact arithmetic).
* :class:`UrKinematics`: Universal Robots' arms (three parallel axes 2-4), the closed form
  of Hawkins (2013), "Analytic inverse kinematics for the Universal Robots UR-5/UR-10
  arms": joint 1 from the wrist-2 centre, joint 5 from the flange's offset, joint 6 from
  the orientation, 2-4 a planar two-link problem. Up to 8 solutions.

Each picks, among its solutions within the joint limits, the one closest (Euclidean) to
the current joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi


class UnreachableError(ValueError):
    """No inverse-kinematics solution (out of reach, or none within the joint limits)."""


@dataclass(frozen=True)
class DhLink:
    """One row of a standard DH table (mm, rad)."""

    alpha_rad: float
    a_mm: float
    d_mm: float


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


@dataclass(frozen=True)
class Singularity:
    """How far an arm is from its singularities at some joints: ``wrist`` = |sin theta5|
    (0: joints 4 and 6 coaxial), ``elbow`` = |sin| of the angle between the upper arm and
    the forearm's line to the wrist (0: the arm stretched or folded, at the edge of its
    reach)."""

    wrist: float
    elbow: float

    @property
    def least(self) -> float:
        return min(self.wrist, self.elbow)


def wrap(angle: float) -> float:
    """Angle in (-pi, pi]."""
    a = (angle + np.pi) % TWO_PI - np.pi
    return np.pi if a == -np.pi else a


class ArmKinematics:
    """Forward, Jacobian, limits, singularities and a numeric inverse of a 6R arm.

    ``dh``: six :class:`DhLink`; ``limits_rad``: (6, 2) lower and upper joint limits;
    ``theta_offsets_rad``: (6,) DH theta minus joint angle (default zeros)."""

    # The damped least squares: damping (mm), a rotation's weight against a translation's
    # (mm per rad), the iteration's stop (mm, rad) and its bound.
    DLS_DAMPING = 1e-3
    DLS_ROTATION_MM = 200.0
    DLS_TOL_MM = 1e-9
    DLS_TOL_RAD = 1e-12
    DLS_MAX_ITER = 200
    # A step of one iteration is bounded (rad): far from the seed the linearisation lies.
    DLS_MAX_STEP_RAD = 0.2

    def __init__(self, dh, limits_rad, theta_offsets_rad=None) -> None:
        self.dh = tuple(dh)
        if len(self.dh) != 6:
            raise ValueError(f"a 6R arm needs 6 DH rows, got {len(self.dh)}")
        self.limits_rad = np.asarray(limits_rad, dtype=float).reshape(6, 2)
        offsets = np.zeros(6) if theta_offsets_rad is None else np.asarray(theta_offsets_rad, dtype=float)
        self.theta_offsets_rad = offsets.reshape(6)
        self._offsets = tuple(float(v) for v in self.theta_offsets_rad)
        self._has_offsets = any(self._offsets)
        self._limits = tuple((float(lo), float(hi)) for lo, hi in self.limits_rad)
        self._links = tuple(
            (float(np.cos(link.alpha_rad)), float(np.sin(link.alpha_rad)), link.a_mm, link.d_mm)
            for link in self.dh
        )
        # The elbow's angle: the forearm's line from joint 3 to the wrist centre makes this
        # angle with x_3's predecessor (see singularity).
        l3, l4 = self.dh[2], self.dh[3]
        self._elbow_phi = math.atan2(-math.sin(l3.alpha_rad) * l4.d_mm, l3.a_mm)

    # --- forward -------------------------------------------------------------------------

    def _thetas(self, q: list[float]) -> list[float]:
        if not self._has_offsets:
            return q
        return [v + o for v, o in zip(q, self._offsets, strict=True)]

    def _link_matrices(self, q: list[float]) -> list[list[list[float]]]:
        """dh_transform of links 1..6 at joints q (floats), as nested lists."""
        mats = []
        for (ca, sa, a, d), theta in zip(self._links, self._thetas(q), strict=True):
            ct, st = math.cos(theta), math.sin(theta)
            mats.append(
                [
                    [ct, -st * ca, st * sa, a * ct],
                    [st, ct * ca, -ct * sa, a * st],
                    [0.0, sa, ca, d],
                    [0.0, 0.0, 0.0, 1.0],
                ]
            )
        return mats

    def link_transforms(self, q_rad: np.ndarray) -> np.ndarray:
        """(7, 4, 4) base_T_link_i for i = 0..6 (i = 0 is the identity, 6 the flange)."""
        A = np.array(self._link_matrices(self._check_q(q_rad).tolist()))
        out = np.empty((7, 4, 4))
        out[0] = np.eye(4)
        for i in range(6):
            out[i + 1] = out[i] @ A[i]
        return out

    def forward(self, q_rad: np.ndarray) -> np.ndarray:
        """(4, 4) base_T_flange for joint angles q_rad (6,), translation in mm."""
        T = np.eye(4)
        for A in np.array(self._link_matrices(self._check_q(q_rad).tolist())):
            T = T @ A
        return T

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

    # --- singularities -------------------------------------------------------------------

    def singularity(self, q_rad: np.ndarray) -> Singularity:
        """The wrist and elbow singularity measure at q_rad (:class:`Singularity`)."""
        theta = np.asarray(self._thetas(self._check_q(q_rad).tolist()))
        return Singularity(wrist=abs(math.sin(theta[4])), elbow=abs(math.sin(theta[2] + self._elbow_phi)))

    # --- limits --------------------------------------------------------------------------

    def within_limits(self, q_rad: np.ndarray, tol_rad: float = 1e-9) -> bool:
        q = self._check_q(q_rad)
        lo, hi = self.limits_rad[:, 0], self.limits_rad[:, 1]
        return bool(np.all(q >= lo - tol_rad) and np.all(q <= hi + tol_rad))

    def limit_margin_rad(self, q_rad: np.ndarray) -> float:
        """The least distance (rad) of any joint from its nearer limit (< 0: outside)."""
        q = self._check_q(q_rad)
        return float(np.minimum(q - self.limits_rad[:, 0], self.limits_rad[:, 1] - q).min())

    def _fit_limits(
        self, q: list[float], q_ref: list[float], first: int = 0, tol_rad: float = 1e-9
    ) -> list[float] | None:
        """Per joint (joints first, first + 1, ... of q's length), the 2*pi-equivalent of
        q within the limits closest to q_ref (the first of equally close ones; None if
        some joint has none). Why: joints that turn more than a full circle."""
        out = []
        for (lo, hi), v, ref in zip(self._limits[first:], q, q_ref[first:], strict=False):
            k_lo = math.ceil((lo - tol_rad - v) / TWO_PI)
            k_hi = math.floor((hi + tol_rad - v) / TWO_PI)
            if k_lo > k_hi:
                return None
            best = v + TWO_PI * k_lo
            for k in range(k_lo + 1, k_hi + 1):
                candidate = v + TWO_PI * k
                if abs(candidate - ref) < abs(best - ref):
                    best = candidate
            out.append(best)
        return out

    # --- inverse -------------------------------------------------------------------------

    def solutions(self, base_T_flange: np.ndarray, q_ref_rad: np.ndarray) -> list[np.ndarray]:
        """Every analytic solution (joint angles, each wrapped to (-pi, pi]) reaching
        base_T_flange; None: this arm has no analytic solver (the numeric one serves)."""
        return None

    def inverse(self, base_T_flange: np.ndarray, q_current_rad: np.ndarray) -> np.ndarray:
        """(6,) the joint solution within limits closest to q_current_rad.

        Analytic solvers: every solution fitted into the limits, the closest (Euclidean)
        taken. Otherwise the damped least squares from q_current_rad. Raises
        UnreachableError when the pose is out of reach or no solution is within limits."""
        q_now = self._check_q(q_current_rad)
        T = self._check_T(base_T_flange)
        sols = self.solutions(T, q_now)
        if sols is None:
            return self.inverse_numeric(T, q_now)
        if not sols:
            raise UnreachableError(f"pose at {np.round(T[:3, 3], 3).tolist()} mm is out of reach")
        now = q_now.tolist()
        best, best_dist = None, math.inf
        for q in sols:
            fit = self._fit_limits(list(q), now)
            if fit is None:
                continue
            d = np.array(fit) - q_now
            dist = math.sqrt(d.dot(d))
            if dist < best_dist:
                best, best_dist = fit, dist
        if best is None:
            raise UnreachableError(f"none of the {len(sols)} inverse-kinematics solutions is within the joint limits")
        return np.array(best)

    def inverse_numeric(self, base_T_flange: np.ndarray, q_seed_rad: np.ndarray) -> np.ndarray:
        """(6,) joints reaching base_T_flange by damped least squares from q_seed_rad (the
        solution the seed's basin holds: the closest one for a seed near it), within the
        limits (2*pi-equivalents closest to the seed). UnreachableError when it does not
        converge or ends outside the limits."""
        T = self._check_T(base_T_flange)
        q = self._check_q(q_seed_rad).copy()
        w = self.DLS_ROTATION_MM
        lam2 = self.DLS_DAMPING**2
        for _ in range(self.DLS_MAX_ITER):
            F = self.forward(q)
            e_p = T[:3, 3] - F[:3, 3]
            e_r = _rotation_vector(T[:3, :3] @ F[:3, :3].T)
            if np.abs(e_p).max() < self.DLS_TOL_MM and np.abs(e_r).max() < self.DLS_TOL_RAD:
                break
            J = self.jacobian(q)
            J[3:] *= w
            e = np.r_[e_p, w * e_r]
            dq = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(6), e)
            step = np.abs(dq).max()
            if step > self.DLS_MAX_STEP_RAD:
                dq *= self.DLS_MAX_STEP_RAD / step
            q = q + dq
        else:
            raise UnreachableError(f"pose at {np.round(T[:3, 3], 3).tolist()} mm: the numeric inverse did not "
                                   f"converge in {self.DLS_MAX_ITER} iterations (out of reach or singular)")
        fit = self._fit_limits(q.tolist(), self._check_q(q_seed_rad).tolist())
        if fit is None:
            raise UnreachableError(f"the numeric inverse of the pose at {np.round(T[:3, 3], 3).tolist()} mm is "
                                   "outside the joint limits")
        return np.array(fit)

    @staticmethod
    def _check_q(q_rad: np.ndarray) -> np.ndarray:
        q = np.asarray(q_rad, dtype=float)
        if q.shape != (6,) or not np.isfinite(q).all():
            raise ValueError(f"joint angles must be a finite (6,) array, got {q_rad!r}")
        return q

    @staticmethod
    def _check_T(base_T_flange: np.ndarray) -> np.ndarray:
        T = np.asarray(base_T_flange, dtype=float)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise ValueError(f"base_T_flange must be a finite 4x4 array, got shape {T.shape}")
        return T


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """The rotation vector (rad) of a rotation matrix (scipy's, without importing it here)."""
    c = (np.trace(R) - 1.0) / 2.0
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = np.linalg.norm(v) / 2.0
    angle = math.atan2(s, min(max(c, -1.0), 1.0))
    if s > 1e-9:
        return v * (angle / (2.0 * s))
    if c > 0:
        return v / 2.0  # small angle: sin ~ angle
    # near pi: the axis from the symmetric part
    B = (R + np.eye(3)) / 2.0
    axis = B[:, int(np.argmax(np.diag(B)))]
    axis = axis / np.linalg.norm(axis)
    return axis * angle


class SphericalWristKinematics(ArmKinematics):
    """An arm with a spherical wrist (see the module docstring): analytic, up to 8."""

    WRIST_SINGULAR_SIN = 1e-10
    _REACH_EPS = 1e-10

    def __init__(self, dh, limits_rad, theta_offsets_rad=None) -> None:
        super().__init__(dh, limits_rad, theta_offsets_rad)
        l1, l2, l3, l4, l5, l6 = self.dh
        h = np.pi / 2
        ok = (abs(abs(l1.alpha_rad) - h) < 1e-12 and abs(l2.alpha_rad) < 1e-12 and abs(abs(l3.alpha_rad) - h) < 1e-12
              and abs(abs(l4.alpha_rad) - h) < 1e-12 and abs(l4.alpha_rad + l5.alpha_rad) < 1e-12
              and l4.a_mm == 0 and l5.a_mm == 0 and l5.d_mm == 0 and l6.a_mm == 0 and l6.alpha_rad == 0)
        if not ok:
            raise ValueError("not a spherical-wrist table (alpha1, alpha3 +-90, alpha2 0, alpha4 = -alpha5 = +-90, "
                             "a4 = a5 = d5 = a6 = alpha6 = 0)")
        self._sa1 = 1.0 if l1.alpha_rad > 0 else -1.0
        self._sigma = -1.0 if l4.alpha_rad > 0 else 1.0  # R36 = Rz(t4) Ry(sigma t5) Rz(t6)
        self._L3 = math.hypot(l3.a_mm, l4.d_mm)
        self._z2 = l2.d_mm + l3.d_mm  # the wrist centre's offset out of the arm plane (frame 1's z)

    def solutions(self, base_T_flange: np.ndarray, q_ref_rad: np.ndarray) -> list[np.ndarray]:
        T = base_T_flange
        l1, l2, _, _, _, l6 = self.dh
        p = T[:3, 3] - l6.d_mm * T[:3, 2]  # the wrist centre
        px, py, pz = (float(v) for v in p)
        v = -self._sa1 * self._z2
        rho2 = px * px + py * py - v * v
        if rho2 < -self._REACH_EPS * max(1.0, v * v):
            return []
        a2, L3, phi = l2.a_mm, self._L3, self._elbow_phi
        Y = (pz - l1.d_mm) / self._sa1
        off = self._offsets
        q4_ref = float(q_ref_rad[3]) + off[3]
        out = []
        for u in (math.sqrt(max(rho2, 0.0)), -math.sqrt(max(rho2, 0.0))):
            if u == 0.0 and out:
                continue  # on joint 1's axis: one shoulder
            t1 = math.atan2(py, px) - math.atan2(v, u)
            X = u - l1.a_mm
            D = (X * X + Y * Y - a2 * a2 - L3 * L3) / (2.0 * a2 * L3)
            if abs(D) > 1.0 + self._REACH_EPS:
                continue
            beta = math.acos(min(max(D, -1.0), 1.0))
            for b in (beta, -beta):
                t2 = math.atan2(Y, X) - math.atan2(L3 * math.sin(b), a2 + L3 * math.cos(b))
                t3 = b - phi
                R03 = np.eye(3)
                for k, t in enumerate((t1, t2, t3)):
                    R03 = R03 @ self._rot(k, t)
                M = R03.T @ T[:3, :3]
                for t4, t5, t6 in self._wrist(M, q4_ref):
                    theta = (t1, t2, t3, t4, t5, t6)
                    out.append(np.array([wrap(t - o) for t, o in zip(theta, off, strict=True)]))
        return out

    def _rot(self, i: int, theta: float) -> np.ndarray:
        ca, sa, _, _ = self._links[i]
        ct, st = math.cos(theta), math.sin(theta)
        return np.array([[ct, -st * ca, st * sa], [st, ct * ca, -ct * sa], [0.0, sa, ca]])

    def _wrist(self, M: np.ndarray, t4_ref: float) -> list[tuple[float, float, float]]:
        """thetas 4-6 with Rz(t4) Ry(sigma t5) Rz(t6) = M: both wrists (noflip, flip)."""
        sg = self._sigma
        sb = math.hypot(M[0, 2], M[1, 2])
        if sb < self.WRIST_SINGULAR_SIN:  # joints 4 and 6 coaxial: keep joint 4 where it is
            t4 = t4_ref
            if M[2, 2] > 0:
                b, t6 = 0.0, math.atan2(M[1, 0], M[0, 0]) - t4
            else:
                b, t6 = np.pi, t4 - math.atan2(-M[1, 0], M[1, 1])
        else:
            b = math.atan2(sb, M[2, 2])
            t4, t6 = math.atan2(M[1, 2], M[0, 2]), math.atan2(M[2, 1], -M[2, 0])
        return [(t4, sg * b, t6), (t4 + np.pi, -sg * b, t6 + np.pi)]


class UrKinematics(ArmKinematics):
    """Universal Robots' arms (alpha = pi/2, 0, 0, pi/2, -pi/2, 0; a2, a3, d1, d4, d5, d6):
    the closed form (module docstring), up to 8 solutions."""

    WRIST_SINGULAR_SIN = 1e-10
    _REACH_EPS = 1e-10

    def __init__(self, dh, limits_rad, theta_offsets_rad=None) -> None:
        super().__init__(dh, limits_rad, theta_offsets_rad)
        h = np.pi / 2
        alphas = tuple(link.alpha_rad for link in self.dh)
        want = (h, 0.0, 0.0, h, -h, 0.0)
        if any(abs(a - w) > 1e-12 for a, w in zip(alphas, want, strict=True)) or self._has_offsets:
            raise ValueError("not a UR table (alpha = 90, 0, 0, 90, -90, 0 deg, no theta offsets)")

    def solutions(self, base_T_flange: np.ndarray, q_ref_rad: np.ndarray) -> list[np.ndarray]:
        T = base_T_flange
        a2, a3 = self.dh[1].a_mm, self.dh[2].a_mm
        d4, d6 = self.dh[3].d_mm, self.dh[5].d_mm
        p5 = T[:3, 3] - d6 * T[:3, 2]  # joint 5's origin
        R = math.hypot(p5[0], p5[1])
        if R < abs(d4) * (1.0 - self._REACH_EPS):
            return []
        phi1 = math.atan2(p5[1], p5[0])
        phi2 = math.acos(min(1.0, d4 / R))
        out = []
        for t1 in (phi1 + phi2 + np.pi / 2, phi1 - phi2 + np.pi / 2):
            s1, c1 = math.sin(t1), math.cos(t1)
            c5 = (T[0, 3] * s1 - T[1, 3] * c1 - d4) / d6
            if abs(c5) > 1.0 + self._REACH_EPS:
                continue
            t5a = math.acos(min(max(c5, -1.0), 1.0))
            for t5 in (t5a, -t5a):
                s5 = math.sin(t5)
                if abs(s5) < self.WRIST_SINGULAR_SIN:
                    t6 = float(q_ref_rad[5])  # joints 2-4 and 6 parallel: keep joint 6
                else:
                    t6 = math.atan2((-T[0, 1] * s1 + T[1, 1] * c1) / s5, (T[0, 0] * s1 - T[1, 0] * c1) / s5)
                T01 = dh_transform(self.dh[0], t1)
                T45 = dh_transform(self.dh[4], t5)
                T56 = dh_transform(self.dh[5], t6)
                T14 = np.linalg.inv(T01) @ T @ np.linalg.inv(T45 @ T56)
                x, y = T14[0, 3], T14[1, 3]
                D = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
                if abs(D) > 1.0 + self._REACH_EPS:
                    continue
                t3a = math.acos(min(max(D, -1.0), 1.0))
                for t3 in (t3a, -t3a):
                    t2 = math.atan2(y, x) - math.atan2(a3 * math.sin(t3), a2 + a3 * math.cos(t3))
                    t4 = math.atan2(T14[1, 0], T14[0, 0]) - t2 - t3
                    out.append(np.array([wrap(t) for t in (t1, t2, t3, t4, t5, t6)]))
        return out
