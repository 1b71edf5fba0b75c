"""The taught path as a seam: straight lines and circular arcs, corners, dwells (issue 21.1).

A recorded path (positions in mm, Z-Y-X torch angles in degrees, stamps) is split into
segments by a split-and-merge search:

1. **Dwells**: runs of points that stay within ``dwell_radius_mm`` of their mean for at
   least ``dwell_min_s`` are one dwell (kept as one point of the seam, with its duration).
2. **Noise**: the path's own noise (hand tremor, measurement) is estimated from the
   residuals of local quadratic fits (5-point windows; curvature does not count as noise).
3. **Split**: a stretch is accepted as a line, else as an arc, when its fit's RMS residual
   is within the tolerance *beyond the noise* (``rms^2 <= tol^2 + noise^2``) and no point
   is farther than ``max(4 tol, 4 noise)`` from it; otherwise it is split at the point
   farthest from its chord (Douglas-Peucker), down to ``min_points``.
4. **Outliers**: in an accepted stretch, a point farther than ``outlier_sigma`` robust
   standard deviations from the fit (and beyond ``2 tol``) is rejected and the fit redone.
5. **Merge**: neighbours that together still fit one line or arc are merged; each
   boundary then moves to where the two fits' summed squared residual is least.
6. **Corners**: where the direction changes by more than ``corner_deg`` between two
   segments, the corner is where the two fitted lines (or tangents) meet (closest points
   of the two 3-D lines), and both segments end exactly there.

Each segment carries its residual RMS and maximum, the noise, the uncertainty carried
from the path points' covariances, and its torch orientation at both ends (a linear fit
of the rotation vectors about the segment's mean rotation against arc length, so the
torch is interpolated per segment).  Frames: whatever frame the path is in (the robot's
world frame for humanpt's path files); units mm and degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

__all__ = ["FitConfig", "FitError", "Segment", "Corner", "Dwell", "Seam", "fit_path", "line_fit", "arc_fit",
           "noise_mm", "sample_segment", "distance_to_seam"]


class FitError(ValueError):
    """A path that cannot be fitted (empty, one point, non-finite values); says why."""


@dataclass(frozen=True)
class FitConfig:
    """Parameters of :func:`fit_path` (mm, s, deg)."""

    tolerance_mm: float = 0.2  # the RMS a segment may deviate from its line/arc beyond the noise
    min_points: int = 4  # the fewest points a segment is fitted on
    corner_deg: float = 20.0  # a direction change above this between segments is a corner
    dwell_radius_mm: float = 0.5  # a dwell's points stay this close to their mean
    dwell_min_s: float = 0.5  # ... for at least this long
    outlier_sigma: float = 5.0  # robust standard deviations beyond which a point is an outlier
    split_confidence: float = 0.999  # two lines stay apart only if the split is this significant (F-test)
    min_arc_sweep_deg: float = 10.0  # an arc sweeps at least this much (else it is a line)
    min_arc_points: int = 7  # ... over at least this many points (a rounded corner is a corner, not an arc)
    max_arc_radius_mm: float = 5000.0  # flatter arcs are lines
    # Tighter arcs are corners (a hairpin, a reversal, the torch turning on the spot): at 20 mm/s
    # an arc of 0.5 mm radius turns the torch at 2300 deg/s, which no playback can follow.
    min_arc_radius_mm: float = 5.0
    corner_reach_mm: float = 30.0  # two lines meet in a corner at most this far beyond their fitted ends

    def __post_init__(self):
        for name in ("tolerance_mm", "corner_deg", "dwell_radius_mm", "outlier_sigma", "min_arc_sweep_deg",
                     "max_arc_radius_mm", "min_arc_radius_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise FitError(f"{name} must be a positive number, got {v!r}")
        if self.min_points < 3:
            raise FitError(f"min_points must be >= 3, got {self.min_points}")
        if not (math.isfinite(self.dwell_min_s) and self.dwell_min_s >= 0):
            raise FitError(f"dwell_min_s must be >= 0, got {self.dwell_min_s!r}")
        if self.min_arc_radius_mm >= self.max_arc_radius_mm:
            raise FitError(f"min_arc_radius_mm ({self.min_arc_radius_mm:g}) must be below max_arc_radius_mm "
                           f"({self.max_arc_radius_mm:g})")


# ---------------------------------------------------------------------------- primitives


@dataclass(frozen=True)
class LineFit:
    point_mm: np.ndarray  # (3,) a point on the line (the centroid)
    direction: np.ndarray  # (3,) unit, from the first point towards the last
    residuals_mm: np.ndarray  # (n,) distances of the points to the line

    def project(self, p_mm: np.ndarray) -> np.ndarray:
        """(.., 3) points -> their feet on the line."""
        return self.point_mm + ((p_mm - self.point_mm) @ self.direction)[..., None] * self.direction


def line_fit(p_mm: np.ndarray) -> LineFit:
    """Total least squares line through (n, 3) points (n >= 2)."""
    c = p_mm.mean(axis=0)
    _, _, vt = np.linalg.svd(p_mm - c, full_matrices=False)
    d = vt[0]
    if np.dot(p_mm[-1] - p_mm[0], d) < 0:
        d = -d
    r = p_mm - c
    res = np.linalg.norm(r - np.outer(r @ d, d), axis=1)
    return LineFit(c, d, res)


@dataclass(frozen=True)
class ArcFit:
    centre_mm: np.ndarray  # (3,)
    normal: np.ndarray  # (3,) unit, the plane's normal, oriented so the arc turns positively about it
    radius_mm: float
    start_angle_rad: float  # of the first point, in the plane's (u, v) basis
    sweep_rad: float  # signed from the first to the last point (positive about ``normal``)
    u: np.ndarray  # (3,) in-plane basis
    v: np.ndarray
    residuals_mm: np.ndarray  # (n,) 3-D distances of the points to the circle

    def point_at(self, angle_rad) -> np.ndarray:
        a = np.asarray(angle_rad, dtype=float)[..., None]
        return self.centre_mm + self.radius_mm * (np.cos(a) * self.u + np.sin(a) * self.v)

    def tangent_at(self, angle_rad: float) -> np.ndarray:
        t = -math.sin(angle_rad) * self.u + math.cos(angle_rad) * self.v
        return t if self.sweep_rad >= 0 else -t


def arc_fit(p_mm: np.ndarray) -> ArcFit | None:
    """Least squares circle through (n, 3) points (n >= 3): the plane by SVD (total least
    squares), the circle in the plane algebraically (Kasa), then its geometric distance
    minimised (scipy, Levenberg-Marquardt); residuals are 3-D distances to the circle.
    None when the points are (nearly) collinear."""
    c0 = p_mm.mean(axis=0)
    _, s, vt = np.linalg.svd(p_mm - c0, full_matrices=False)
    if s[1] < 1e-9 * max(s[0], 1e-12):
        return None
    u, v, n = vt[0], vt[1], vt[2]
    q = np.stack([(p_mm - c0) @ u, (p_mm - c0) @ v], axis=1)
    A = np.column_stack([2 * q, np.ones(len(q))])
    b = (q ** 2).sum(axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    cq = sol[:2]
    r0 = math.sqrt(max(sol[2] + cq @ cq, 1e-12))

    def resid2(x):  # in-plane geometric distance to the circle (cx, cy, r)
        return np.hypot(q[:, 0] - x[0], q[:, 1] - x[1]) - x[2]

    sol = least_squares(resid2, np.array([cq[0], cq[1], r0]), method="lm")
    cq, r0 = sol.x[:2], abs(float(sol.x[2]))
    centre, normal, r = c0 + cq[0] * u + cq[1] * v, n, r0

    def resid(centre, normal, r):
        d = p_mm - centre
        h = d @ normal
        rho = np.linalg.norm(d - np.outer(h, normal), axis=1)
        return np.hypot(h, rho - r)

    # In-plane basis from the first point; the sweep unwrapped point by point.
    d0 = p_mm[0] - centre
    u = d0 - (d0 @ normal) * normal
    if np.linalg.norm(u) < 1e-12:
        return None
    u = u / np.linalg.norm(u)
    v = np.cross(normal, u)
    d = p_mm - centre
    ang = np.unwrap(np.arctan2(d @ v, d @ u))
    sweep = float(ang[-1] - ang[0])
    if sweep < 0:  # orient the normal so the arc turns positively about it
        normal, v, ang, sweep = -normal, -v, -ang, -sweep
    return ArcFit(centre, normal, r, float(ang[0]), sweep, u, v, resid(centre, normal, r))


def noise_mm(p_mm: np.ndarray, window: int = 5) -> float:
    """The path's noise (mm, per point, 3-D RMS): the median over 5-point windows of the
    residual of a quadratic fit against the chord length (curvature and uneven spacing
    along the path are modelled, noise across it is not)."""
    n = len(p_mm)
    if n < window:
        return 0.0
    dof = window - 3
    per = []
    for i in range(n - window + 1):
        w = p_mm[i:i + window]
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(w, axis=0), axis=1))])
        if s[-1] < 1e-9:
            continue  # standing still: no path here
        u = s / s[-1] - 0.5
        per.append(float(((w - _quadratic_at(u, _quadratic(u, w))) ** 2).sum() / dof))
    return math.sqrt(float(np.median(per))) if per else 0.0


def _quadratic(s: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """The least-squares quadratic curve through points (k, 3) at parameters s (k,) (chord
    length): its coefficients (3, 3), highest power first (:func:`_quadratic_at`)."""
    coef, *_ = np.linalg.lstsq(np.vander(s, 3), pts, rcond=None)
    return coef


def _quadratic_at(s: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """The curve of :func:`_quadratic` at parameters s (m,): (m, 3)."""
    return np.vander(s, 3) @ coef


# ---------------------------------------------------------------------------- the seam


@dataclass(frozen=True)
class Segment:
    """A line or an arc of the seam (mm, deg).  ``start_mm``/``end_mm`` are on the fit (a
    corner's point where a corner joins two segments); ``first``/``last`` index the path
    points it was fitted on (inclusive); an arc has ``centre_mm``, ``normal``,
    ``radius_mm`` and ``sweep_deg`` (positive about ``normal``); ``start_ypr_deg`` and
    ``end_ypr_deg`` are the torch's Z-Y-X angles at its ends."""

    kind: str  # "line" | "arc"
    first: int
    last: int
    start_mm: tuple[float, float, float]
    end_mm: tuple[float, float, float]
    start_ypr_deg: tuple[float, float, float]
    end_ypr_deg: tuple[float, float, float]
    residual_rms_mm: float
    residual_max_mm: float
    points: int
    outliers: tuple[int, ...] = ()
    sigma_mm: float = math.nan  # the points' own position uncertainty (from the path's covariance), RMS
    centre_mm: tuple[float, float, float] | None = None
    normal: tuple[float, float, float] | None = None
    radius_mm: float | None = None
    sweep_deg: float | None = None
    doubt: str = ""  # why the fit doubts this segment ("" when it met its tolerance)

    @property
    def length_mm(self) -> float:
        if self.kind == "arc":
            return abs(math.radians(self.sweep_deg)) * self.radius_mm
        return float(np.linalg.norm(np.subtract(self.end_mm, self.start_mm)))

    def arc_basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """An arc's (centre, unit normal, u, v): u the unit direction from the centre to the
        start in the arc's plane, v = normal x u, so the arc is centre + r (cos a u + sin a
        v) for a from 0 to the sweep (mm)."""
        c, n = np.array(self.centre_mm, dtype=float), np.array(self.normal, dtype=float)
        n = n / np.linalg.norm(n)
        u = np.array(self.start_mm, dtype=float) - c
        u = u - (u @ n) * n
        u = u / np.linalg.norm(u)
        return c, n, u, np.cross(n, u)

    def points_at(self, fractions) -> np.ndarray:
        """(k, 3) points a fraction (0..1, of the length) along the segment, mm; at 0 and 1
        exactly its own ends (an arc's fitted ends may lie micrometres off its circle)."""
        f = np.clip(np.atleast_1d(np.asarray(fractions, dtype=float)), 0.0, 1.0)
        a, b = np.array(self.start_mm, dtype=float), np.array(self.end_mm, dtype=float)
        if self.kind == "line":
            return a + f[:, None] * (b - a)
        c, _, u, v = self.arc_basis()
        ang = f * math.radians(self.sweep_deg)
        p = c + self.radius_mm * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v)
        p[f <= 0.0], p[f >= 1.0] = a, b
        return p


@dataclass(frozen=True)
class Corner:
    """Where two segments meet at an angle: the point (mm), the direction change (deg),
    and the segments before and after (indices into :attr:`Seam.segments`)."""

    point_mm: tuple[float, float, float]
    angle_deg: float
    before: int
    after: int


@dataclass(frozen=True)
class Dwell:
    """The torch held still: where (mm), from which to which path point, for how long (s)."""

    point_mm: tuple[float, float, float]
    first: int
    last: int
    duration_s: float


@dataclass(frozen=True)
class Seam:
    segments: tuple[Segment, ...]
    corners: tuple[Corner, ...]
    dwells: tuple[Dwell, ...]
    outliers: tuple[int, ...]
    noise_mm: float
    config: FitConfig
    points: int
    meta: dict = field(default_factory=dict)  # source path/run, which point (G or tip), frame
    corner_cut: tuple[int, ...] = ()  # path points where the hand rounded a corner (in no fit)

    @property
    def doubts(self) -> list[str]:
        """One line per segment the fit doubts (its residual beyond the tolerance, points too
        far apart, a turn beside it not taken as a corner): empty when the seam is trusted."""
        return [f"segment {i} ({s.kind}, points {s.first}-{s.last}): {s.doubt}"
                for i, s in enumerate(self.segments) if s.doubt]

    @property
    def residual_rms_mm(self) -> float:
        """RMS residual over every fitted point of every segment."""
        n = sum(s.points for s in self.segments)
        if n == 0:
            return math.nan
        return math.sqrt(sum(s.residual_rms_mm ** 2 * s.points for s in self.segments) / n)


def _check_input(x: np.ndarray, stamp_ns: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != 6:
        raise FitError(f"a path is (N, 6): x, y, z mm and psi, theta, phi deg; got shape {x.shape}")
    if len(x) < 2:
        raise FitError(f"a path of {len(x)} point{'s' if len(x) != 1 else ''} has no segment to fit")
    bad = np.flatnonzero(~np.isfinite(x).all(axis=1))
    if len(bad):
        raise FitError(f"the path has non-finite values at point{'s' if len(bad) > 1 else ''} "
                       f"{', '.join(str(int(i)) for i in bad[:5])}{' ...' if len(bad) > 5 else ''}")
    if stamp_ns is None:
        t = np.arange(len(x), dtype=float)
    else:
        t = np.asarray(stamp_ns, dtype=float) * 1e-9
        if t.shape != (len(x),) or not np.all(np.isfinite(t)):
            raise FitError("the stamps must be one finite number per point")
        if np.any(np.diff(t) < 0):
            raise FitError("the stamps go backwards")
    return x, t


def _dwells(p: np.ndarray, t: np.ndarray, cfg: FitConfig) -> list[tuple[int, int]]:
    """[(first, last)] runs of points within dwell_radius_mm of their mean for >= dwell_min_s."""
    out, i, n = [], 0, len(p)
    while i < n:
        j = i
        while j + 1 < n:
            m = p[i:j + 2].mean(axis=0)
            if np.max(np.linalg.norm(p[i:j + 2] - m, axis=1)) > cfg.dwell_radius_mm:
                break
            j += 1
        if j > i and t[j] - t[i] >= cfg.dwell_min_s:
            out.append((i, j))
            i = j + 1
        else:
            i += 1
    return out


@dataclass
class _Piece:
    idx: np.ndarray  # indices into the (dwell-collapsed) working points
    kind: str
    fit: object
    rms: float
    max: float


def _fit_piece(q: np.ndarray, idx: np.ndarray, cfg: FitConfig, noise: float, force: bool = False) -> _Piece | None:
    """The best accepted model of the points ``q[idx]`` (a line first, else an arc), or
    None; ``force``: the better of the two even if not accepted."""
    pts = q[idx]
    limit_rms = math.sqrt(cfg.tolerance_mm ** 2 + noise ** 2)
    limit_max = max(4 * cfg.tolerance_mm, 4 * noise)
    lf = line_fit(pts)
    line = _Piece(idx, "line", lf, float(np.sqrt(np.mean(lf.residuals_mm ** 2))), float(lf.residuals_mm.max()))
    if line.rms <= limit_rms and line.max <= limit_max:
        return line
    arc = None
    if len(idx) >= max(cfg.min_points, cfg.min_arc_points, 4):
        af = arc_fit(pts)
        if _arc_allowed(af, len(idx), cfg):
            arc = _Piece(idx, "arc", af, float(np.sqrt(np.mean(af.residuals_mm ** 2))), float(af.residuals_mm.max()))
            if arc.rms <= limit_rms and arc.max <= limit_max:
                return arc
    if force:
        return min([p for p in (line, arc) if p is not None], key=lambda p: p.rms)
    return None


def _arc_allowed(af, n_points: int, cfg: FitConfig) -> bool:
    """Whether an arc fit may be a segment: enough points (``min_arc_points``), its radius
    within [``min_arc_radius_mm``, ``max_arc_radius_mm``] (tighter is a corner, flatter a
    line) and a sweep of at least ``min_arc_sweep_deg``, less than a full turn."""
    return (af is not None and n_points >= max(cfg.min_points, cfg.min_arc_points, 4)
            and cfg.min_arc_radius_mm <= af.radius_mm <= cfg.max_arc_radius_mm
            and math.degrees(af.sweep_rad) >= cfg.min_arc_sweep_deg and af.sweep_rad < 2 * math.pi)


def _chord_split(q: np.ndarray, idx: np.ndarray) -> int:
    """The position (in idx) of the point farthest from the chord first -> last."""
    a, b = q[idx[0]], q[idx[-1]]
    d = b - a
    L = np.linalg.norm(d)
    r = q[idx] - a
    if L < 1e-9:
        dist = np.linalg.norm(r, axis=1)
    else:
        d = d / L
        dist = np.linalg.norm(r - np.outer(r @ d, d), axis=1)
    k = int(np.argmax(dist[1:-1])) + 1 if len(idx) > 2 else len(idx) // 2
    return k


def _split(q: np.ndarray, idx: np.ndarray, cfg: FitConfig, noise: float) -> list[_Piece]:
    piece = _fit_piece(q, idx, cfg, noise)
    if piece is not None or len(idx) < 2 * cfg.min_points - 1:
        return [piece or _fit_piece(q, idx, cfg, noise, force=True)]
    k = _chord_split(q, idx)
    k = min(max(k, cfg.min_points - 1), len(idx) - cfg.min_points)
    # the split point belongs to both sides (a corner is on both lines)
    return _split(q, idx[:k + 1], cfg, noise) + _split(q, idx[k:], cfg, noise)


_PARAMS = {"line": 4, "arc": 6}  # free parameters of a 3-D line / circle arc


def _split_needed(a: _Piece, b: _Piece, union: _Piece, cfg: FitConfig) -> bool:
    """Does splitting into ``a`` and ``b`` explain the points significantly better than
    ``union`` (an F-test on the residuals, each point giving 2 residuals across the path,
    at ``1 - split_confidence``)?  Noise the local estimate missed (a hand's slow wander)
    does not make a corner."""
    from scipy.stats import f as f_dist

    sse_u, sse_s = _sse(union), _sse(a) + _sse(b)
    dof_s = 2 * (len(a.idx) + len(b.idx)) - _PARAMS[a.kind] - _PARAMS[b.kind]
    ddof = _PARAMS[a.kind] + _PARAMS[b.kind] - _PARAMS[union.kind]
    if dof_s <= 0 or ddof <= 0 or sse_s <= 0:
        return True
    F = ((sse_u - sse_s) / ddof) / (sse_s / dof_s)
    return bool(f_dist.sf(F, ddof, dof_s) < 1.0 - cfg.split_confidence)


def _merge(q: np.ndarray, pieces: list[_Piece], cfg: FitConfig, noise: float) -> list[_Piece]:
    """Merge neighbours, best first, while their union fits one line or arc: within the
    tolerance, or (a line; no point beyond the outlier limit) no significantly worse than
    the two apart."""
    limit_max = max(4 * cfg.tolerance_mm, 4 * noise)
    changed = True
    while changed and len(pieces) > 1:
        changed = False
        best = None
        for i in range(len(pieces) - 1):
            idx = np.union1d(pieces[i].idx, pieces[i + 1].idx)
            m = _fit_piece(q, idx, cfg, noise)
            if m is None:
                u = _refit(q, idx, "line")
                if (u is not None and u.max <= limit_max and pieces[i].kind == pieces[i + 1].kind == "line"
                        and not _split_needed(pieces[i], pieces[i + 1], u, cfg)):
                    m = u
            if m is not None and (best is None or m.rms < best[1].rms):
                best = (i, m)
        if best is not None:
            i, m = best
            pieces[i:i + 2] = [m]
            changed = True
    return pieces


def _drop_rounded_corners(pieces: list[_Piece], cfg: FitConfig) -> tuple[list[_Piece], list[int]]:
    """A short piece between two lines that turn by more than ``corner_deg`` is the hand
    (and the servo) rounding a corner: it is dropped, its inner points are kept out of every
    fit (returned), and the corner becomes where the two lines meet."""
    cut: list[int] = []
    i = 1
    while i < len(pieces) - 1:
        a, m, b = pieces[i - 1], pieces[i], pieces[i + 1]
        if len(m.idx) <= cfg.min_points and a.kind == "line" and b.kind == "line":
            angle = math.degrees(math.acos(float(np.clip(a.fit.direction @ b.fit.direction, -1, 1))))
            if angle > cfg.corner_deg:
                cut += [int(k) for k in m.idx[1:-1]]
                del pieces[i]
                continue
        i += 1
    return pieces, cut


def _dist_to_chord(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    L = np.linalg.norm(d)
    if L < 1e-9:
        return float(np.linalg.norm(p - a))
    r = p - a
    return float(np.linalg.norm(r - (r @ d) / (L * L) * d))


def _spikes(q: np.ndarray, noise: float, cfg: FitConfig) -> list[int]:
    """Isolated points off a path that is smooth without them (a reflection taken for a
    source, a bad frame): far from the chord of their neighbours while the neighbours lie
    on the chords that skip the point (a straight stretch), or, on a curve, far from the
    smooth curve through its two neighbours on each side (:func:`_off_curve`) while those
    four lie on it and turn by less than a corner."""
    out = []
    big = max(cfg.outlier_sigma * noise, 2 * cfg.tolerance_mm)
    small = max(3 * noise, cfg.tolerance_mm)
    for i in range(2, len(q) - 2):
        if (_dist_to_chord(q[i], q[i - 1], q[i + 1]) > big
                and _dist_to_chord(q[i - 1], q[i - 2], q[i + 1]) <= small
                and _dist_to_chord(q[i + 1], q[i - 1], q[i + 2]) <= small):
            out.append(i)
            continue
        off, fit_mm, turn_deg = _off_curve(q[i - 2:i + 3])
        if off > big and fit_mm <= small and turn_deg < cfg.corner_deg:
            out.append(i)
    return out


def _off_curve(five: np.ndarray) -> tuple[float, float, float]:
    """Five consecutive points, the middle one in question: (its distance from the
    quadratic curve (in arc length) through the other four, least squares; the largest
    distance of those four from that curve; the turn, deg, from the first chord to the
    last).  On an arc of radius r sampled every h the curve is within ~(2h)^4 / 8r^3 of the
    arc (4e-3 mm at r = 80, h = 5.8 mm, where the chord test above misses by the sagitta)."""
    a, b, m, c, d = five
    g = float(np.linalg.norm(c - b))
    if g < 1e-9:
        return 0.0, 0.0, 0.0
    s = np.array([-0.5 * g - float(np.linalg.norm(b - a)), -0.5 * g, 0.5 * g, 0.5 * g + float(np.linalg.norm(d - c))])
    four = np.array([a, b, c, d])
    coef = _quadratic(s, four)
    fit_mm = float(np.linalg.norm(_quadratic_at(s, coef) - four, axis=1).max())
    curve = _quadratic_at(np.linspace(-0.5 * g, 0.5 * g, 33), coef)  # between the two nearest
    off = float(np.linalg.norm(curve - m, axis=1).min())
    u, w = b - a, d - c
    nu, nw = float(np.linalg.norm(u)), float(np.linalg.norm(w))
    turn = 0.0 if nu < 1e-9 or nw < 1e-9 else math.degrees(math.acos(float(np.clip(u @ w / (nu * nw), -1.0, 1.0))))
    return off, fit_mm, turn


def _sse(piece: _Piece) -> float:
    return float(np.sum(piece.fit.residuals_mm ** 2))


def _refit(q: np.ndarray, idx: np.ndarray, kind: str, cfg: FitConfig | None = None) -> _Piece | None:
    """The points as the given kind (no test of its residual); None if an arc does not fit,
    or (with ``cfg``) is no arc the fit may make (:func:`_arc_allowed`: a boundary moved
    onto a short stretch once made a 6-point arc of 0.5 mm radius that the seam file then
    refused)."""
    f = line_fit(q[idx]) if kind == "line" else arc_fit(q[idx])
    if f is None or (kind == "arc" and cfg is not None and not _arc_allowed(f, len(idx), cfg)):
        return None
    return _Piece(idx, kind, f, float(np.sqrt(np.mean(f.residuals_mm ** 2))), float(f.residuals_mm.max()))


def _refine_boundaries(q: np.ndarray, pieces: list[_Piece], cfg: FitConfig, noise: float) -> list[_Piece]:
    """Move each shared boundary point to where the two neighbours' summed SSE is least."""
    for i in range(len(pieces) - 1):
        a, b = pieces[i], pieces[i + 1]
        lo, hi = a.idx[0], b.idx[-1]
        shared = a.idx[-1]
        best = (_sse(a) + _sse(b), a, b)
        for k in range(max(lo + cfg.min_points - 1, shared - 3), min(hi - cfg.min_points + 1, shared + 3) + 1):
            if k == shared:
                continue
            ia, ib = np.arange(lo, k + 1), np.arange(k, hi + 1)
            pa, pb = _refit(q, ia, a.kind, cfg), _refit(q, ib, b.kind, cfg)
            if pa is not None and pb is not None and _sse(pa) + _sse(pb) < best[0]:
                best = (_sse(pa) + _sse(pb), pa, pb)
        pieces[i], pieces[i + 1] = best[1], best[2]
    return pieces


def _reject_outliers(q: np.ndarray, piece: _Piece, cfg: FitConfig, noise: float) -> tuple[_Piece, list[int]]:
    res = piece.fit.residuals_mm
    sigma = max(1.4826 * float(np.median(np.abs(res - np.median(res)))), noise, 1e-6)
    bad = (res > cfg.outlier_sigma * sigma) & (res > 2 * cfg.tolerance_mm)
    bad[0] = bad[-1] = False  # the ends are shared with the neighbours
    if not bad.any() or (~bad).sum() < cfg.min_points:
        return piece, []
    keep = piece.idx[~bad]
    return _fit_piece(q, keep, cfg, noise, force=True), [int(i) for i in piece.idx[bad]]


def _closest_points(p1, d1, p2, d2) -> np.ndarray | None:
    """Midpoint of the closest points of two 3-D lines; None when (nearly) parallel."""
    w = p1 - p2
    b = d1 @ d2
    denom = 1 - b * b
    if denom < 1e-9:
        return None
    s = (b * (d2 @ w) - (d1 @ w)) / denom
    t = ((d2 @ w) - b * (d1 @ w)) / denom
    return 0.5 * ((p1 + s * d1) + (p2 + t * d2))


def _end_directions(piece: _Piece) -> tuple[np.ndarray, np.ndarray]:
    if piece.kind == "line":
        return piece.fit.direction, piece.fit.direction
    f: ArcFit = piece.fit
    return f.tangent_at(f.start_angle_rad), f.tangent_at(f.start_angle_rad + f.sweep_rad)


def _end_points(q: np.ndarray, piece: _Piece) -> tuple[np.ndarray, np.ndarray]:
    if piece.kind == "line":
        return piece.fit.project(q[piece.idx[0]]), piece.fit.project(q[piece.idx[-1]])
    f: ArcFit = piece.fit
    return f.point_at(f.start_angle_rad), f.point_at(f.start_angle_rad + f.sweep_rad)


def _orientation_ends(ypr_deg: np.ndarray, s_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Torch Z-Y-X angles (deg) at arc length 0 and s_mm[-1]: rotation vectors about the
    mean rotation, fitted linearly against arc length."""
    rots = Rotation.from_euler("ZYX", ypr_deg, degrees=True)
    mean = rots.mean()
    rv = (mean.inv() * rots).as_rotvec()
    if len(s_mm) >= 2 and s_mm[-1] - s_mm[0] > 1e-9:
        A = np.column_stack([np.ones(len(s_mm)), s_mm])
        coef, *_ = np.linalg.lstsq(A, rv, rcond=None)
        ends = [coef[0] + coef[1] * s_mm[0], coef[0] + coef[1] * s_mm[-1]]
    else:
        ends = [rv.mean(axis=0)] * 2
    out = [(mean * Rotation.from_rotvec(e)).as_euler("ZYX", degrees=True) for e in ends]
    return out[0], out[1]


def _doubt(q: np.ndarray, piece: _Piece, cfg: FitConfig, noise: float) -> str:
    """Why the fit doubts ``piece`` ("" when it does not): its residual beyond what the
    split accepts (a piece kept only because it was too short to split), or an arc's points
    too far apart to tell it from its chords within the tolerance."""
    limit_rms = math.sqrt(cfg.tolerance_mm ** 2 + noise ** 2)
    limit_max = max(4 * cfg.tolerance_mm, 4 * noise)
    why = []
    if piece.rms > limit_rms:
        why.append(f"residual RMS {piece.rms:.3f} mm beyond its limit {limit_rms:.3f} mm (tolerance "
                   f"{cfg.tolerance_mm:g} mm, path noise {noise:.3f} mm)")
    if piece.max > limit_max:
        why.append(f"a point {piece.max:.3f} mm off the fit, beyond {limit_max:.3f} mm")
    if piece.kind == "arc":  # a chord d deviates d^2 / 8r from its arc: points that far apart cannot show it
        # (the median spacing, not the largest: one point rejected as an outlier, or one
        # measurement missed, leaves one wider gap that the points around it bridge; a
        # recording sparse all along the arc is what cannot tell it from its chords)
        pts = q[piece.idx]
        gap = float(np.median(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
        sagitta = gap ** 2 / (8 * piece.fit.radius_mm)
        if sagitta > cfg.tolerance_mm:
            why.append(f"points {gap:.1f} mm apart (median) on a radius of {piece.fit.radius_mm:.1f} mm: the arc "
                       f"leaves their chord by {sagitta:.2f} mm, beyond the tolerance (record denser)")
    return "; ".join(why)


def _no_corner(q: np.ndarray, pieces: list[_Piece], cfg: FitConfig, noise: float) -> list[bool]:
    """Per piece: may no corner be made beside it?  When it was kept beyond its tolerance
    only because it had too few points to split (fewer than 2 min_points - 1): its
    direction is a chord's, and two such chords of an arc meet in a corner the path never
    had (issue 32: 41 deg, residual 1.18 mm against 0.2)."""
    limit_rms = math.sqrt(cfg.tolerance_mm ** 2 + noise ** 2)
    limit_max = max(4 * cfg.tolerance_mm, 4 * noise)
    return [bool((pc.rms > limit_rms or pc.max > limit_max) and len(pc.idx) < 2 * cfg.min_points - 1)
            for pc in pieces]


def _join(q: np.ndarray, pieces: list[_Piece], cfg: FitConfig, noise: float, spacing: float,
          doubted: list[bool] | None = None) -> tuple[list[np.ndarray], list[np.ndarray], list[Corner]]:
    """Each piece's start and end, and the corners: where the direction changes by more
    than corner_deg, the two pieces meet where their lines (tangents) do; else halfway
    between their own ends.  Beside a ``doubted`` piece (:func:`_no_corner`) no corner is
    made (its direction is not known well enough to say the path turned there)."""
    starts, ends = zip(*(_end_points(q, pc) for pc in pieces), strict=True)
    starts, ends = [s.copy() for s in starts], [e.copy() for e in ends]
    corners: list[Corner] = []
    doubted = doubted or [False] * len(pieces)
    for i in range(len(pieces) - 1):
        _, d_out = _end_directions(pieces[i])
        d_in, _ = _end_directions(pieces[i + 1])
        angle = math.degrees(math.acos(float(np.clip(d_out @ d_in, -1.0, 1.0))))
        joint = None
        if angle > cfg.corner_deg and not (doubted[i] or doubted[i + 1]):
            joint = _closest_points(ends[i], d_out, starts[i + 1], d_in)
            # the shared point may lie up to about a point's spacing on either side of the corner
            slack = max(3 * max(cfg.tolerance_mm, noise), 1.5 * spacing)
            if joint is not None and not (
                    -slack <= (joint - ends[i]) @ d_out <= cfg.corner_reach_mm
                    and -cfg.corner_reach_mm <= (joint - starts[i + 1]) @ d_in <= slack):
                joint = None  # the lines meet far from where the hand turned: no clean corner
            if joint is not None:
                corners.append(Corner(tuple(map(float, joint)), angle, i, i + 1))
        if joint is None:
            joint = 0.5 * (ends[i] + starts[i + 1])
        ends[i], starts[i + 1] = joint, joint
    return starts, ends, corners


def fit_path(x: np.ndarray, stamp_ns: np.ndarray | None = None, cov_mm2: np.ndarray | None = None,
             config: FitConfig | None = None, meta: dict | None = None) -> Seam:
    """Fit a seam to a path: ``x`` (N, 6) positions mm and Z-Y-X angles deg (one frame),
    ``stamp_ns`` (N,) (for dwells; None: dwells are not looked for), ``cov_mm2`` (N, 3, 3)
    position covariances or None.  Raises :class:`FitError` on an empty, one-point or
    non-finite path."""
    cfg = config or FitConfig()
    x, t = _check_input(x, stamp_ns)
    p = x[:, :3]
    dwell_runs = _dwells(p, t, cfg) if stamp_ns is not None else []
    # Working points: a dwell counts once (its mean), so it does not weigh on the fits.
    keep = np.ones(len(p), dtype=bool)
    for a, b in dwell_runs:
        keep[a + 1:b + 1] = False
    q_src = np.flatnonzero(keep)  # working index -> path index
    q = p[q_src].copy()
    for a, b in dwell_runs:
        q[np.searchsorted(q_src, a)] = p[a:b + 1].mean(axis=0)
    noise = noise_mm(q)
    spikes = _spikes(q, noise, cfg)
    if spikes:
        q, q_src = np.delete(q, spikes, axis=0), np.delete(q_src, spikes)
    if len(q) < 2:
        raise FitError("the path does not move: every point is one dwell")
    idx = np.arange(len(q))
    if len(q) < cfg.min_points:
        pieces = [_fit_piece(q, idx, cfg, noise, force=True)]
    else:
        pieces = _split(q, idx, cfg, noise)
    pieces = _merge(q, pieces, cfg, noise)
    pieces = _refine_boundaries(q, pieces, cfg, noise)
    pieces, cut = _drop_rounded_corners(pieces, cfg)
    corner_cut = [int(q_src[i]) for i in cut]
    outliers: list[int] = [int(i) for i in np.flatnonzero(keep)[spikes]] if spikes else []
    cleaned = []
    for pc in pieces:
        pc, bad = _reject_outliers(q, pc, cfg, noise)
        cleaned.append(pc)
        outliers += [int(q_src[i]) for i in bad]
    pieces = cleaned

    spacing = float(np.median(np.linalg.norm(np.diff(q, axis=0), axis=1))) if len(q) > 1 else 0.0
    doubts = [_doubt(q, pc, cfg, noise) for pc in pieces]
    starts, ends, corners = _join(q, pieces, cfg, noise, spacing, _no_corner(q, pieces, cfg, noise))
    if corners:
        # The hand rounds a corner: the points within a spacing of it lie off both lines.
        # Fit each line without them, then join again.
        near: dict[int, list[np.ndarray]] = {}
        for c in corners:
            near.setdefault(c.before, []).append(np.array(c.point_mm))
            near.setdefault(c.after, []).append(np.array(c.point_mm))
        for i, joints in near.items():
            pc = pieces[i]
            if pc.kind != "line":
                continue
            far = np.all([np.linalg.norm(q[pc.idx] - j, axis=1) > spacing for j in joints], axis=0)
            if far.sum() >= cfg.min_points and not far.all():
                corner_cut += [int(q_src[k]) for k in pc.idx[~far]]
                pieces[i] = _refit(q, pc.idx[far], "line")
        doubts = [_doubt(q, pc, cfg, noise) for pc in pieces]
        starts, ends, corners = _join(q, pieces, cfg, noise, spacing, _no_corner(q, pieces, cfg, noise))
    # A turn beside a piece kept beyond its tolerance was not taken as a corner: say so.
    blocked = _no_corner(q, pieces, cfg, noise)
    for i in range(len(pieces) - 1):
        if blocked[i] or blocked[i + 1]:
            _, d_out = _end_directions(pieces[i])
            d_in, _ = _end_directions(pieces[i + 1])
            angle = math.degrees(math.acos(float(np.clip(d_out @ d_in, -1.0, 1.0))))
            if angle > cfg.corner_deg:
                note = f"a turn of {angle:.0f} deg between segments {i} and {i + 1}, not taken as a corner"
                for k in (i, i + 1):
                    doubts[k] = f"{doubts[k]}; {note}" if doubts[k] else note

    segments = []
    for i, pc in enumerate(pieces):
        src = q_src[pc.idx]
        s_mm = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q[pc.idx], axis=0), axis=1))])
        y0, y1 = _orientation_ends(x[src, 3:], s_mm)
        sigma = math.nan
        if cov_mm2 is not None:
            c = np.asarray(cov_mm2, dtype=float)[src]
            tr = np.trace(c, axis1=1, axis2=2)
            if np.all(np.isfinite(tr)):
                sigma = math.sqrt(float(np.mean(tr)))
        seg_outliers = tuple(o for o in outliers if src[0] <= o <= src[-1])
        common = dict(first=int(src[0]), last=int(src[-1]), start_mm=tuple(map(float, starts[i])),
                      end_mm=tuple(map(float, ends[i])), start_ypr_deg=tuple(map(float, y0)),
                      end_ypr_deg=tuple(map(float, y1)), residual_rms_mm=pc.rms, residual_max_mm=pc.max,
                      points=len(pc.idx), outliers=seg_outliers, sigma_mm=sigma, doubt=doubts[i])
        if pc.kind == "line":
            segments.append(Segment("line", **common))
        else:
            f: ArcFit = pc.fit
            segments.append(Segment("arc", **common, centre_mm=tuple(map(float, f.centre_mm)),
                                    normal=tuple(map(float, f.normal)), radius_mm=float(f.radius_mm),
                                    sweep_deg=float(math.degrees(f.sweep_rad))))
    dwells = tuple(Dwell(tuple(map(float, p[a:b + 1].mean(axis=0))), int(a), int(b), float(t[b] - t[a]))
                   for a, b in dwell_runs)
    return Seam(tuple(segments), tuple(corners), dwells, tuple(sorted(outliers)), noise, cfg, len(x), dict(meta or {}),
                tuple(sorted(set(corner_cut))))


def sample_segment(seg: Segment, step_mm: float = 1.0) -> np.ndarray:
    """(k, 3) points along a segment, at most ``step_mm`` apart, ends included."""
    n = max(2, int(math.ceil(seg.length_mm / step_mm)) + 1)
    return seg.points_at(np.linspace(0.0, 1.0, n))


def distance_to_seam(seam: Seam, p_mm: np.ndarray) -> np.ndarray:
    """(N,) distance (mm) of each of (N, 3) points to the nearest segment of the seam (a
    line segment between its ends; an arc between its ends)."""
    p = np.atleast_2d(np.asarray(p_mm, dtype=float))
    best = np.full(len(p), np.inf)
    for seg in seam.segments:
        a, b = np.array(seg.start_mm), np.array(seg.end_mm)
        if seg.kind == "line":
            d = b - a
            L2 = float(d @ d)
            s = np.clip(((p - a) @ d) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(p))
            dist = np.linalg.norm(p - (a + s[:, None] * d), axis=1)
        else:
            c, nrm, u, v = seg.arc_basis()
            r = p - c
            h = r @ nrm
            ang = np.mod(np.arctan2(r @ v, r @ u), 2 * math.pi)
            inside = ang <= math.radians(seg.sweep_deg)
            rho = np.linalg.norm(r - np.outer(h, nrm), axis=1)
            on_arc = np.hypot(h, rho - seg.radius_mm)
            to_ends = np.minimum(np.linalg.norm(p - a, axis=1), np.linalg.norm(p - b, axis=1))
            dist = np.where(inside, on_arc, to_ends)
        best = np.minimum(best, dist)
    return best
