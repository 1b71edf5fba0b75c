"""Constant-velocity Kalman filter of a rigid pose (pure numpy + filterpy).

State (12,), world frame, SI units::

    x = [p (3, m), r (3, rad), v (3, m/s), w (3, rad/s)]

The orientation is ``R = exp(r) @ R_ref``: ``r`` is a small rotation vector (world frame)
relative to a reference rotation that is re-centred after every update (a multiplicative
error state), so there is no Euler singularity and every rotation innovation is a
rotation vector of ``R_meas @ R_pred.T``, wrapped into (-pi, pi] by construction.

F, H and Q are built by hand (filterpy's ``kinematic_kf`` builds a wrong H): F is the
constant-velocity transition, Q the discrete white-noise-acceleration model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter

from humanpt.schemas.convert import matrix_from_rotvec, rotvec_from_matrix

I3 = np.eye(3)
H_POSE = np.hstack([np.eye(6), np.zeros((6, 6))])  # measures p and r
H_POSITION = np.hstack([I3, np.zeros((3, 9))])  # measures p only


def transition(dt_s: float) -> np.ndarray:
    """(12, 12) constant-velocity transition over ``dt_s``."""
    F = np.eye(12)
    F[0:3, 6:9] = dt_s * I3
    F[3:6, 9:12] = dt_s * I3
    return F


def process_noise(
    dt_s: float, accel_sigma_m_s2: float, ang_accel_sigma_rad_s2: float
) -> np.ndarray:
    """(12, 12) discrete white-noise acceleration: per axis q * [[dt^3/3, dt^2/2], [dt^2/2, dt]]."""
    Q = np.zeros((12, 12))
    for pos, vel, q in (
        (slice(0, 3), slice(6, 9), accel_sigma_m_s2**2),
        (slice(3, 6), slice(9, 12), ang_accel_sigma_rad_s2**2),
    ):
        Q[pos, pos] = q * dt_s**3 / 3 * I3
        Q[pos, vel] = q * dt_s**2 / 2 * I3
        Q[vel, pos] = q * dt_s**2 / 2 * I3
        Q[vel, vel] = q * dt_s * I3
    return Q


@dataclass(frozen=True)
class Gate:
    """Outcome of one measurement: accepted, or rejected by the Mahalanobis gate."""

    accepted: bool
    mahalanobis2: float


class PoseKalman:
    """Filter of world_T_tob; times in ns, poses as (4, 4) transforms in metres."""

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
        self.kf = KalmanFilter(dim_x=12, dim_z=6)
        self.R_ref = np.eye(3)
        self.t_ns: int | None = None

    @property
    def initialised(self) -> bool:
        return self.t_ns is not None

    def reset(self, t_ns: int, world_T_tob: np.ndarray) -> None:
        """Start again at a measured pose with zero velocity."""
        self.kf.x = np.zeros(12)
        self.kf.x[0:3] = world_T_tob[:3, 3]
        self.kf.P = np.diag(self.init_sd**2)
        self.R_ref = world_T_tob[:3, :3].copy()
        self.t_ns = int(t_ns)

    def predict_to(self, t_ns: int) -> None:
        """Advance the filter to ``t_ns`` (no-op for t_ns <= current time)."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        if dt <= 0:
            return
        self.kf.F = transition(dt)
        self.kf.Q = process_noise(dt, self.accel_sigma, self.ang_accel_sigma)
        self.kf.predict()
        self.t_ns = int(t_ns)

    def rotation(self, x: np.ndarray | None = None) -> np.ndarray:
        x = self.kf.x if x is None else x
        return matrix_from_rotvec(x[3:6]) @ self.R_ref

    def _recentre(self) -> None:
        self.R_ref = self.rotation()
        self.kf.x[3:6] = 0.0

    def update_pose(self, world_T_tob: np.ndarray, R_meas: np.ndarray, gate_chi2: float) -> Gate:
        """Update with a full pose; ``R_meas`` (6, 6) is its covariance (m^2, rad^2)."""
        y = np.empty(6)
        y[0:3] = world_T_tob[:3, 3] - self.kf.x[0:3]
        # Rotation innovation: the rotation vector from predicted to measured (wrapped).
        y[3:6] = rotvec_from_matrix(world_T_tob[:3, :3] @ self.rotation().T)
        return self._update(y, H_POSE, R_meas, gate_chi2)

    def update_position(self, world_p_m: np.ndarray, R_meas: np.ndarray, gate_chi2: float) -> Gate:
        """Update the position only; ``R_meas`` (3, 3) in m^2."""
        y = np.asarray(world_p_m, dtype=float) - self.kf.x[0:3]
        return self._update(y, H_POSITION, R_meas, gate_chi2)

    def _update(self, y: np.ndarray, H: np.ndarray, R: np.ndarray, gate_chi2: float) -> Gate:
        S = H @ self.kf.P @ H.T + R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > gate_chi2:
            return Gate(False, d2)
        z = H @ self.kf.x + y
        self.kf.update(z, R=R, H=H)
        self._recentre()
        return Gate(True, d2)

    def predicted(self, t_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(world_T_tob (4, 4) m, velocity (6,) [v m/s, w rad/s], covariance (12, 12)) at ``t_ns``,
        without changing the filter; ``t_ns`` may be before the filter's time (a state for
        an earlier cycle stamp), then the motion is run backwards."""
        dt = (int(t_ns) - self.t_ns) * 1e-9
        F = transition(dt)
        x = F @ self.kf.x
        P = F @ self.kf.P @ F.T + process_noise(abs(dt), self.accel_sigma, self.ang_accel_sigma)
        T = np.eye(4)
        T[:3, :3] = matrix_from_rotvec(x[3:6]) @ self.R_ref
        T[:3, 3] = x[0:3]
        return T, x[6:12].copy(), P
