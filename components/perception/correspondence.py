"""Which blob is which: left/right pairs, the three sources, the target frame.

In the complex image the two views are superimposed and nothing says whether a blob was
seen by the right or the left virtual camera. A pair (right i, left j) is possible when
the two centres satisfy the PSVS epipolar constraint (same scan line, up to the small
depth offset l of the left camera) and the disparity ``u_L - u_R`` is positive and within
the working depth range.

:func:`match_scored` (the default method) scores *every* way of picking three disjoint
pairs by a chi-square of

* the epipolar residuals (``epipolar_sigma_px``),
* the three triangle sides against the target model's (``side_sigma_mm``; sorted sides, so
  the labelling does not matter yet),
* the similarity of the two views' areas (a source is seen at the same size in both),
* the brightness: sources are the brightest things in the image, so a dimmer blob (a stray
  reflection, which is also blurred) costs more than a bright one,

after hard gates (epipolar residual <= ``epipolar_tol_px``, depth within
``min_depth_mm .. max_depth_mm``, blob size compatible with a source of the model's
diameter at the triangulated depth, sides within ``side_tolerance_mm``). The best triple
wins, so blobs that share a scan line or a stray reflection on one do not break the
pairing. With no valid triple, the best two pairs whose distance is one of the model's
sides, then the best single pair, give a position-only measurement.

:func:`match_scan_line` is the paper's pairing (:func:`humanpt.perception.paper
.pair_by_scan_line`) followed by the same triangulation and labelling.

Both name the three sources A, B, C with :func:`humanpt.geometry.label_sources` (Section 4)
and build ``camera_T_tob`` by eq. (7), (8). Quality: ``visible/3 * P(chi2_n >= chi2)``, the
chi-square probability of the residuals (epipolar residuals and side errors of the result,
``n`` terms) - 1 for a perfect fit, about 0.5 for residuals of the expected size, towards 0
for a bad fit.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import gammaincc

from humanpt.geometry import (
    GeometryError,
    PsvsParams,
    TargetModel,
    label_sources,
    tob_frame_from_points,
    triangulate,
    undistort_pixels,
)

from .blobs import Blobs
from .paper import pair_by_scan_line

__all__ = [
    "FULL",
    "POSITION_ONLY",
    "LOST",
    "MatchSettings",
    "Match",
    "ideal_pixels",
    "eq4_points_mm",
    "epipolar_residual_px",
    "disparity_range_px",
    "match_scored",
    "match_scan_line",
    "lost",
]

FULL, POSITION_ONLY, LOST = "full", "position_only", "lost"
_AREA_SIGMA = 0.3  # log area ratio of the two views of one source
_PEAK_SIGMA = 0.5  # log brightness ratio to the brightest accepted blob
_MAX_CANDIDATES = 40  # best candidate pairs kept: C(40, 3) = 9880 triples at most


@dataclass(frozen=True)
class MatchSettings:
    """What the correspondence step needs besides the blobs (see PerceptionConfig)."""

    params: PsvsParams
    model: TargetModel
    min_depth_mm: float = 200.0
    max_depth_mm: float = 2000.0
    epipolar_tol_px: float = 2.0
    epipolar_sigma_px: float = 0.05
    side_sigma_mm: float = 0.5
    max_area_ratio: float = 2.5
    size_ratio_range: tuple[float, float] = (0.5, 1.8)
    triangulation: str = "eq4"


@dataclass(frozen=True)
class Match:
    """The result for one image.

    ``pairs`` (k, 2) int: (right, left) indices into the blobs, ordered A, B, C when
    ``status`` is FULL; ``residual_px`` (k,): |epipolar residual|; ``camera_p_mm`` (k, 3):
    the triangulated points, camera frame, mm; ``camera_T_tob`` (4, 4), mm, when FULL;
    ``status`` FULL / POSITION_ONLY / LOST; ``quality`` in [0, 1]; ``side_error_mm``: largest
    |measured - model| side (NaN when no side was measured).
    """

    pairs: np.ndarray
    residual_px: np.ndarray
    camera_p_mm: np.ndarray
    camera_T_tob: np.ndarray | None
    status: str
    quality: float
    side_error_mm: float = math.nan

    @property
    def visible(self) -> int:
        return int(self.pairs.shape[0])


def lost() -> Match:
    return Match(np.zeros((0, 2), int), np.zeros(0), np.zeros((0, 3)), None, LOST, 0.0)


# --------------------------------------------------------------------------- geometry


def ideal_pixels(params: PsvsParams, uv_px: np.ndarray) -> np.ndarray:
    """Observed centres (n, 2) -> ideal (undistorted) pixels, the input of eq. (4)."""
    uv = np.asarray(uv_px, dtype=float).reshape(-1, 2)
    if params.has_distortion and len(uv):
        return undistort_pixels(uv, params.real_camera_matrix, params.dist_coeffs)
    return uv


def _offsets(params: PsvsParams, uv_r: np.ndarray, uv_l: np.ndarray):
    """Centred, de-skewed coordinates (du_R, dv_R, du_L, dv_L) of eq. (2)."""
    cr, cl = params.right_camera, params.left_camera
    dv_r = uv_r[..., 1] - cr.v0
    dv_l = uv_l[..., 1] - cl.v0
    du_r = uv_r[..., 0] - cr.u0 - cr.skew * dv_r / cr.a_v
    du_l = uv_l[..., 0] - cl.u0 - cl.skew * dv_l / cl.a_v
    return du_r, dv_r, du_l, dv_l


def eq4_points_mm(params: PsvsParams, uv_r: np.ndarray, uv_l: np.ndarray) -> np.ndarray:
    """Eq. (4) for many candidate pairs at once, ideal px (..., 2) -> (..., 3) mm, without
    the geometry library's checks (a non-positive disparity gives inf/NaN or z < 0, which
    the callers' depth gate removes)."""
    a_u, a_v = params.a_u, params.a_v
    b, m, l = params.baseline_mm, params.m_mm, params.l_mm
    du_r, dv_r, du_l, dv_l = _offsets(params, uv_r, uv_l)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (a_u * (b + m) + l * du_l) / (du_l - du_r) - b / 2.0
    x = (z + b / 2.0) * du_r / a_u + b / 2.0
    y = 0.5 * ((z + b / 2.0) * dv_r + (z + b / 2.0 - l) * dv_l) / a_v
    return np.stack([x, y, z], axis=-1)


def epipolar_residual_px(
    params: PsvsParams, uv_r: np.ndarray, uv_l: np.ndarray, z_mm: np.ndarray | None = None
) -> np.ndarray:
    """Signed epipolar residual (...,) in px of candidate pairs (ideal px): the two y
    equations of eq. (4) agree when ``dv_R = dv_L (z + b/2 - l)/(z + b/2)`` (the left
    camera sits l further forward), so the residual is ``dv_R - dv_L (z + b/2 - l)/(z +
    b/2)``. ``z_mm`` from eq. (4) when already known."""
    b, l = params.baseline_mm, params.l_mm
    _, dv_r, _, dv_l = _offsets(params, uv_r, uv_l)
    if z_mm is None:
        z_mm = eq4_points_mm(params, uv_r, uv_l)[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return dv_r - dv_l * (z_mm + b / 2.0 - l) / (z_mm + b / 2.0)


def disparity_range_px(params: PsvsParams, min_depth_mm: float, max_depth_mm: float):
    """(smallest, largest) disparity ``u_L - u_R`` (px) of a point at depth z in the
    working range, from eq. (4) with the point on the optical axis (the l term is a
    fraction of a pixel; 5 % slack on either side)."""
    b, m = params.baseline_mm, params.m_mm
    lo = params.a_u * (b + m) / (max_depth_mm + b / 2.0)
    hi = params.a_u * (b + m) / (min_depth_mm + b / 2.0)
    return 0.95 * lo, 1.05 * hi


# --------------------------------------------------------------------------- scoring


def _p_value(chi2: float, n: int) -> float:
    """P(chi2_n >= chi2): 1 for a perfect fit."""
    if n <= 0:
        return 1.0
    return float(gammaincc(0.5 * n, 0.5 * max(chi2, 0.0)))


def _sides(p: np.ndarray) -> np.ndarray:
    """Sorted side lengths (..., 3) of triangles (..., 3, 3)."""
    d = np.stack(
        [
            np.linalg.norm(p[..., 0, :] - p[..., 1, :], axis=-1),
            np.linalg.norm(p[..., 1, :] - p[..., 2, :], axis=-1),
            np.linalg.norm(p[..., 2, :] - p[..., 0, :], axis=-1),
        ],
        axis=-1,
    )
    return np.sort(d, axis=-1)


_COMBOS: dict[tuple[int, int], np.ndarray] = {}


def _combinations(n: int, k: int) -> np.ndarray:
    key = (n, k)
    c = _COMBOS.get(key)
    if c is None:
        c = np.array(list(itertools.combinations(range(n), k)), dtype=int).reshape(-1, k)
        if n <= 64:
            _COMBOS[key] = c
    return c


def _candidates(blobs: Blobs, uv: np.ndarray, s: MatchSettings):
    """Every (right i, left j) pair passing the gates: indices, |residual|, eq. (4) points,
    and its chi-square terms (epipolar + area + brightness)."""
    n = len(blobs)
    ii, jj = np.nonzero(~np.eye(n, dtype=bool))
    d_lo, d_hi = disparity_range_px(s.params, s.min_depth_mm, s.max_depth_mm)
    disparity = uv[jj, 0] - uv[ii, 0]
    keep = (
        (disparity >= d_lo)
        & (disparity <= d_hi)
        & (np.abs(uv[jj, 1] - uv[ii, 1]) <= 3 * s.epipolar_tol_px + 5)
    )
    ii, jj = ii[keep], jj[keep]
    p = eq4_points_mm(s.params, uv[ii], uv[jj])
    res = epipolar_residual_px(s.params, uv[ii], uv[jj], p[:, 2])
    z = p[:, 2]
    # the size a source of the model's diameter has at that depth (right camera)
    expected = s.params.a_u * s.model.source_diameter_mm / (z + s.params.baseline_mm / 2.0)
    lo, hi = s.size_ratio_range
    size_ok = np.ones(len(ii), bool)
    for k in (ii, jj):
        ratio = blobs.size_px[k] / expected
        size_ok &= (ratio >= lo) & (ratio <= hi)
    log_area = np.log(blobs.area_px[ii] / blobs.area_px[jj])
    keep = (
        np.isfinite(z)
        & (z >= s.min_depth_mm)
        & (z <= s.max_depth_mm)
        & (np.abs(res) <= s.epipolar_tol_px)
        & size_ok
        & (np.abs(log_area) <= math.log(s.max_area_ratio))
    )
    ii, jj, p, res, log_area = ii[keep], jj[keep], p[keep], res[keep], log_area[keep]
    peak = np.maximum(blobs.peak_dn, 1e-6)
    dim = np.log(peak.max() / peak) if n else peak
    chi2 = (
        (res / s.epipolar_sigma_px) ** 2
        + (log_area / _AREA_SIGMA) ** 2
        + ((dim[ii] ** 2 + dim[jj] ** 2) / _PEAK_SIGMA**2)
    )
    if len(chi2) > _MAX_CANDIDATES:
        best = np.sort(np.argsort(chi2, kind="stable")[:_MAX_CANDIDATES])
        ii, jj, p, res, chi2 = ii[best], jj[best], p[best], res[best], chi2[best]
    return ii, jj, np.abs(res), p, chi2


def _disjoint(blob_ids: np.ndarray) -> np.ndarray:
    """(T, m) blob indices -> (T,) True where no blob is used twice."""
    s = np.sort(blob_ids, axis=1)
    return ~np.any(s[:, 1:] == s[:, :-1], axis=1)


def match_scored(blobs: Blobs, s: MatchSettings) -> Match:
    """The default method's correspondence (module docstring): the best-scoring set of
    three disjoint pairs, else two, else one."""
    if len(blobs) < 2:
        return lost()
    uv = ideal_pixels(s.params, blobs.uv_px)
    if len(blobs) <= _SMALL_BLOBS:
        small = _candidates_small(blobs, uv, s)
        if small is not None and len(small[0]) <= _SMALL_PAIRS:
            return _best_small(blobs, uv, s, *small)
    ii, jj, res, p, chi2 = _candidates(blobs, uv, s)
    n_pairs = len(ii)
    if n_pairs == 0:
        return lost()
    model_sides = np.sort(np.array(s.model._sides_mm))
    tol = s.model.side_tolerance_mm
    if n_pairs >= 3:
        combos = _combinations(n_pairs, 3)
        ok = _disjoint(np.concatenate([ii[combos], jj[combos]], axis=1))
        combos = combos[ok]
        if len(combos):
            err = _sides(p[combos]) - model_sides  # (T, 3)
            ok = np.max(np.abs(err), axis=1) <= tol
            combos, err = combos[ok], err[ok]
            if len(combos):
                total = chi2[combos].sum(axis=1) + ((err / s.side_sigma_mm) ** 2).sum(axis=1)
                best = combos[int(np.argmin(total))]
                result = _finish(blobs, uv, ii[best], jj[best], s)
                if result is not None:
                    return result
    if n_pairs >= 2:
        combos = _combinations(n_pairs, 2)
        combos = combos[_disjoint(np.concatenate([ii[combos], jj[combos]], axis=1))]
        if len(combos):
            dist = np.linalg.norm(p[combos[:, 0]] - p[combos[:, 1]], axis=-1)
            err = np.min(np.abs(dist[:, None] - model_sides[None, :]), axis=1)
            ok = err <= tol
            combos, err = combos[ok], err[ok]
            if len(combos):
                total = chi2[combos].sum(axis=1) + (err / s.side_sigma_mm) ** 2
                best = combos[int(np.argmin(total))]
                return _finish(blobs, uv, ii[best], jj[best], s)
    best = int(np.argmin(chi2))
    return _finish(blobs, uv, ii[[best]], jj[[best]], s)


# A few blobs and candidate pairs (the usual image: the target's six views): the same
# search on plain floats. Every number is computed by the operations of the array code in
# the same order (sums of up to three terms in order, as np.sum does them; logarithms by
# np.log), so the result is the same; anything else goes through the array code.
_SMALL_BLOBS = 12
_SMALL_PAIRS = 8


def _candidates_small(blobs: Blobs, uv: np.ndarray, s: MatchSettings):
    """:func:`_candidates` as lists (ii, jj, |residual|, points, chi-square), or None when
    the array code has to run (more than ``_MAX_CANDIDATES`` pairs, non-finite scores)."""
    params = s.params
    cr, cl = params.right_camera, params.left_camera
    a_u, a_v, b, m, l = params.a_u, params.a_v, params.baseline_mm, params.m_mm, params.l_mm
    d_lo, d_hi = disparity_range_px(params, s.min_depth_mm, s.max_depth_mm)
    v_tol = 3 * s.epipolar_tol_px + 5
    lo, hi = s.size_ratio_range
    diameter = s.model.source_diameter_mm
    pts = uv.tolist()
    size = blobs.size_px.tolist()
    # _offsets of every blob seen as a right and as a left view
    off_r = [(u - cr.u0 - cr.skew * (v - cr.v0) / cr.a_v, v - cr.v0) for u, v in pts]
    off_l = [(u - cl.u0 - cl.skew * (v - cl.v0) / cl.a_v, v - cl.v0) for u, v in pts]
    kept = []
    for i, (ui, vi) in enumerate(pts):
        du_r, dv_r = off_r[i]
        for j, (uj, vj) in enumerate(pts):
            if i == j or not (d_lo <= uj - ui <= d_hi and abs(vj - vi) <= v_tol):
                continue
            du_l, dv_l = off_l[j]
            if du_l - du_r == 0.0:
                continue  # z not finite: the depth gate drops it
            z = (a_u * (b + m) + l * du_l) / (du_l - du_r) - b / 2.0
            if not (math.isfinite(z) and s.min_depth_mm <= z <= s.max_depth_mm):
                continue
            res = dv_r - dv_l * (z + b / 2.0 - l) / (z + b / 2.0)
            if not abs(res) <= s.epipolar_tol_px:
                continue
            expected = a_u * diameter / (z + b / 2.0)
            if not (lo <= size[i] / expected <= hi and lo <= size[j] / expected <= hi):
                continue
            x = (z + b / 2.0) * du_r / a_u + b / 2.0
            y = 0.5 * ((z + b / 2.0) * dv_r + (z + b / 2.0 - l) * dv_l) / a_v
            kept.append((i, j, res, (x, y, z)))
    if len(kept) > _MAX_CANDIDATES:
        return None
    ii = [k[0] for k in kept]
    jj = [k[1] for k in kept]
    log_area = np.log(blobs.area_px[ii] / blobs.area_px[jj]).tolist()
    peak = np.maximum(blobs.peak_dn, 1e-6)
    dim = np.log(peak.max() / peak).tolist()
    max_log = math.log(s.max_area_ratio)
    out = ([], [], [], [], [])
    for (i, j, res, p), la in zip(kept, log_area, strict=True):
        if not abs(la) <= max_log:
            continue
        t, a = res / s.epipolar_sigma_px, la / _AREA_SIGMA
        chi2 = t * t + a * a + (dim[i] * dim[i] + dim[j] * dim[j]) / _PEAK_SIGMA**2
        if not math.isfinite(chi2):
            return None
        for lst, v in zip(out, (i, j, abs(res), p, chi2), strict=True):
            lst.append(v)
    return out


def _dist(p: tuple, q: tuple) -> float:
    dx, dy, dz = p[0] - q[0], p[1] - q[1], p[2] - q[2]
    return math.sqrt(dx * dx + dy * dy + dz * dz)


def _best_small(blobs: Blobs, uv: np.ndarray, s: MatchSettings, ii, jj, res, p, chi2) -> Match:
    """:func:`match_scored` after :func:`_candidates_small` (the same choices: first best
    in the order of the array code's combinations)."""
    n_pairs = len(ii)
    if n_pairs == 0:
        return lost()
    m0, m1, m2 = sorted(s.model._sides_mm)
    tol, sigma = s.model.side_tolerance_mm, s.side_sigma_mm
    if n_pairs >= 3:
        best, best_total = None, math.inf
        for a, b, c in itertools.combinations(range(n_pairs), 3):
            if len({ii[a], ii[b], ii[c], jj[a], jj[b], jj[c]}) < 6:
                continue
            d0, d1, d2 = sorted((_dist(p[a], p[b]), _dist(p[b], p[c]), _dist(p[c], p[a])))
            e0, e1, e2 = d0 - m0, d1 - m1, d2 - m2
            if not max(abs(e0), abs(e1), abs(e2)) <= tol:
                continue
            t0, t1, t2 = e0 / sigma, e1 / sigma, e2 / sigma
            total = chi2[a] + chi2[b] + chi2[c] + (t0 * t0 + t1 * t1 + t2 * t2)
            if best is None or total < best_total:
                best, best_total = (a, b, c), total
        if best is not None:
            result = _finish(blobs, uv, [ii[k] for k in best], [jj[k] for k in best], s)
            if result is not None:
                return result
    if n_pairs >= 2:
        best, best_total = None, math.inf
        for a, b in itertools.combinations(range(n_pairs), 2):
            if len({ii[a], ii[b], jj[a], jj[b]}) < 4:
                continue
            dist = _dist(p[a], p[b])
            err = min(abs(dist - m0), abs(dist - m1), abs(dist - m2))
            if not err <= tol:
                continue
            t = err / sigma
            total = chi2[a] + chi2[b] + t * t
            if best is None or total < best_total:
                best, best_total = (a, b), total
        if best is not None:
            return _finish(blobs, uv, [ii[k] for k in best], [jj[k] for k in best], s)
    best = min(range(n_pairs), key=chi2.__getitem__)
    return _finish(blobs, uv, [ii[best]], [jj[best]], s)


def _eq4_rows(params: PsvsParams, uv: list, right, left) -> list | None:
    """:func:`humanpt.geometry.triangulate_eq4` of the pairs (right[k], left[k]) of ideal
    pixels ``uv`` (a list of (u, v)) in plain float arithmetic - its operations in the
    same order, so the same numbers - as a list of (x, y, z); None where it raises."""
    a_u, a_v, b, m, l = params.a_u, params.a_v, params.baseline_mm, params.m_mm, params.l_mm
    cr, cl = params.right_camera, params.left_camera
    zr, zl = cr.centre_mm[2], cl.centre_mm[2]
    h = b / 2.0
    num0 = a_u * (b + m)
    rows = []
    for i, j in zip(right, left, strict=True):
        ur, vr = uv[i]
        ul, vl = uv[j]
        dv_r = vr - cr.v0
        du_r = ur - cr.u0 - cr.skew * dv_r / cr.a_v
        dv_l = vl - cl.v0
        du_l = ul - cl.u0 - cl.skew * dv_l / cl.a_v
        den = du_l - du_r
        if not (math.isfinite(den) and abs(den) >= 1e-12):
            return None
        z = (num0 + l * du_l) / den - h
        x_right = (z + h) * du_r / a_u + h
        x_left = (z + h - l) * du_l / a_u - h - m
        y_right = (z + h) * dv_r / a_v
        y_left = (z + h - l) * dv_l / a_v
        if not (z - zr > 0 and z - zl > 0):
            return None
        rows.append((0.5 * (x_right + x_left), 0.5 * (y_right + y_left), z))
    return rows


def _finish(
    blobs: Blobs,
    uv: np.ndarray,
    right: np.ndarray,
    left: np.ndarray,
    s: MatchSettings,
    method: str | None = None,
) -> Match | None:
    """Triangulate the chosen pairs with the configured method, name A, B, C (three
    pairs), build the frame and the quality. None when three pairs cannot be labelled.

    Plain float arithmetic on these few numbers, in the order of the array formulas it
    replaces (:func:`epipolar_residual_px`, ``np.sum`` of three terms adds them in order),
    so the same numbers without numpy's per-call overhead."""
    method = method or s.triangulation
    uv_list = uv.tolist()
    right_l, left_l = np.asarray(right).tolist(), np.asarray(left).tolist()
    if method == "eq4":
        pts = _eq4_rows(s.params, uv_list, right_l, left_l)
        if pts is None:
            return None
    else:
        try:
            pts = triangulate(s.params, uv[right], uv[left], method=method, undistort=False)
        except GeometryError:
            return None
        pts = pts.tolist()
    params = s.params
    b, l = params.baseline_mm, params.l_mm
    v0r, v0l = params.right_camera.v0, params.left_camera.v0
    res = [
        abs(uv_list[i][1] - v0r - (uv_list[j][1] - v0l) * (z + b / 2.0 - l) / (z + b / 2.0))
        for (_, _, z), i, j in zip(pts, right_l, left_l, strict=True)
    ]
    if len(res) <= 3:  # np.sum adds up to three terms in order
        chi2 = 0.0
        for r in res:
            t = r / s.epipolar_sigma_px
            chi2 += t * t
    else:
        chi2 = float(np.sum((np.array(res) / s.epipolar_sigma_px) ** 2))
    pairs = list(zip(right_l, left_l, strict=True))
    if len(pts) == 3:
        try:
            lab = label_sources(s.model, np.array(pts))
        except GeometryError:
            return None
        order = lab.order
        p = lab.camera_p_abc_mm
        res = [res[k] for k in order]
        pairs = [pairs[k] for k in order]
        sigma = s.side_sigma_mm
        e0, e1, e2 = (a - m for a, m in zip(lab.sides_mm.tolist(), s.model._sides_mm, strict=True))
        t0, t1, t2 = e0 / sigma, e1 / sigma, e2 / sigma
        chi2 += t0 * t0 + t1 * t1 + t2 * t2
        try:
            frame = tob_frame_from_points(p[0], p[1], p[2])
        except GeometryError:
            return None
        quality = _p_value(chi2, 6)
        return Match(
            np.array(pairs), np.array(res), p, frame, FULL, quality, max(abs(e0), abs(e1), abs(e2))
        )
    p = np.array(pts)
    side_error = math.nan
    n_terms = len(pts)
    if len(pts) == 2:
        (x0, y0, z0), (x1, y1, z1) = pts
        dx, dy, dz = x0 - x1, y0 - y1, z0 - z1
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        side_error = min(abs(dist - m) for m in s.model._sides_mm)
        chi2 += (side_error / s.side_sigma_mm) ** 2
        n_terms += 1
    quality = len(pts) / 3.0 * _p_value(chi2, n_terms)
    return Match(np.array(pairs), np.array(res), p, None, POSITION_ONLY, quality, side_error)


def match_scan_line(blobs: Blobs, s: MatchSettings, scan_line_tol_px: float) -> Match:
    """The paper's correspondence (Section 4): pairs by scan line, points by eq. (4). Three
    pairs that can be named A, B, C give the frame; otherwise (fewer pairs, or a triangle
    that does not fit the model - the paper has no such check, a wrong pose would follow)
    the points are a position-only measurement."""
    if len(blobs) < 2:
        return lost()
    uv = ideal_pixels(s.params, blobs.uv_px)
    pairs = pair_by_scan_line(uv, scan_line_tol_px)
    if len(pairs) == 0:
        return lost()
    right, left = pairs[:, 0], pairs[:, 1]
    result = _finish(blobs, uv, right, left, s, method="eq4")
    if result is None and len(pairs) == 3:
        # not the target's triangle (or not labellable): report the points only
        try:
            p = triangulate(s.params, uv[right], uv[left], method="eq4", undistort=False)
        except GeometryError:
            return lost()
        res = np.abs(epipolar_residual_px(s.params, uv[right], uv[left], p[:, 2]))
        return Match(pairs, res, p, None, POSITION_ONLY, 0.0)
    return result if result is not None else lost()
