"""Blob checks: is each source of a FULL measurement seen whole? (issue 18, item 3)

A source partly covered (a cable, the operator's glove, a weld spatter shield) or merged
with something bright (a reflection, a lamp) still gives a blob, but its centre is not the
source's: 30 % covered moves it ~0.26 source radii (~1 px at 600 mm), which biases G by
~0.2 mm while everything else looks fine. Once the three sources are paired and named
(FULL) the measured pose predicts what each blob must look like, so each one is compared
with its prediction and with the others:

* **brightness** (``flux``): a disc of radius r seen through a view covers the ellipse
  ``J (s, t)``, ``J = d(u, v)/d(s, t)`` (the projection's Jacobian times the disc's
  in-plane axes, in radii: :func:`humanpt.geometry.projection_jacobian`), so its flux is
  ``radiance x gain_view x pi |det J|``. The flux per predicted pixel ``q`` is the same
  for the three sources of one view (the view's gain divides out: each view is compared
  with its own median). A source's **brightness ratio** is the geometric mean over its two
  views of ``q / median(q)``: a covered source has less (~1 - the covered fraction), a
  merged one more.
* **agreement of the two views**: ``log(q_right / q_left)`` of a source against the median
  of the three sources (the mirrors' gain ratio divides out): something in front of one
  view only, or a reflection touching one view's blob, breaks it.
* **shape**: the blob's second moments ``M`` (intensity-weighted; the paper method: its
  binary shape's) minus the predicted disc's ``J J^T / 4`` leave what the optics add -
  the blur, blooming along the columns, motion blur - which all six blobs share, so the
  median of the six rests is taken off too; the **anisotropy** of what remains,
  ``sqrt(((D_uu - D_vv)/2)^2 + D_uv^2)`` in units of the disc's own variance
  ``|det J| / 4``, grows when a straight edge cuts the disc or a neighbour touches it.

A source is **degraded** when a figure is off its ideal (brightness 1, view ratio 0,
anisotropy 0) by more than ``sqrt(tol^2 + (noise_k sd)^2)``: ``tol`` (``flux_tol``,
``view_tol``, ``shape_tol``) for what the model leaves out (the sources' angular
fall-off, the lens distortion, pixel sampling), ``sd`` the figure's SD from the image's
background noise (its histogram's sigma over the blob's aperture and over the local
background ring: the weighted method's :class:`~humanpt.perception.blobs.Blobs` ``noise``),
so that far, faint blobs are not flagged for their noise. The paper method measures
binary areas and shapes (pixel locking, no noise figure): its limits are ``tol_factor``
(``PerceptionConfig.degraded_paper_factor``) times wider. The references are medians of three, so one bad source is
found; two sources covered alike make the third look too bright (it is flagged instead:
still not silently trusted, but the wrong one).

What then (``degraded_policy``):

* ``rebuild`` (default): the degraded source's point is rebuilt from the two others and the
  target model - it must lie on the circle of points at the model's distances from them,
  and only its angle on that circle (the triangle's rotation about the other two's line)
  is taken from the measurement. A straight cover in the source's plane moves the
  measured point within the TOB plane, which changes neither that angle nor anything
  else of the rebuilt point: the pose keeps its precision (status FULL). With two or
  more degraded sources: as ``exclude``.
* ``exclude``: the degraded sources' pairs are dropped; the rest is a POSITION_ONLY
  measurement (LOST when nothing is left).
* ``keep``: flagged only, measured as before.

Only FULL measurements are checked: with fewer sources there is no pose to predict the
blobs from and no majority to compare with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from humanpt.geometry import (
    GeometryError,
    PsvsParams,
    TargetModel,
    projection_jacobian,
    tob_frame_from_points,
)

from .blobs import Blobs
from .config import POLICIES
from .correspondence import FULL, LOST, POSITION_ONLY, Match

__all__ = ["SOURCE_NAMES", "POLICIES", "CheckSettings", "SourceCheck", "check_sources",
           "apply_policy", "rebuild_point"]

SOURCE_NAMES = "ABC"


@dataclass(frozen=True)
class CheckSettings:
    """Limits of the blob checks (see :class:`humanpt.perception.PerceptionConfig`)."""

    flux_tol: float = 0.05
    view_tol: float = 0.05
    shape_tol: float = 0.15
    noise_k: float = 5.0
    tol_factor: float = 1.0  # every limit times this (the paper method's paper_factor)

    def __post_init__(self) -> None:
        # (3 checks, 1): the squared tolerances, computed once
        tol2 = np.array([[self.flux_tol], [self.view_tol], [self.shape_tol]]) ** 2
        tol2.setflags(write=False)
        object.__setattr__(self, "tol2", tol2)
        object.__setattr__(self, "tol2_flat", np.ascontiguousarray(tol2.ravel()))


@dataclass(frozen=True)
class SourceCheck:
    """The checks of one FULL measurement, per source A, B, C (arrays (3,)).

    ``brightness`` ratio to the median source (1 = as bright as its size predicts);
    ``view_log_ratio`` log(q_right / q_left) minus the median source's; ``anisotropy``
    the larger of the two views' (dimensionless); ``degraded`` the flagged sources
    (indices 0 = A, 1 = B, 2 = C, ascending); ``reason`` one line for a person ("" when
    nothing is flagged); ``sd`` (3 checks, 3 sources) the background noise's SDs of the
    three figures (0 for the paper method); ``limits`` (3 checks, 3 sources) what each
    figure may differ from its ideal (1, 0, 0)."""

    brightness: np.ndarray
    view_log_ratio: np.ndarray
    anisotropy: np.ndarray
    degraded: tuple[int, ...]
    reason: str
    sd: np.ndarray | None = None
    limits: np.ndarray | None = None


_NO_NOISE = np.zeros((3, 2, 2))


def _disc_jacobians(params: PsvsParams, match: Match, radius_mm: float) -> np.ndarray:
    """(3, 2, 2, 2): per source A, B, C and view (right, left) ``d(u, v)/d(s, t)`` of the
    source's disc ((s, t) in radii along the TOB's u and v axes, camera frame), px. The
    lens distortion is left out (it scales neighbouring blobs alike)."""
    axes = match.camera_T_tob[:3, :2] * radius_mm  # (3, 2): the disc's in-plane axes, mm
    views = np.array([projection_jacobian(cam, match.camera_p_mm)
                      for cam in (params.right_camera, params.left_camera)])  # (2, 3, 2, 3)
    return (views @ axes).swapaxes(0, 1)


def check_sources(
    blobs: Blobs, match: Match, params: PsvsParams, model: TargetModel, s: CheckSettings
) -> SourceCheck | None:
    """The checks of a FULL ``match`` of ``blobs`` (module docstring); None when there is
    nothing to check (not FULL, or the detector gave no flux and moments)."""
    if match.status != FULL or match.camera_T_tob is None or blobs.flux_dn is None:
        return None
    from .weighted import kernels

    jac = _disc_jacobians(params, match, 0.5 * model.source_diameter_mm)  # (3, 2, 2, 2)
    idx = match.pairs  # (3, 2) right, left blob of A, B, C
    noise = blobs.noise
    # the figures, their SDs and limits in one compiled call (kernels.source_figures)
    brightness, view_log_ratio, anisotropy, sd, limits = kernels().source_figures(
        np.ascontiguousarray(jac), np.ascontiguousarray(blobs.flux_dn[idx], dtype=float),
        np.ascontiguousarray(blobs.moments_px2[idx], dtype=float),
        _NO_NOISE if noise is None else np.ascontiguousarray(noise[idx], dtype=float), noise is not None,
        s.tol2_flat, float(s.noise_k), float(s.tol_factor))
    reasons = []
    degraded = []
    for k, (b, v, a, (lim_b, lim_v, lim_a)) in enumerate(zip(
            brightness.tolist(), view_log_ratio.tolist(), anisotropy.tolist(), limits.T.tolist(), strict=True)):
        why = []
        if not abs(b - 1.0) <= lim_b:  # (NaN fails too)
            more = " (merged?)" if b > 1.0 else ""
            why.append(f"{100.0 * b:.0f} % of its expected brightness{more} "
                       f"(±{100.0 * lim_b:.0f} % allowed)")
        if not abs(v) <= lim_v:
            why.append(f"its two views differ by {100.0 * (math.exp(v) - 1.0):+.0f} % "
                       f"(log ratio {v:+.2f}, {lim_v:.2f} allowed)")
        if not a <= lim_a:
            why.append(f"shape off its ellipse by {a:.2f} ({lim_a:.2f} allowed)")
        if why:
            degraded.append(k)
            reasons.append(f"{SOURCE_NAMES[k]}: " + ", ".join(why))
    return SourceCheck(brightness, view_log_ratio, anisotropy, tuple(degraded), "; ".join(reasons),
                       sd, limits)


def rebuild_point(p_mm: np.ndarray, k: int, model: TargetModel) -> np.ndarray:
    """Source ``k``'s point (3,) rebuilt from the other two of ``p_mm`` (3, 3) rows A, B, C
    (mm, any frame) and the model's sides: on the circle of points at the model's distances
    from them, at the measured point's angle about their line. Raises
    :class:`GeometryError` when the other two are too close or the measured point lies on
    their line."""
    i, j = [n for n in range(3) if n != k]
    sides = model.sides_mm  # |AB|, |BC|, |CA|
    dist = {(0, 1): sides[0], (1, 2): sides[1], (0, 2): sides[2]}
    r_i = float(dist[tuple(sorted((i, k)))])  # model |P_i P_k|
    r_j = float(dist[tuple(sorted((j, k)))])
    pi, pj, pk = p_mm[i], p_mm[j], p_mm[k]
    axis = pj - pi
    d = float(np.linalg.norm(axis))
    if d < 1e-6:
        raise GeometryError("cannot rebuild a source: the other two coincide")
    axis = axis / d
    along = (d * d + r_i * r_i - r_j * r_j) / (2.0 * d)  # the foot of k on the line, from i
    height = math.sqrt(max(r_i * r_i - along * along, 0.0))
    out = (pk - pi) - float(np.dot(pk - pi, axis)) * axis
    n = float(np.linalg.norm(out))
    if n < 1e-6:
        raise GeometryError("cannot rebuild a source: its measurement lies on the others' line")
    return pi + along * axis + height * out / n


def apply_policy(match: Match, check: SourceCheck | None, policy: str, model: TargetModel) -> Match:
    """The measurement after ``policy`` (module docstring) for the degraded sources."""
    if check is None or not check.degraded or policy == "keep":
        return match
    if policy == "rebuild" and len(check.degraded) == 1:
        k = check.degraded[0]
        p = np.array(match.camera_p_mm, dtype=float)
        try:
            p[k] = rebuild_point(p, k, model)
            frame = tob_frame_from_points(p[0], p[1], p[2])
        except GeometryError:
            pass  # fall through to exclude
        else:
            return replace(match, camera_p_mm=p, camera_T_tob=frame,
                           quality=match.quality * 2.0 / 3.0)
    keep = [k for k in range(3) if k not in check.degraded]
    if not keep:
        return Match(np.zeros((0, 2), int), np.zeros(0), np.zeros((0, 3)), None, LOST, 0.0)
    return Match(match.pairs[keep], match.residual_px[keep], match.camera_p_mm[keep], None,
                 POSITION_ONLY, match.quality * len(keep) / 3.0)
