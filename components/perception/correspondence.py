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

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import gammaincc

from humanpt.geometry import (
    GeometryError,
    PsvsParams,
    TargetModel,
    eq4_points_mm,
    label_sources,
    parallel_pixels,
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

    def __post_init__(self) -> None:
        # What follows from the settings alone, computed once (not per image): the
        # disparity range, the model's sides (as given and sorted), the gates' limits.
        derived = {
            "disparity_px": disparity_range_px(self.params, self.min_depth_mm, self.max_depth_mm),
            "model_sides_mm": self.model.sides_mm,
            "sorted_sides_mm": np.sort(self.model.sides_mm),
            "log_max_area_ratio": math.log(self.max_area_ratio),
            "v_gate_px": 3 * self.epipolar_tol_px + 5,
        }
        d_lo, d_hi = derived["disparity_px"]
        lo, hi = self.size_ratio_range
        # the gates and sigmas in the order kernels.score_pairs reads them
        derived["gates"] = np.array([
            d_lo, d_hi, derived["v_gate_px"], self.params.a_u * self.model.source_diameter_mm,
            self.params.baseline_mm / 2.0, lo, hi, self.min_depth_mm, self.max_depth_mm, self.epipolar_tol_px,
            self.epipolar_sigma_px, derived["log_max_area_ratio"], _AREA_SIGMA, _PEAK_SIGMA,
            self.model.side_tolerance_mm, self.side_sigma_mm], dtype=float)
        for name, value in derived.items():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class Match:
    """The result for one image.

    ``pairs`` (k, 2) int: (right, left) indices into the blobs, ordered A, B, C when
    ``status`` is FULL; ``residual_px`` (k,): |epipolar residual|; ``camera_p_mm`` (k, 3):
    the triangulated points, camera frame, mm; ``camera_T_tob`` (4, 4), mm, when FULL;
    ``status`` FULL / POSITION_ONLY / LOST; ``quality`` in [0, 1]; ``side_error_mm``: largest
    |measured - model| side (NaN when no side was measured); ``eq4_residual_px`` (k,) the
    signed epipolar residuals (:func:`epipolar_residual_px` at eq. (4)'s depth) when the
    correspondence already computed them (None otherwise; the mirror drift watch uses them).
    """

    pairs: np.ndarray
    residual_px: np.ndarray
    camera_p_mm: np.ndarray
    camera_T_tob: np.ndarray | None
    status: str
    quality: float
    side_error_mm: float = math.nan
    eq4_residual_px: np.ndarray | None = None

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


def epipolar_residual_px(
    params: PsvsParams, uv_r: np.ndarray, uv_l: np.ndarray, z_mm: np.ndarray | None = None
) -> np.ndarray:
    """Signed epipolar residual (...,) in px of candidate pairs (ideal px): the two y
    equations of eq. (4) agree when ``dv_R = dv_L (z + b/2 - l)/(z + b/2)`` (the left
    camera sits l further forward), so the residual is ``dv_R - dv_L (z + b/2 - l)/(z +
    b/2)``. ``z_mm`` from eq. (4) when already known. Rotated virtual cameras (tilted
    mirrors in the rig): on the pixels mapped into the parallel cameras, as eq. (4)."""
    b, l = params.baseline_mm, params.l_mm
    if z_mm is None:
        z_mm = eq4_points_mm(params, uv_r, uv_l)[..., 2]
    dv_r = parallel_pixels(params.right_camera, uv_r)[..., 1] - params.right_camera.v0
    dv_l = parallel_pixels(params.left_camera, uv_l)[..., 1] - params.left_camera.v0
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


_PAIRS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _ordered_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) index arrays of the n (n - 1) ordered pairs of n blobs, i != j."""
    pairs = _PAIRS.get(n)
    if pairs is None:
        pairs = np.nonzero(~np.eye(n, dtype=bool))
        if n <= 64:
            _PAIRS[n] = pairs
    return pairs


def match_scored(blobs: Blobs, s: MatchSettings) -> Match:
    """The default method's correspondence (module docstring): the best-scoring set of
    three disjoint pairs, else two, else one. Every ordered pair's eq. (4) point and
    epipolar residual in one call each; the gates, the scores and the search over sets of
    pairs in one compiled call (:func:`humanpt.perception.kernels.score_pairs`)."""
    if len(blobs) < 2:
        return lost()
    from .weighted import kernels

    uv = ideal_pixels(s.params, blobs.uv_px)
    ii, jj = _ordered_pairs(len(blobs))
    uv_r, uv_l = uv[ii], uv[jj]
    p = eq4_points_mm(s.params, uv_r, uv_l)
    res = epipolar_residual_px(s.params, uv_r, uv_l, p[:, 2])
    index, _, three, two, one = kernels().score_pairs(
        *(np.ascontiguousarray(a, dtype=float) for a in (uv, blobs.size_px, blobs.area_px, blobs.peak_dn)),
        ii, jj, np.ascontiguousarray(p), np.ascontiguousarray(res), s.gates, s.sorted_sides_mm, _MAX_CANDIDATES)
    if one < 0:
        return lost()
    for best in (three, two):
        if best[0] >= 0:
            k = index[best]
            result = _finish(blobs, uv, ii[k], jj[k], s, p[k], res[k])
            if result is not None or len(best) == 2:
                return result
    k = index[[one]]
    return _finish(blobs, uv, ii[k], jj[k], s, p[k], res[k])


def _finish(
    blobs: Blobs,
    uv: np.ndarray,
    right: np.ndarray,
    left: np.ndarray,
    s: MatchSettings,
    eq4_p_mm: np.ndarray | None = None,
    eq4_residual_px: np.ndarray | None = None,
    method: str | None = None,
) -> Match | None:
    """Triangulate the chosen pairs with the configured method, name A, B, C (three
    pairs), build the frame and the quality. None when the pairs cannot be triangulated
    or three pairs cannot be labelled. ``eq4_p_mm``, ``eq4_residual_px``: the pairs'
    eq. (4) points and signed epipolar residuals when already known (the candidates'; they
    passed the depth gate, so they are in front of the cameras)."""
    method = method or s.triangulation
    right, left = np.asarray(right), np.asarray(left)
    signed = eq4_residual_px
    if method == "eq4" and eq4_p_mm is not None:
        p, res = eq4_p_mm, np.abs(eq4_residual_px)
    else:
        try:
            p = triangulate(s.params, uv[right], uv[left], method=method, undistort=False)
        except GeometryError:
            return None
        res = epipolar_residual_px(s.params, uv[right], uv[left], p[:, 2])
        if method == "eq4":
            signed = res
        res = np.abs(res)
    chi2 = float(np.dot(res, res)) / s.epipolar_sigma_px**2
    pairs = np.array((right, left)).T
    if len(p) == 3:
        try:
            lab = label_sources(s.model, p)
            frame = tob_frame_from_points(*lab.camera_p_abc_mm)
        except GeometryError:
            return None
        order = list(lab.order)
        e = (lab.sides_mm - s.model_sides_mm) / s.side_sigma_mm
        chi2 += float(np.dot(e, e))
        return Match(pairs[order], res[order], lab.camera_p_abc_mm, frame, FULL, _p_value(chi2, 6),
                     lab.side_error_mm, None if signed is None else signed[order])
    side_error = math.nan
    n_terms = len(p)
    if len(p) == 2:
        side_error = float(np.min(np.abs(np.linalg.norm(p[0] - p[1]) - s.model_sides_mm)))
        chi2 += (side_error / s.side_sigma_mm) ** 2
        n_terms += 1
    return Match(pairs, res, p, None, POSITION_ONLY, len(p) / 3.0 * _p_value(chi2, n_terms), side_error,
                 signed)


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
