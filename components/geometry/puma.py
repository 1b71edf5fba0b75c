"""Puma kinematics: standard (classic Paul) DH, forward, analytic inverse, Jacobian.

A model of the robot, not a simulator: the product plans with it (hand-eye poses a Puma can
reach, :func:`humanpt.calibration.handeye.puma_move_check`) and the simulated Puma
(:mod:`humanpt.sim_robot`) moves with it. (Until issue 30 it was ``humanpt.sim_robot.kinematics``.)

numpy and plain floats (the same numbers, see below). Lengths in mm, angles in radians
unless a name says ``_deg``.

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

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

import numpy as np

from humanpt.geometry.arm import TWO_PI, ArmKinematics, DhLink, UnreachableError, dh_transform
from humanpt.geometry.arm import wrap as _wrap

__all__ = ["DhLink", "GEOMETRY", "HOME_JOINTS_DEG", "IkSolution", "PUMA_JOINT_LIMITS_DEG", "PumaGeometry",
           "PumaKinematics", "PumaModel", "RobotModelConfig", "TWO_PI", "TrueArm", "UnreachableError",
           "dh_transform", "follow", "perturbed_geometry", "wrist_sin"]


class PumaModel(StrEnum):
    PUMA_762 = "puma762"  # the 761/762 family (the paper's Puma 761)
    PUMA_560 = "puma560"


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

# Flange straight down in front of the robot, elbow up: (786.0, 190.0, -296.0) mm in the
# base frame, yaw 0, pitch 0, roll 180 deg (puma762). Well inside every joint limit and
# away from the wrist singularity (q5 = 25 deg). The simulated Puma starts here; a planner
# takes it as the reference branch of the first inverse kinematics.
HOME_JOINTS_DEG = (0.0, -35.0, 190.0, 0.0, 25.0, -180.0)

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


_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


def _sum_sq(q: list[float], ref: list[float], start: float) -> float:
    """start + the squared differences q - ref, added one by one."""
    s = start
    for a, b in zip(q, ref, strict=False):
        s += (a - b) * (a - b)
    return s


def _near(sq: float) -> float:
    """Sums of squares above this cannot be the smallest if ``sq`` is (a margin far above
    the rounding differences between ways of summing six squares)."""
    return sq * (1.0 + 1e-9) + 1e-300


# Why the hot paths below mix plain floats and numpy: the simulated controller solves IK
# every 28 ms cycle, and numpy's cost per call on 3-vectors dwarfs the arithmetic. Plain
# float arithmetic (+ - * /, %, abs, sqrt, sin, cos, ceil, floor) gives the very numbers
# numpy's element-wise ufuncs give, so scalars use it. Matrix products stay numpy matmuls
# (BLAS fuses multiply-adds, which plain Python cannot reproduce) and arctan2, arccos,
# hypot stay numpy ufuncs (numpy's SIMD versions may differ from libm's in the last bit),
# several values per call where the inputs allow. tests/sim_robot check the results bit
# for bit against the plain per-branch numpy formulation.


class PumaKinematics(ArmKinematics):
    """Forward and inverse kinematics of one Puma model: the arm core's forward, Jacobian,
    limits and singularity measure (:class:`humanpt.geometry.arm.ArmKinematics`) with the
    Puma's own analytic inverse (its branches named as VAL names them, its arithmetic kept
    bit for bit: the golden recordings depend on it)."""

    # Below this |sin q5| the wrist is singular: only q4 + q6 (or q6 - q4) is defined.
    WRIST_SINGULAR_SIN = 1e-10
    # Reach tolerance: a pose this close (mm^2-relative) outside the workspace still solves.
    _REACH_EPS = 1e-10

    def __init__(self, config: RobotModelConfig | None = None) -> None:
        self.config = config or RobotModelConfig()
        self.geometry = self.config.geometry
        super().__init__(self.geometry.dh(), self.config.joint_limits_rad)
        # Per-model constants of the hot paths (each the value the formula would compute).
        g = self.geometry
        L3 = np.hypot(g.a3_mm, g.d4_mm)
        self._L3 = float(L3)  # elbow -> wrist centre
        self._phi = float(np.arctan2(g.d4_mm, g.a3_mm))
        self._a2_sq, self._L3_sq = g.a2_mm**2, float(L3**2)
        self._cos_den = float(2.0 * g.a2_mm * L3)  # law of cosines at the elbow

    def _rotation(self, i: int, theta: float) -> list[list[float]]:
        """The rotation part of link i's dh_transform at theta."""
        ca, sa, _, _ = self._links[i]
        ct, st = math.cos(theta), math.sin(theta)
        return [[ct, -st * ca, st * sa], [st, ct * ca, -ct * sa], [0.0, sa, ca]]

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
        T = self._check_T(base_T_flange)
        q_ref = [0.0] * 6 if q_ref_rad is None else self._check_q(q_ref_rad).tolist()
        return [
            IkSolution(
                q_rad=np.array(q if fitted is None else fitted),
                arm=arm,
                elbow=elbow,
                wrist=wrist,
                within_limits=fitted is not None,
            )
            for q, arm, elbow, wrist, fitted in self._branches(T, q_ref)
        ]

    def inverse(self, base_T_flange: np.ndarray, q_current_rad: np.ndarray) -> np.ndarray:
        """(6,) the joint solution within limits closest (Euclidean) to q_current_rad (the
        first of equally close ones in inverse_all's order).

        Raises UnreachableError when the pose is out of reach or no branch is in limits.
        """
        q_now = self._check_q(q_current_rad)
        T = self._check_T(base_T_flange)
        legs = self._legs(T)
        if not legs:
            raise UnreachableError(f"pose at {np.round(T[:3, 3], 3).tolist()} mm is out of reach")
        now = q_now.tolist()
        # Why not every branch: joints 1-3 alone put most legs (arm x elbow) far from the
        # current joints; once a branch is found, legs whose joints 1-3 are already farther
        # cannot hold the closest and their wrists are not solved. ``sq``: plain float
        # sums of squared joint differences, joint by joint (never decreasing).
        arm_fits = []  # (sum of squares over joints 1-3, leg index, joints 1-3)
        for i, (_, _, q1, q2, q3) in enumerate(legs):
            fit = self._fit_limits([_wrap(q1), _wrap(q2), _wrap(q3)], now)
            if fit is not None:
                arm_fits.append((_sum_sq(fit, now, 0.0), i, fit))
        arm_fits.sort(key=lambda a: a[0])
        found = []  # (branch index, fitted q, sum of squares)
        best_sq = math.inf
        for sq, i, fit in arm_fits:
            if sq > _near(best_sq):
                break
            (wrists,) = self._wrists([legs[i]], T[:3, :3], now[3])
            for w, ((q4, q5, q6), _) in enumerate(wrists):
                wrist_fit = self._fit_limits([_wrap(q4), _wrap(q5), _wrap(q6)], now, 3)
                if wrist_fit is not None:
                    found.append((2 * i + w, fit + wrist_fit, _sum_sq(wrist_fit, now[3:], sq)))
                    best_sq = min(best_sq, found[-1][2])
        if not found:
            configs = ", ".join(
                f"{arm}/{elbow}/{wrist}" for arm, elbow, *_ in legs for wrist in ("noflip", "flip")
            )
            raise UnreachableError(
                f"no inverse-kinematics branch within the joint limits (tried {configs})"
            )
        found.sort(key=lambda f: f[0])
        # The closest by np.linalg.norm(q - q_now) (a dot product with fused multiply-adds,
        # so the plain sums of squares may differ from it in the last bits: they only rule
        # out the candidates clearly farther than the closest).
        cut = _near(min(f[2] for f in found))
        best, best_dist = None, math.inf
        for _, q, sq in found:
            if sq <= cut:
                d = np.array(q) - q_now
                dist = math.sqrt(d.dot(d))
                if dist < best_dist:
                    best, best_dist = q, dist
        return np.array(best)

    def _branches(
        self, T: np.ndarray, q_ref: list[float]
    ) -> list[tuple[list[float], str, str, str, list[float] | None]]:
        """The analytic branches reaching T, in the order lefty/righty, elbow angle
        +beta/-beta, noflip/flip: (q wrapped to (-pi, pi], arm, elbow, wrist, q fitted
        into the limits or None)."""
        legs = self._legs(T)
        out = []
        for (arm, elbow, q1, q2, q3), wrists in zip(
            legs, self._wrists(legs, T[:3, :3], q_ref[3]) if legs else (), strict=True
        ):
            arm_q = [_wrap(q1), _wrap(q2), _wrap(q3)]
            arm_fit = self._fit_limits(arm_q, q_ref)  # joints 1-3: the same for both wrists
            for (q4, q5, q6), wrist in wrists:
                wrist_q = [_wrap(q4), _wrap(q5), _wrap(q6)]
                wrist_fit = None if arm_fit is None else self._fit_limits(wrist_q, q_ref, 3)
                fitted = None if wrist_fit is None else arm_fit + wrist_fit
                out.append((arm_q + wrist_q, arm, elbow, wrist, fitted))
        return out

    def _legs(self, T: np.ndarray) -> list[tuple[str, str, float, float, float]]:
        """Joints 1-3 reaching T's wrist centre: (arm, elbow, q1, q2, q3) for lefty and
        righty, each with elbow angle +beta and -beta (unwrapped); [] when out of reach."""
        g = self.geometry
        d2, a2, L3 = g.d2_mm, g.a2_mm, self._L3
        (_, _, r02, x), (_, _, r12, y), (_, _, r22, z), _ = T.tolist()
        px, py, pz = x - g.d6_mm * r02, y - g.d6_mm * r12, z - g.d6_mm * r22  # wrist centre
        r2 = px * px + py * py - d2**2
        if r2 < -self._REACH_EPS * max(1.0, d2**2):
            return []  # wrist centre inside the shoulder-offset cylinder
        r = math.sqrt(max(r2, 0.0))
        # In the arm plane (frame-1 x, -z) the wrist centre is at X, Y = +-r, -pz: both arms
        # have it at the same distance from the shoulder, hence the same elbow angles.
        D = (r * r + pz * pz - self._a2_sq - self._L3_sq) / self._cos_den
        if abs(D) > 1.0 + self._REACH_EPS:
            return []
        beta = float(np.arccos(min(max(D, -1.0), 1.0)))
        betas = (beta, -beta)
        # One arctan2 call: atan2(py, px), per arm atan2(d2, X) and atan2(Y, X), per elbow
        # angle the elbow's offset angle.
        at = np.arctan2(
            [py, d2, d2, -pz, -pz, L3 * math.sin(beta), L3 * math.sin(-beta)],
            [px, r, -r, r, -r, a2 + L3 * math.cos(beta), a2 + L3 * math.cos(-beta)],
        ).tolist()
        legs = []
        for i, (arm, x2) in enumerate((("lefty", r), ("righty", -r))):
            q1 = at[0] - at[1 + i]
            for j, b in enumerate(betas):
                q2 = at[3 + i] - at[5 + j]
                legs.append((arm, self._elbow_label(q2, x2, pz), q1, q2, self._phi + b))
        return legs

    def _wrists(self, legs: list, R: np.ndarray, q4_ref: float) -> list[tuple]:
        """Per leg, joints 4-6 (unwrapped) of its noflip and flip wrists reaching the
        rotation R: ((q4, q5, q6), "noflip"), ((q4', q5', q6'), "flip").

        From R36 = R03^T R = Rz(q4) Ry(q5) Rz(q6) (what alpha4 = -90, alpha5 = +90 give);
        the legs share the hypot and arctan2 calls."""
        Ms = []
        for leg in legs:
            A = np.array([self._rotation(k, leg[2 + k]) for k in range(3)])
            R03 = _EYE3 @ A[0] @ A[1] @ A[2]
            Ms.append((R03.T @ R).tolist())
        s5 = np.hypot([M[0][2] for M in Ms], [M[1][2] for M in Ms]).tolist()
        w = np.arctan2(
            [M[1][2] for M in Ms] + s5 + [M[2][1] for M in Ms],
            [M[0][2] for M in Ms] + [M[2][2] for M in Ms] + [-M[2][0] for M in Ms],
        ).tolist()
        n = len(legs)
        out = []
        for i, M in enumerate(Ms):
            if s5[i] < self.WRIST_SINGULAR_SIN:
                out.append(self._singular_wrist(M, q4_ref))
            else:
                q4, q5, q6 = w[i], w[n + i], w[2 * n + i]
                out.append((((q4, q5, q6), "noflip"), ((q4 + np.pi, -q5, q6 + np.pi), "flip")))
        return out

    @staticmethod
    def _singular_wrist(M: list[list[float]], q4_ref: float):
        """Joints 4-6 at a wrist singularity (joints 4 and 6 coaxial): keep q4 where it
        is, q6 takes the rest."""
        if M[2][2] > 0:  # q5 = 0: R36 = Rz(q4 + q6)
            q5 = 0.0
            q6 = float(np.arctan2(M[1][0], M[0][0])) - q4_ref
        else:  # q5 = pi: R36 = Ry(pi) Rz(q6 - q4)
            q5 = np.pi
            q6 = float(np.arctan2(M[1][0], M[1][1])) + q4_ref
        return (((q4_ref, q5, q6), "noflip"), ((q4_ref + np.pi, -q5, q6 + np.pi), "flip"))

    def _elbow_label(self, q2: float, x2: float, pz: float) -> Literal["above", "below"]:
        """ABOVE when the elbow lies above the shoulder -> wrist-centre line."""
        a2 = self.geometry.a2_mm
        e_h, e_z = a2 * math.cos(q2), -a2 * math.sin(q2)  # elbow in the arm plane
        cross = x2 * e_z - pz * e_h
        side = 1.0 if x2 >= 0 else -1.0
        return "above" if cross * side > 0 else "below"

# --------------------------------------------------------------------------- the true arm


def perturbed_geometry(geometry: PumaGeometry, length_errors_mm) -> PumaGeometry:
    """``geometry`` with each length (d2, a2, a3, d4, d6, mm) off by ``length_errors_mm``
    (5,): a real arm's links as built, against the nominal table."""
    e = [float(v) for v in length_errors_mm]
    if len(e) != 5:
        raise ValueError(f"length errors need 5 values (d2, a2, a3, d4, d6 mm), got {len(e)}")
    g = geometry
    return PumaGeometry(d2_mm=g.d2_mm + e[0], a2_mm=g.a2_mm + e[1], a3_mm=g.a3_mm + e[2],
                        d4_mm=g.d4_mm + e[3], d6_mm=g.d6_mm + e[4])


class TrueArm:
    """Forward kinematics of the physical arm that a nominal model (:class:`PumaKinematics`,
    any :class:`~humanpt.geometry.arm.ArmKinematics`) only approximates: DH lengths
    ``geometry`` (mm: a :class:`PumaGeometry`, or any arm's six :class:`DhLink` rows) and a
    zero offset per joint (``joint_offsets_rad`` (6,): the true DH angle is the encoder's
    angle plus the offset, plus the table's own ``theta_offsets_rad`` where it has them).
    ``forward(q)`` is where the flange really is when the encoders read ``q``."""

    def __init__(self, geometry, joint_offsets_rad, theta_offsets_rad=None) -> None:
        self.dh = geometry.dh() if hasattr(geometry, "dh") else tuple(geometry)
        self.joint_offsets_rad = np.asarray(joint_offsets_rad, dtype=float).reshape(6)
        if theta_offsets_rad is not None:
            self.joint_offsets_rad = self.joint_offsets_rad + np.asarray(theta_offsets_rad, dtype=float).reshape(6)

    def forward(self, q_rad: np.ndarray) -> np.ndarray:
        """(4, 4) the true base_T_flange (mm) at encoder angles ``q_rad`` (6,)."""
        T = np.eye(4)
        for link, theta in zip(self.dh, np.asarray(q_rad, dtype=float) + self.joint_offsets_rad, strict=True):
            T = T @ dh_transform(link, float(theta))
        return T


def follow(kin: ArmKinematics, base_T_flange_mm: np.ndarray, q_start_rad: np.ndarray) -> np.ndarray:
    """(N, 6) joints (rad) a controller reaches when it takes the flange through the poses
    ``base_T_flange_mm`` (N, 4, 4) one after the other, each on the in-limits branch closest
    to the joints before (as a Puma applies ALTER corrections; any arm's kinematics), from ``q_start_rad`` (6,).
    Raises UnreachableError naming the first pose out of reach (``pose i of N ...``)."""
    T = np.asarray(base_T_flange_mm, dtype=float).reshape(-1, 4, 4)
    out = np.zeros((len(T), 6))
    q = np.asarray(q_start_rad, dtype=float)
    for i, t in enumerate(T):
        try:
            q = kin.inverse(t, q)
        except UnreachableError as e:
            raise UnreachableError(f"pose {i} of {len(T)}: {e}") from None
        out[i] = q
    return out


def wrist_sin(q_rad: np.ndarray) -> np.ndarray:
    """sin q5 of joints (..., 6): 0 at the wrist singularity (joints 4 and 6 coaxial); its
    sign says which of the two wrists (noflip/flip) the arm is on."""
    return np.sin(np.asarray(q_rad, dtype=float)[..., 4])
