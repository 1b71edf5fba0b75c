"""Constant-velocity Kalman filter of a rigid pose (filterpy's KalmanFilter).

State (12,), world frame, SI units::

    x = [p (3, m), r (3, rad), v (3, m/s), w (3, rad/s)]

The orientation is ``R = exp(r) @ R_ref``: ``r`` is a small rotation vector (world frame)
relative to a reference rotation that is re-centred after every update (a multiplicative
error state), so there is no Euler singularity and every rotation innovation is a
rotation vector of ``R_meas @ R_pred.T``, wrapped into (-pi, pi] by construction.

F, H and Q are built by hand (filterpy's ``kinematic_kf`` builds a wrong H): F is the
constant-velocity transition, Q the discrete white-noise-acceleration model; filterpy's
``KalmanFilter.predict``/``update`` (Joseph form) do the rest.

A still target (see the core) is averaged by a copy of the filter that gets
zero-velocity pseudo-measurements and a process noise scaled by ``q_scale``.

:class:`PoseIMM` follows manoeuvres: an interacting multiple model (Blom and Bar-Shalom)
of two constant-velocity models, calm and manoeuvring (a white acceleration as large as
a hand's sudden start, stop or turn), each a filterpy ``KalmanFilter`` of the same state.
The translation block (p, v) and the rotation block (r, w) of every model are
uncorrelated (F, Q, H and R are block-diagonal between them), so each block has its own
mode probabilities and is mixed on its own: a sudden turn of a steadily moving torch is a
manoeuvre of the rotation only. Both models share the reference rotation, re-centred on
the combined estimate after every update. (filterpy's ``IMMEstimator`` is not used: it
mixes with a fixed switching matrix computed at the update, so neither a varying frame
interval nor a gated measurement, after which the next prediction must start from the
predicted mode probabilities, fits it; nor does its one set of mode probabilities.)
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.transforms import matrix_from_rotvec, rotvec_from_matrix


def _kalman_filter():
    """filterpy's 12-state, 6-measurement KalmanFilter.  Imported here, not at the module's
    top: filterpy pulls in scipy.stats (about 0.5 s), and every component's process reads
    this module through its config type at start-up; only the pose filter builds one."""
    from filterpy.kalman import KalmanFilter

    return KalmanFilter(dim_x=12, dim_z=6)

I3 = np.eye(3)
H_POSE = np.hstack([np.eye(6), np.zeros((6, 6))])  # measures p and r
H_POSITION = np.hstack([I3, np.zeros((3, 9))])  # measures p only
H_VELOCITY = np.hstack([np.zeros((6, 6)), np.eye(6)])  # "measures" v and w (zero-velocity update)
# The translation (p, v) and rotation (r, w) blocks of the state, and their rows in a pose
# measurement (p, r): the IMM mixes each on its own.
BLOCKS = (np.array([0, 1, 2, 6, 7, 8]), np.array([3, 4, 5, 9, 10, 11]))
MEAS_ROWS = (np.arange(0, 3), np.arange(3, 6))
BLOCKS_IX = tuple(np.ix_(idx, idx) for idx in BLOCKS)  # (12, 12) -> each block's (6, 6)
MEAS_ROWS_IX = tuple(np.ix_(rows, rows) for rows in MEAS_ROWS)


def _logsumexp(a: np.ndarray) -> np.float64:
    """``scipy.special.logsumexp(a)`` of a 1-D float array, the same operations in the same
    order (the largest terms taken out of the sum, ``log1p(s) + log(m) + a_max``) without its
    array-API dispatch, which cost more than the filter's update; scipy itself for what is
    not finite (its edge cases)."""
    a_max = np.max(a, keepdims=True)
    mask = a == a_max
    m = np.sum(mask.astype(a.dtype), keepdims=True, dtype=a.dtype)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.sum(np.exp(np.where(mask, -np.inf, a) - a_max), keepdims=True, dtype=a.dtype)
        s = np.where(s == 0, s, s / m)
        out = np.log1p(s) + np.log(m) + a_max
    if not np.isfinite(out[0]):
        from scipy.special import logsumexp

        return logsumexp(a)
    return out[0]


def _block_indices(blocks) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices into a (12, 12) array of the diagonal and of the off-diagonal entries of
    the 3x3 blocks whose first entries are ``blocks`` [(row, col), ...], block by block."""
    diag = [(r + i) * 12 + c + i for r, c in blocks for i in range(3)]
    off = [(r + i) * 12 + c + j for r, c in blocks for i in range(3) for j in range(3) if i != j]
    return np.array(diag), np.array(off)


# F: the (p, v) and (r, w) blocks are dt * I3; Q: per group (position, rotation) the blocks
# (pp, pv, vp, vv) are q * [dt^3/3, dt^2/2, dt^2/2, dt] * I3. Both are filled from these
# indices with the numbers the products with I3 give: s on the diagonal, s * 0 off it
# (which is the +0.0 already there unless s is negative, infinite or NaN).
_F_DIAG, _F_OFF = _block_indices([(0, 6), (3, 9)])
_Q_DIAG, _Q_OFF = _block_indices([(0, 0), (0, 6), (6, 0), (6, 6), (3, 3), (3, 9), (9, 3), (9, 9)])


def transition(dt_s: float) -> np.ndarray:
    """(12, 12) constant-velocity transition over ``dt_s``."""
    F = np.eye(12)
    flat = F.reshape(-1)
    flat[_F_DIAG] = dt_s
    zero = dt_s * 0.0
    if zero != 0.0 or math.copysign(1.0, zero) < 0.0:  # -0.0 or NaN: not np.eye's zeros
        flat[_F_OFF] = zero
    return F


def process_noise(
    dt_s: float, accel_sigma_m_s2: float, ang_accel_sigma_rad_s2: float
) -> np.ndarray:
    """(12, 12) discrete white-noise acceleration: per axis q * [[dt^3/3, dt^2/2], [dt^2/2, dt]]."""
    diag = []
    for q in (accel_sigma_m_s2**2, ang_accel_sigma_rad_s2**2):
        a, b, c = q * dt_s**3 / 3, q * dt_s**2 / 2, q * dt_s
        diag += [a, a, a, b, b, b, b, b, b, c, c, c]
    Q = np.zeros(144)
    Q[_Q_DIAG] = diag
    if not all(v >= 0.0 and v != math.inf and math.copysign(1.0, v) > 0.0 for v in diag[::3]):
        # v * 0 off the block diagonals is -0.0 or NaN, not the zeros already there
        Q[_Q_OFF] = [v * 0.0 for v in diag[::3] for _ in range(6)]
    return Q.reshape(12, 12)


@dataclass(frozen=True)
class Gate:
    """Outcome of one measurement: accepted, or rejected by the Mahalanobis gate."""

    accepted: bool
    mahalanobis2: float


class _PoseEstimate:
    """What both filters share: a state ``x`` (12,) [p, r, v, w] whose orientation is
    ``exp(r) @ R_ref``, its time ``t_ns`` (None before the first measurement), and the pose
    predicted from it by the constant-velocity transition."""

    x: np.ndarray
    R_ref: np.ndarray
    t_ns: int | None

    @property
    def initialised(self) -> bool:
        return self.t_ns is not None

    def rotation(self, x: np.ndarray | None = None) -> np.ndarray:
        x = self.x if x is None else x
        return matrix_from_rotvec(x[3:6]) @ self.R_ref

    def predicted_pose(self, t_ns: int) -> np.ndarray:
        """The world_T_tob of :meth:`predicted` alone."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        return self._transform(transition(dt) @ self.x)

    def _filters(self) -> list:
        """The filterpy filters that hold the state (one, or one per model)."""
        raise NotImplementedError

    def hold_orientation(self) -> None:
        """While the orientation is not measured (one or two sources seen), hold it: the
        angular velocity's estimate set to zero in every model, so that predictions keep
        the last measured orientation instead of turning it at a rate estimated from noise
        for as long as the source stays hidden (issue 32: 0.35 deg/s over a 2 s occlusion
        put a held tip 60 mm away 0.75 mm off). Its covariance is left as it is: the
        orientation's uncertainty still grows."""
        for kf in self._filters():
            kf.x[9:12] = 0.0
        self.version += 1

    def _transform(self, x: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.rotation(x)
        T[:3, 3] = x[0:3]
        return T


class PoseKalman(_PoseEstimate):
    """Filter of world_T_tob; times in ns, poses as (4, 4) transforms in metres.

    ``x`` (12,) and ``P`` (12, 12) are the state and its covariance (filterpy's); ``version``
    counts the changes of the state (for caches of things computed from it)."""

    def __init__(
        self,
        accel_sigma_m_s2: float,
        ang_accel_sigma_rad_s2: float,
        init_sigma_m: float = 0.01,
        init_sigma_rad: float = 0.05,
        init_sigma_v: float = 0.3,
        init_sigma_w: float = 1.0,
    ):
        self.accel_sigma = accel_sigma_m_s2
        self.ang_accel_sigma = ang_accel_sigma_rad_s2
        self.init_sd = np.repeat([init_sigma_m, init_sigma_rad, init_sigma_v, init_sigma_w], 3)
        self.q_scale = 1.0  # process noise x this (a still target: << 1)
        self.kf = _kalman_filter()
        self.R_ref = np.eye(3)
        self.t_ns: int | None = None
        self.version = 0

    @property
    def x(self) -> np.ndarray:
        return self.kf.x

    @property
    def P(self) -> np.ndarray:
        return self.kf.P

    def _filters(self) -> list:
        return [self.kf]

    def reset(self, t_ns: int, world_T_tob: np.ndarray, calm_only: bool = False) -> None:
        """Start again at a measured pose with zero velocity."""
        self.kf.x = np.zeros(12)
        self.kf.x[0:3] = world_T_tob[:3, 3]
        self.kf.P = np.diag(self.init_sd**2)
        self.R_ref = world_T_tob[:3, :3].copy()
        self.t_ns = int(t_ns)
        self.q_scale = 1.0
        self.version += 1

    def predict_to(self, t_ns: int) -> None:
        """Advance the filter to ``t_ns`` (no-op for t_ns <= current time)."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        if dt <= 0:
            return
        Q = process_noise(dt, self.accel_sigma, self.ang_accel_sigma)
        self.kf.predict(F=transition(dt), Q=Q * self.q_scale if self.q_scale != 1.0 else Q)
        self.t_ns = int(t_ns)
        self.version += 1

    def _recentre(self) -> None:
        self.R_ref = self.rotation()
        self.kf.x[3:6] = 0.0

    def update_pose(self, world_T_tob: np.ndarray, R_meas: np.ndarray, gate_chi2: float,
                    manoeuvre_gates: bool = True, calm_only: bool = False) -> Gate:
        """Update with a full pose; ``R_meas`` (6, 6) is its covariance (m^2, rad^2).
        (``manoeuvre_gates``, ``calm_only``: as :meth:`PoseIMM.update_pose`; one model here.)"""
        y = np.empty(6)
        y[0:3] = world_T_tob[:3, 3] - self.x[0:3]
        # Rotation innovation: the rotation vector from predicted to measured (wrapped).
        y[3:6] = rotvec_from_matrix(world_T_tob[:3, :3] @ self.rotation().T, assume_valid=True)
        return self._update(y, H_POSE, R_meas, gate_chi2)

    def update_position(self, world_p_m: np.ndarray, R_meas: np.ndarray, gate_chi2: float,
                        manoeuvre_gates: bool = True) -> Gate:
        """Update the position only; ``R_meas`` (3, 3) in m^2."""
        y = np.asarray(world_p_m, dtype=float) - self.x[0:3]
        return self._update(y, H_POSITION, R_meas, gate_chi2)

    def _update(self, y: np.ndarray, H: np.ndarray, R: np.ndarray, gate_chi2: float) -> Gate:
        S = H @ self.P @ H.T + R
        d2 = float(y @ np.linalg.solve(S, y))
        if not d2 <= gate_chi2:  # a NaN distance is not inside the gate either
            return Gate(False, d2)
        self.kf.update(H @ self.x + y, R=R, H=H)
        self._recentre()
        self.version += 1
        return Gate(True, d2)

    def update_zero_velocity(self, R_vel: np.ndarray) -> None:
        """A zero-velocity pseudo-measurement (the target is still); ``R_vel`` (6, 6) in
        (m/s)^2 and (rad/s)^2."""
        self.kf.update(np.zeros(6), R=R_vel, H=H_VELOCITY)
        self._recentre()
        self.version += 1

    def collapsed(self) -> PoseKalman:
        """A single-model filter in this state (as :meth:`PoseIMM.collapsed`): a copy."""
        return self.copy()

    def copy(self) -> PoseKalman:
        """An independent filter in the same state."""
        other = PoseKalman.__new__(PoseKalman)
        other.__dict__.update(self.__dict__)
        other.kf = copy.deepcopy(self.kf)
        other.R_ref = self.R_ref.copy()
        return other

    def predicted(self, t_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(world_T_tob (4, 4) m, velocity (6,) [v m/s, w rad/s], covariance (12, 12)) at ``t_ns``,
        without changing the filter; ``t_ns`` may be before the filter's time (a state for
        an earlier cycle stamp), then the motion is run backwards."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        F = transition(dt)
        x = F @ self.x
        P = F @ self.P @ F.T + self.q_scale * process_noise(abs(dt), self.accel_sigma, self.ang_accel_sigma)
        return self._transform(x), x[6:12].copy(), P



def switching_matrix(dt_s: float, calm_mean_s: float, manoeuvre_mean_s: float) -> np.ndarray:
    """(2, 2) mode transition over ``dt_s``: M[i, j] = P(mode j at the end | mode i at the
    start), modes (calm, manoeuvre) lasting ``calm_mean_s`` / ``manoeuvre_mean_s`` on average
    (a continuous-time Markov chain: over a long gap, the long-run shares)."""
    a, b = 1.0 / calm_mean_s, 1.0 / manoeuvre_mean_s  # rates calm -> manoeuvre, manoeuvre -> calm
    s = a + b
    left = -math.expm1(-s * dt_s)  # 1 - exp(-s dt)
    return np.array([[1.0 - a / s * left, a / s * left], [b / s * left, 1.0 - b / s * left]])


def _combine(mu: np.ndarray, xs: list[np.ndarray], Ps: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Moment-matched mixture: sum mu_j x_j and sum mu_j (P_j + dx_j dx_j^T)."""
    x = sum(m * xj for m, xj in zip(mu, xs, strict=True))
    P = sum(m * (Pj + np.outer(xj - x, xj - x)) for m, xj, Pj in zip(mu, xs, Ps, strict=True))
    return x, P


class PoseIMM(_PoseEstimate):
    """Filter of world_T_tob that follows manoeuvres (see the module docstring); the
    interface of :class:`PoseKalman`. ``noises``: (accel m/s^2, angular accel rad/s^2) of
    the calm and of the manoeuvring model; ``calm_mean_s`` / ``manoeuvre_mean_s``: how long
    each mode lasts on average. ``x`` (12,), ``P`` (12, 12): the combined estimate;
    ``mu`` (2 blocks, 2 modes): the mode probabilities of the translation and the rotation."""

    def __init__(self, noises: tuple[tuple[float, float], tuple[float, float]], calm_mean_s: float,
                 manoeuvre_mean_s: float, init_sd: np.ndarray | None = None):
        self.noises = tuple(noises)
        self.calm_mean_s, self.manoeuvre_mean_s = calm_mean_s, manoeuvre_mean_s
        self.init_sd = np.repeat([0.01, 0.05, 0.3, 1.0], 3) if init_sd is None else init_sd
        self.kfs = [_kalman_filter() for _ in self.noises]
        self.mu = np.tile(self._stationary(), (2, 1))
        self.R_ref = np.eye(3)
        self.t_ns: int | None = None
        self.version = 0
        self._cache: tuple[int, np.ndarray, np.ndarray] | None = None

    def _filters(self) -> list:
        return self.kfs

    def _stationary(self) -> np.ndarray:
        """The long-run share of each mode."""
        calm, man = self.calm_mean_s, self.manoeuvre_mean_s
        return np.array([calm, man]) / (calm + man)

    # -- the combined estimate --------------------------------------------------------
    def _combined(self) -> tuple[np.ndarray, np.ndarray]:
        if self._cache is None or self._cache[0] != self.version:
            x, P = self._mix_blocks(self.mu, [kf.x for kf in self.kfs], [kf.P for kf in self.kfs])
            self._cache = (self.version, x, P)
        return self._cache[1], self._cache[2]

    @staticmethod
    def _mix_blocks(mu: np.ndarray, xs: list[np.ndarray], Ps: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        x, P = np.zeros(12), np.zeros((12, 12))
        for b, (idx, ix) in enumerate(zip(BLOCKS, BLOCKS_IX, strict=True)):
            xb, Pb = _combine(mu[b], [xj[idx] for xj in xs], [Pj[ix] for Pj in Ps])
            x[idx] = xb
            P[ix] = Pb
        return x, P

    @property
    def x(self) -> np.ndarray:
        return self._combined()[0]

    @property
    def P(self) -> np.ndarray:
        return self._combined()[1]

    @property
    def manoeuvre_probability(self) -> tuple[float, float]:
        """(translation, rotation): the probability that the target manoeuvres."""
        return float(self.mu[0, 1]), float(self.mu[1, 1])

    def set_noises(self, noises, calm_mean_s: float, manoeuvre_mean_s: float) -> None:
        self.noises = tuple(noises)
        self.calm_mean_s, self.manoeuvre_mean_s = calm_mean_s, manoeuvre_mean_s

    # -- filtering -------------------------------------------------------------------
    def reset(self, t_ns: int, world_T_tob: np.ndarray, calm_only: bool = False) -> None:
        """Start again at a measured pose with zero velocity (``calm_only``: see
        :meth:`update_pose`)."""
        for kf in self.kfs:
            kf.x = np.zeros(12)
            kf.x[0:3] = world_T_tob[:3, 3]
            kf.P = np.diag(self.init_sd**2)
        self.mu = np.tile([1.0, 0.0] if calm_only else self._stationary(), (2, 1))
        self.R_ref = world_T_tob[:3, :3].copy()
        self.t_ns = int(t_ns)
        self.version += 1

    def predict_to(self, t_ns: int) -> None:
        """Mix the models (per block) and advance each to ``t_ns`` (no-op for t_ns <= now);
        the mode probabilities become the predicted ones."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        if dt <= 0:
            return
        M = switching_matrix(dt, self.calm_mean_s, self.manoeuvre_mean_s)
        xs = [kf.x.copy() for kf in self.kfs]
        Ps = [kf.P.copy() for kf in self.kfs]
        for b, (idx, ix) in enumerate(zip(BLOCKS, BLOCKS_IX, strict=True)):
            cbar = self.mu[b] @ M  # predicted mode probabilities
            omega = M * self.mu[b][:, None] / cbar[None, :]  # omega[i, j] = P(was i | is j)
            for j, kf in enumerate(self.kfs):
                x0, P0 = _combine(omega[:, j], [xi[idx] for xi in xs], [Pi[ix] for Pi in Ps])
                kf.x[idx] = x0
                kf.P[ix] = P0
            self.mu[b] = cbar
        F = transition(dt)
        for kf, (accel, ang_accel) in zip(self.kfs, self.noises, strict=True):
            kf.predict(F=F, Q=process_noise(dt, accel, ang_accel))
        self.t_ns = int(t_ns)
        self.version += 1

    def update_pose(self, world_T_tob: np.ndarray, R_meas: np.ndarray, gate_chi2: float,
                    manoeuvre_gates: bool = True, calm_only: bool = False) -> Gate:
        """Update with a full pose; ``R_meas`` (6, 6) its covariance (m^2, rad^2), no
        correlation between position and rotation. ``manoeuvre_gates``: whether the
        manoeuvring model may let the measurement in (else the calm one alone decides);
        ``calm_only``: a measurement that cannot tell a manoeuvre from its own errors: the
        calm model alone gates it and gives the estimate (the mode probabilities are set
        to calm), as the single calm filter would."""
        if calm_only:
            self.mu[:] = [1.0, 0.0]
            self.version += 1
            manoeuvre_gates = False
        ys = []
        for kf in self.kfs:
            y = np.empty(6)
            y[0:3] = world_T_tob[:3, 3] - kf.x[0:3]
            y[3:6] = rotvec_from_matrix(world_T_tob[:3, :3] @ self.rotation(kf.x).T, assume_valid=True)
            ys.append(y)
        return self._update(ys, H_POSE, R_meas, gate_chi2, (0, 1), manoeuvre_gates)

    def update_position(self, world_p_m: np.ndarray, R_meas: np.ndarray, gate_chi2: float,
                        manoeuvre_gates: bool = True) -> Gate:
        """Update the position only; ``R_meas`` (3, 3) in m^2."""
        ys = [np.asarray(world_p_m, dtype=float) - kf.x[0:3] for kf in self.kfs]
        return self._update(ys, H_POSITION, R_meas, gate_chi2, (0,), manoeuvre_gates)

    def _update(self, ys: list[np.ndarray], H: np.ndarray, R: np.ndarray, gate_chi2: float,
                blocks: tuple[int, ...], manoeuvre_gates: bool) -> Gate:
        # Per block and model: the Mahalanobis distance and the log likelihood of the
        # innovation. The measurement is inside the gate if, per block, the model it
        # fits best puts it there: a real manoeuvre is not an outlier.
        d2 = np.zeros((2, len(self.kfs)))
        loglik = np.zeros((2, len(self.kfs)))
        for j, (kf, y) in enumerate(zip(self.kfs, ys, strict=True)):
            S = H @ kf.P @ H.T + R
            for b in blocks:
                rows = MEAS_ROWS[b]
                Sb, yb = S[MEAS_ROWS_IX[b]], y[rows]
                d2[b, j] = float(yb @ np.linalg.solve(Sb, yb))
                sign, logdet = np.linalg.slogdet(2.0 * math.pi * Sb)
                loglik[b, j] = -0.5 * (d2[b, j] + logdet) if sign > 0 else -math.inf
        gating = d2 if manoeuvre_gates else d2[:, :1]
        best = float(sum(gating[b].min() for b in blocks))
        if not best <= gate_chi2:  # a NaN distance is not inside the gate either
            return Gate(False, best)
        for kf, y in zip(self.kfs, ys, strict=True):
            kf.update(H @ kf.x + y, R=R, H=H)
        for b in blocks:
            if self.mu[b, 1] == 0.0:  # calm only (update_pose's calm_only)
                continue
            logmu = np.log(np.maximum(self.mu[b], 1e-300)) + loglik[b]
            self.mu[b] = np.exp(logmu - _logsumexp(logmu))
        self._recentre()
        return Gate(True, best)

    def _recentre(self) -> None:
        """The shared reference onto the combined rotation; each model's small rotation
        re-expressed about it."""
        self.version += 1
        R_new = self.rotation()
        for kf in self.kfs:
            kf.x[3:6] = rotvec_from_matrix(self.rotation(kf.x) @ R_new.T, assume_valid=True)
        self.R_ref = R_new
        self.version += 1

    def collapsed(self) -> PoseKalman:
        """A single-model filter (the calm model's noise) in the combined state: where a
        still target is averaged."""
        calm = self.noises[0]
        out = PoseKalman(calm[0], calm[1])
        out.init_sd = self.init_sd.copy()
        out.kf.x = self.x.copy()
        out.kf.P = self.P.copy()
        out.R_ref = self.R_ref.copy()
        out.t_ns = self.t_ns
        out._recentre()
        return out

    def predicted(self, t_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`PoseKalman.predicted`: (world_T_tob (4, 4) m, velocity (6,), covariance
        (12, 12)) of the combined estimate at ``t_ns``, each model predicted on its own and
        combined with the current mode probabilities; the filter is not changed."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        F = transition(dt)
        xs = [F @ kf.x for kf in self.kfs]
        Ps = [F @ kf.P @ F.T + process_noise(abs(dt), a, aa) for kf, (a, aa) in zip(self.kfs, self.noises, strict=True)]
        x, P = self._mix_blocks(self.mu, xs, Ps)
        return self._transform(x), x[6:12].copy(), P

