"""Path files: CSV in mm and degrees, RTS smoothing, and export as a VAL II program.

CSV columns (a header line first)::

    index,stamp_ns,x_mm,y_mm,z_mm,psi_deg,theta_deg,phi_deg[,tip_x_mm,...,tip_phi_deg]
    [,orientation_held,cov_xx_mm2,...,cov_zz_mm2,cov_rxx_deg2,...,cov_rzz_deg2[,cov_tip_xx_mm2,...]]

X = (x, y, z, psi, theta, phi) is the state vector of the paper (§4): position of G (or of
the driver tip P) in the world frame, yaw-pitch-roll Z-Y-X.

Since issue 18 the recorder adds, per point: ``orientation_held`` (1: the orientation was
held, not measured - one or two sources visible; the position is measured), and the
filter's covariance as the 6 upper-triangle terms (xx, xy, xz, yy, yz, zz) of three
symmetric 3x3 matrices, world frame: G's position (mm^2), the orientation as a small
rotation vector about the world axes (deg^2; not the covariance of psi, theta, phi, which
is singular at theta = +-90 deg), and, with a tip, the tip's position (mm^2). Files without
these columns (older ones) still read: the fields are then None.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.runtime.files import atomic_open

HEADER = ["index", "stamp_ns", "x_mm", "y_mm", "z_mm", "psi_deg", "theta_deg", "phi_deg"]
TIP_HEADER = ["tip_x_mm", "tip_y_mm", "tip_z_mm", "tip_psi_deg", "tip_theta_deg", "tip_phi_deg"]
_UPPER = ("xx", "xy", "xz", "yy", "yz", "zz")
_UPPER_IJ = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
COV_HEADER = (["orientation_held"] + [f"cov_{k}_mm2" for k in _UPPER] + [f"cov_r{k}_deg2" for k in _UPPER])
TIP_COV_HEADER = [f"cov_tip_{k}_mm2" for k in _UPPER]


class PathFileError(ValueError):
    """A path file that cannot be read; the message names the file and line."""


@dataclass
class Path6:
    """A recorded path: stamps (N,) ns, X of G (N, 6), and X of the tip (N, 6) or None;
    ``orientation_held`` (N,) bool, ``cov_g_mm2``, ``cov_r_deg2`` (N, 3, 3) and
    ``cov_tip_mm2`` (N, 3, 3) (with a tip) when recorded, else None (see the module doc)."""

    index: np.ndarray
    stamp_ns: np.ndarray
    x_g: np.ndarray
    x_tip: np.ndarray | None = None
    orientation_held: np.ndarray | None = None
    cov_g_mm2: np.ndarray | None = None
    cov_r_deg2: np.ndarray | None = None
    cov_tip_mm2: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.stamp_ns)

    def points(self, which: str = "auto", held: str = "fill") -> np.ndarray:
        """(N, 6) X of the tip if recorded (``auto``/``tip``), else of G. Held orientations
        (``held="fill"``, default) are interpolated from the measured ones around them
        (:func:`fill_held_orientation`), what playback and the VAL export use; ``"keep"``:
        as recorded."""
        if which == "tip" or (which == "auto" and self.x_tip is not None):
            if self.x_tip is None:
                raise PathFileError("this path has no driver tip columns")
            x = self.x_tip
        else:
            x = self.x_g
        if held == "keep" or self.orientation_held is None or not np.any(self.orientation_held):
            return x
        return fill_held_orientation(x, self.orientation_held, self.stamp_ns)


def fill_held_orientation(x: np.ndarray, held: np.ndarray, stamp_ns: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) mm/deg: the points ``x`` with each held orientation (``held`` (N,) True)
    replaced by the geodesic interpolation, in time (``stamp_ns``, else by index), between
    the nearest measured orientations before and after it; the nearest one alone at either
    end. Positions are untouched; with no measured orientation at all, ``x`` is returned
    as is (a copy)."""
    from scipy.spatial.transform import Rotation, Slerp

    x = np.array(x, dtype=float).reshape(-1, 6)
    held = np.asarray(held, dtype=bool).reshape(-1)
    if len(held) != len(x):
        raise ValueError(f"held has {len(held)} entries for {len(x)} points")
    good = np.flatnonzero(~held)
    if not len(good) or len(good) == len(x):
        return x
    t = (np.arange(len(x), dtype=float) if stamp_ns is None
         else (np.asarray(stamp_ns, dtype=np.int64) - int(stamp_ns[0])) * 1e-9)
    rot = Rotation.from_euler("ZYX", x[good, 3:6], degrees=True)
    bad = np.flatnonzero(held)
    tb = np.clip(t[bad], t[good[0]], t[good[-1]])
    if len(good) == 1:
        filled = Rotation.concatenate([rot] * len(bad))
    else:
        filled = Slerp(t[good], rot)(tb)
    x[bad, 3:6] = filled.as_euler("ZYX", degrees=True)
    return x


def from_path_points(points) -> Path6:
    """A :class:`Path6` (mm, deg; held flags and covariances in mm^2, deg^2) of recorded
    ``controller/path`` messages (humanpt.PathPoint, all with or all without a tip)."""
    from humanpt.geometry.transforms import x_from_transform
    from humanpt.geometry.units import to_mm
    from humanpt.schemas.convert import from_pose

    def x(p):
        return x_from_transform(to_mm(from_pose(p)))

    def cov(values, scale):
        return np.asarray(values, dtype=float).reshape(3, 3) * scale if len(values) == 9 else np.zeros((3, 3))

    pts = list(points)
    tip = bool(pts) and pts[0].has_tip
    return Path6(
        np.array([p.index for p in pts], dtype=int), np.array([p.header.stamp_ns for p in pts], dtype=np.int64),
        np.array([x(p.world_T_tob) for p in pts]).reshape(-1, 6),
        np.array([x(p.world_T_tip) for p in pts]).reshape(-1, 6) if tip else None,
        orientation_held=np.array([p.orientation_held for p in pts], dtype=bool),
        cov_g_mm2=np.array([cov(p.position_covariance_m2, 1e6) for p in pts]).reshape(-1, 3, 3),
        cov_r_deg2=np.array([cov(p.rotation_covariance_rad2, np.degrees(1.0) ** 2) for p in pts]).reshape(-1, 3, 3),
        cov_tip_mm2=(np.array([cov(p.tip_position_covariance_m2, 1e6) for p in pts]).reshape(-1, 3, 3)
                     if tip else None))


def _upper(m: np.ndarray) -> list[float]:
    return [float(m[i, j]) for i, j in _UPPER_IJ]


def _from_upper(v: np.ndarray) -> np.ndarray:
    """(N, 6) upper triangles -> (N, 3, 3) symmetric."""
    v = np.asarray(v, dtype=float).reshape(-1, 6)
    m = np.zeros((len(v), 3, 3))
    for k, (i, j) in enumerate(_UPPER_IJ):
        m[:, i, j] = m[:, j, i] = v[:, k]
    return m


def row(index: int, stamp_ns: int, x_g: np.ndarray, x_tip: np.ndarray | None, *,
        orientation_held: bool | None = None, cov_g_mm2: np.ndarray | None = None,
        cov_r_deg2: np.ndarray | None = None, cov_tip_mm2: np.ndarray | None = None) -> list[str]:
    """One CSV row; the covariance columns when ``orientation_held`` is given (the
    covariances (3, 3) then too: NaN-free, zeros when unknown)."""
    vals = [str(int(index)), str(int(stamp_ns))] + [f"{v:.6f}" for v in x_g]
    if x_tip is not None:
        vals += [f"{v:.6f}" for v in x_tip]
    if orientation_held is not None:
        vals.append("1" if orientation_held else "0")
        for m in (cov_g_mm2, cov_r_deg2) + ((cov_tip_mm2,) if x_tip is not None else ()):
            vals += [f"{v:.6g}" for v in _upper(np.zeros((3, 3)) if m is None else np.asarray(m, dtype=float))]
    return vals


def header(with_tip: bool, with_covariance: bool = False) -> list[str]:
    return (HEADER + (TIP_HEADER if with_tip else [])
            + ((COV_HEADER + (TIP_COV_HEADER if with_tip else [])) if with_covariance else []))


def write(path: str | Path, p: Path6) -> None:
    cov = p.orientation_held is not None
    with atomic_open(path, "w", newline="") as f:  # never through a link planted at its name
        w = csv.writer(f)
        w.writerow(header(p.x_tip is not None, cov))
        for i in range(len(p)):
            extra = {}
            if cov:
                extra = {"orientation_held": bool(p.orientation_held[i]),
                         "cov_g_mm2": None if p.cov_g_mm2 is None else p.cov_g_mm2[i],
                         "cov_r_deg2": None if p.cov_r_deg2 is None else p.cov_r_deg2[i],
                         "cov_tip_mm2": None if p.cov_tip_mm2 is None else p.cov_tip_mm2[i]}
            w.writerow(row(p.index[i], p.stamp_ns[i], p.x_g[i], None if p.x_tip is None else p.x_tip[i], **extra))


# How large a row may be (bytes): a path row is about 400 (csv's own field limit is 128 kB).
_MAX_ROW = 4096


def _bounds(n_cols: int, tip: bool) -> list[tuple[float, float, str]]:
    """Per column (lo, hi, what) (:mod:`humanpt.seam.limits`): positions within +-10 m,
    angles within +-720 deg, covariances within +-1e8 (mm^2, deg^2), index whole >= 0."""
    from humanpt.seam.limits import MAX_ABS_DEG, MAX_ABS_MM, MAX_COV, MAX_INDEX

    pos, ang, cov = (-MAX_ABS_MM, MAX_ABS_MM, "mm"), (-MAX_ABS_DEG, MAX_ABS_DEG, "deg"), (-MAX_COV, MAX_COV, "")
    out = [(0, MAX_INDEX, ""), (-np.inf, np.inf, "")] + [pos] * 3 + [ang] * 3
    if tip:
        out += [pos] * 3 + [ang] * 3
    if n_cols > len(out):
        out += [(0.0, 1.0, "")] + [cov] * (n_cols - len(out) - 1)
    return out


def read(path: str | Path) -> Path6:
    """A path file, every value checked: finite, within :mod:`humanpt.seam.limits`,
    stamps whole nanoseconds within int64; :class:`PathFileError` naming the file, the
    line and the column."""
    from humanpt.seam.sanitise import shown

    p = Path(path)
    name = shown(p)
    if not p.is_file():
        raise PathFileError(f"{name}: no such path file")
    try:
        with open(p, newline="") as f:
            rows = []
            for r in csv.reader(f):
                if sum(len(c) for c in r) > _MAX_ROW:
                    raise PathFileError(f"{name}:{len(rows) + 1}: a row of more than {_MAX_ROW} characters")
                rows.append(r)
    except (UnicodeDecodeError, csv.Error) as e:
        raise PathFileError(f"{name}: not a path file ({shown(e)})") from None
    except OSError as e:
        raise PathFileError(f"{name}: cannot read ({shown(e.strerror or e)})") from None
    if not rows:
        raise PathFileError(f"{name}: empty file (no header line)")
    head = rows[0]
    if head not in [header(tip, cov) for tip in (False, True) for cov in (False, True)]:
        raise PathFileError(f"{name}:1: not a humanpt path header: {shown(','.join(head))[:200]}")
    tip = TIP_HEADER[0] in head
    cov = COV_HEADER[0] in head
    n = len(head)
    bounds = _bounds(n, tip)
    k_held = head.index(COV_HEADER[0]) if cov else 0
    data, stamps = [], []
    int64 = np.iinfo(np.int64)
    for lineno, r in enumerate(rows[1:], start=2):
        if not r:
            continue
        if len(r) != n:
            raise PathFileError(f"{name}:{lineno}: {len(r)} columns, expected {n}")
        try:
            vals = [float(v) for v in r]
            stamp = int(r[1])  # exact: wall-clock stamps (~1.8e18 ns) exceed a float's 53 bits
        except ValueError as e:
            raise PathFileError(f"{name}:{lineno}: {shown(e)}") from None
        for k, (v, (lo, hi, unit)) in enumerate(zip(vals, bounds, strict=True)):
            if not np.isfinite(v):
                raise PathFileError(f"{name}:{lineno}: {head[k]} is {r[k]}, not a finite number")
            if not lo <= v <= hi:
                raise PathFileError(f"{name}:{lineno}: {head[k]} {v:g}{' ' + unit if unit else ''} is outside "
                                    f"[{lo:.10g}, {hi:.10g}]")
            if k in (0, k_held) and v != int(v):
                raise PathFileError(f"{name}:{lineno}: {head[k]} {v:g} is not a whole number")
        if not int64.min <= stamp <= int64.max:
            raise PathFileError(f"{name}:{lineno}: stamp_ns {stamp} is outside int64 nanoseconds")
        data.append(vals)
        stamps.append(stamp)
    a = np.array(data, dtype=float).reshape(-1, n)
    out = Path6(a[:, 0].astype(int), np.array(stamps, dtype=np.int64), a[:, 2:8], a[:, 8:14] if tip else None)
    if cov:
        k = 14 if tip else 8
        out.orientation_held = a[:, k] != 0
        out.cov_g_mm2, out.cov_r_deg2 = _from_upper(a[:, k + 1:k + 7]), _from_upper(a[:, k + 7:k + 13])
        out.cov_tip_mm2 = _from_upper(a[:, k + 13:k + 19]) if tip else None
    return out


def smooth(x: np.ndarray, stamp_ns: np.ndarray, *, accel_sigma: float = 200.0, meas_sigma: float = 0.3
           ) -> np.ndarray:
    """RTS-smoothed (N, 6) path: per coordinate a constant-velocity Kalman filter forward and
    filterpy's Rauch-Tung-Striebel smoother backward.  Angles are unwrapped first and
    wrapped back.  ``accel_sigma`` in units/s^2, ``meas_sigma`` in units."""
    # filterpy (and the scipy.stats it pulls in: 0.7 s) only here: the controller's process
    # start-up does not pay for an offline smoother.
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter, rts_smoother

    from humanpt.seam.limits import MAX_ABS_DEG, MAX_ABS_MM

    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != 6 or not np.all(np.isfinite(x)):
        raise PathFileError("smoothing needs (N, 6) finite points")
    if np.abs(x[:, :3]).max(initial=0.0) > MAX_ABS_MM or np.abs(x[:, 3:]).max(initial=0.0) > MAX_ABS_DEG:
        raise PathFileError(f"a point beyond +-{MAX_ABS_MM:g} mm or +-{MAX_ABS_DEG:g} deg: not smoothed")
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
    if not np.all(np.isfinite(out)):
        raise PathFileError("smoothing gave values that are not finite numbers (a path beyond the limits?)")
    return out


def to_val2(x: np.ndarray, name: str = "path", speed_percent: float = 20.0) -> str:
    """A VAL II program that moves the tool through the points (mm, deg).

    VAL II's TRANS(x, y, z, o, a, t) takes Euler O-A-T angles (Z-Y-Z); the points are
    converted from yaw-pitch-roll Z-Y-X via scipy.  Every point must lie in the robot
    gateway's workspace box (:mod:`humanpt.seam.limits`), SPEED in (0, 100]; ``name``
    becomes a VAL II name (:func:`re_name`).
    """
    from scipy.spatial.transform import Rotation

    from humanpt.geometry.transforms import oat_deg_from_rotation

    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != 6 or not np.all(np.isfinite(x)):
        raise PathFileError("a VAL II program needs (N, 6) finite points")
    from humanpt.seam.limits import ENVELOPE_MAX_MM, ENVELOPE_MIN_MM

    lo, hi = np.asarray(ENVELOPE_MIN_MM), np.asarray(ENVELOPE_MAX_MM)
    out = np.flatnonzero(np.any((x[:, :3] < lo) | (x[:, :3] > hi), axis=1))
    if len(out):
        raise PathFileError(f"point {int(out[0])} ({', '.join(f'{v:.6g}' for v in x[out[0], :3])}) mm is beyond "
                            f"the workspace {tuple(lo)}..{tuple(hi)} mm (the robot gateway's box, "
                            "humanpt.seam.limits): not a VAL II program")
    if not (np.isfinite(speed_percent) and 0 < speed_percent <= 100):
        raise PathFileError(f"SPEED must be a percent in (0, 100], got {speed_percent!r}")
    prog = re_name(name)
    lines = [f".PROGRAM {prog}()", f"  ; {len(x)} points recorded by humanpt (teaching by showing)",
             f"  SPEED {speed_percent:g} ALWAYS"]
    for i, p in enumerate(x):
        o, a, t = oat_deg_from_rotation(Rotation.from_euler("ZYX", p[3:6], degrees=True))
        lines.append(f"  SET p{i} = TRANS({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f}, {o:.3f}, {a:.3f}, {t:.3f})")
    lines += [f"  MOVES p{i}" for i in range(len(x))]
    lines.append(".END")
    return "\n".join(lines) + "\n"


def re_name(name: str) -> str:
    """A VAL II program name of ``name`` (:func:`humanpt.seam.sanitise.identifier`)."""
    from humanpt.seam.sanitise import identifier

    return identifier(name, "val", default="path")
