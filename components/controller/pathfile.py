"""Path files: CSV in mm and degrees, RTS smoothing, and export as a VAL II program.

CSV columns (a header line first)::

    index,stamp_ns,x_mm,y_mm,z_mm,psi_deg,theta_deg,phi_deg[,tip_x_mm,...,tip_phi_deg]

X = (x, y, z, psi, theta, phi) is the state vector of the paper (§4): position of G (or of
the driver tip P) in the world frame, yaw-pitch-roll Z-Y-X.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter, rts_smoother

HEADER = ["index", "stamp_ns", "x_mm", "y_mm", "z_mm", "psi_deg", "theta_deg", "phi_deg"]
TIP_HEADER = ["tip_x_mm", "tip_y_mm", "tip_z_mm", "tip_psi_deg", "tip_theta_deg", "tip_phi_deg"]


class PathFileError(ValueError):
    """A path file that cannot be read; the message names the file and line."""


@dataclass
class Path6:
    """A recorded path: stamps (N,) ns, X of G (N, 6), and X of the tip (N, 6) or None."""

    index: np.ndarray
    stamp_ns: np.ndarray
    x_g: np.ndarray
    x_tip: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.stamp_ns)

    def points(self, which: str = "auto") -> np.ndarray:
        """(N, 6) X of the tip if recorded (``auto``/``tip``), else of G."""
        if which == "tip" or (which == "auto" and self.x_tip is not None):
            if self.x_tip is None:
                raise PathFileError("this path has no driver tip columns")
            return self.x_tip
        return self.x_g


def row(index: int, stamp_ns: int, x_g: np.ndarray, x_tip: np.ndarray | None) -> list[str]:
    vals = [str(int(index)), str(int(stamp_ns))] + [f"{v:.6f}" for v in x_g]
    if x_tip is not None:
        vals += [f"{v:.6f}" for v in x_tip]
    return vals


def header(with_tip: bool) -> list[str]:
    return HEADER + (TIP_HEADER if with_tip else [])


def write(path: str | Path, p: Path6) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header(p.x_tip is not None))
        for i in range(len(p)):
            w.writerow(row(p.index[i], p.stamp_ns[i], p.x_g[i], None if p.x_tip is None else p.x_tip[i]))


def read(path: str | Path) -> Path6:
    p = Path(path)
    if not p.is_file():
        raise PathFileError(f"{p}: no such path file")
    with open(p, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise PathFileError(f"{p}: empty file (no header line)")
    head = rows[0]
    if head not in (HEADER, HEADER + TIP_HEADER):
        raise PathFileError(f"{p}:1: not a humanpt path header: {','.join(head)}")
    n = len(head)
    data = []
    for lineno, r in enumerate(rows[1:], start=2):
        if not r:
            continue
        if len(r) != n:
            raise PathFileError(f"{p}:{lineno}: {len(r)} columns, expected {n}")
        try:
            data.append([float(v) for v in r])
        except ValueError as e:
            raise PathFileError(f"{p}:{lineno}: {e}") from e
    a = np.array(data, dtype=float).reshape(-1, n)
    return Path6(a[:, 0].astype(int), a[:, 1].astype(np.int64), a[:, 2:8],
                 a[:, 8:14] if n == len(HEADER) + len(TIP_HEADER) else None)


def smooth(x: np.ndarray, stamp_ns: np.ndarray, *, accel_sigma: float = 200.0, meas_sigma: float = 0.3
           ) -> np.ndarray:
    """RTS-smoothed (N, 6) path: per coordinate a constant-velocity Kalman filter forward and
    filterpy's Rauch-Tung-Striebel smoother backward.  Angles are unwrapped first and
    wrapped back.  ``accel_sigma`` in units/s^2, ``meas_sigma`` in units."""
    x = np.asarray(x, dtype=float)
    if len(x) < 3:
        return x.copy()
    t = (np.asarray(stamp_ns, dtype=np.int64) - int(stamp_ns[0])) * 1e-9
    dts = np.diff(t)
    if np.any(dts <= 0):
        raise PathFileError("path stamps must increase strictly")
    work = x.copy()
    work[:, 3:] = np.degrees(np.unwrap(np.radians(work[:, 3:]), axis=0))
    out = np.empty_like(work)
    for j in range(6):
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.x = np.array([work[0, j], 0.0])
        kf.P = np.diag([meas_sigma**2, 100.0**2])
        kf.H = np.array([[1.0, 0.0]])
        kf.R = np.array([[meas_sigma**2]])
        Fs = [np.array([[1.0, dt], [0.0, 1.0]]) for dt in np.r_[dts[0], dts]]
        Qs = [Q_discrete_white_noise(2, dt=dt, var=accel_sigma**2) for dt in np.r_[dts[0], dts]]
        means, covs = [], []
        for k in range(len(work)):
            kf.F, kf.Q = Fs[k], Qs[k]
            if k:
                kf.predict()
            kf.update(work[k, j])
            means.append(kf.x.copy())
            covs.append(kf.P.copy())
        xs, _, _, _ = rts_smoother(np.array(means), np.array(covs), np.array(Fs), np.array(Qs))
        out[:, j] = xs[:, 0]
    out[:, 3:] = (out[:, 3:] + 180.0) % 360.0 - 180.0
    return out


def to_val2(x: np.ndarray, name: str = "path", speed_percent: float = 20.0) -> str:
    """A VAL II program that moves the tool through the points (mm, deg).

    VAL II's TRANS(x, y, z, o, a, t) takes Euler O-A-T angles (Z-Y-Z); the points are
    converted from yaw-pitch-roll Z-Y-X via scipy.
    """
    from scipy.spatial.transform import Rotation

    x = np.asarray(x, dtype=float)
    prog = re_name(name)
    lines = [f".PROGRAM {prog}()", f"  ; {len(x)} points recorded by humanpt (teaching by showing)",
             f"  SPEED {speed_percent:g} ALWAYS"]
    for i, p in enumerate(x):
        o, a, t = Rotation.from_euler("ZYX", p[3:6], degrees=True).as_euler("ZYZ", degrees=True)
        lines.append(f"  SET p{i} = TRANS({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}, {o:.3f}, {a:.3f}, {t:.3f})")
    lines += [f"  MOVES p{i}" for i in range(len(x))]
    lines.append(".END")
    return "\n".join(lines) + "\n"


def re_name(name: str) -> str:
    clean = "".join(c if c.isalnum() else "_" for c in name.lower()).strip("_") or "path"
    return clean if clean[0].isalpha() else f"p_{clean}"
