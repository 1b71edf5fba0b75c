"""The driver tip (Section 4.1): the controller's pivot calibration (eq. (10)-(13) and a
least-squares pivot fit, :mod:`humanpt.geometry.calibration`) reports its result as the
JSON of a ``calibration_done`` event; this turns it into the rig's ``[tip]``."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.rig import Calibration, Rig, Tip

__all__ = ["TipResult", "tip_result_from_event", "apply_to_rig", "pattern_centre_px", "pivot_point_from_views",
           "paper_result"]


@dataclass(frozen=True)
class TipResult:
    """``tob_t_tip_mm`` (3,): P in the TOB frame; ``sigma_mm``: its largest 1-sigma (from
    the fit's residuals); ``residual_rms_mm``: how far the tip strayed from one point
    over the samples; ``world_p_pivot_mm`` (3,): the pivot point the fit found;
    ``samples``: poses used; ``paper_tob_t_tip_mm``: eq. (13)'s result when P' was given."""

    tob_t_tip_mm: tuple[float, float, float]
    sigma_mm: float
    residual_rms_mm: float
    world_p_pivot_mm: tuple[float, float, float]
    samples: int
    paper_tob_t_tip_mm: tuple[float, float, float] | None = None
    paper_residual_rms_mm: float | None = None  # eq. (13)'s tip: how far it strays from P'


def tip_result_from_event(text: str, sigma_mm: float | None = None) -> TipResult:
    """The JSON text of the controller's ``calibration_done`` event -> TipResult.
    ``sigma_mm``: the fit's 1-sigma when known (the controller's rig has it), else the
    residual RMS over sqrt(samples / 3) (3 equations per pose)."""
    d = json.loads(text)
    n = int(d["samples"])
    rms = float(d["residual_rms_mm"])
    sigma = float(sigma_mm) if sigma_mm is not None else rms / np.sqrt(max(n / 3.0, 1.0))
    paper = d.get("paper_tob_t_tip_mm")
    return TipResult(tuple(float(v) for v in d["tob_t_tip_mm"]), sigma, rms,
                     tuple(float(v) for v in d["world_p_pivot_mm"]), n,
                     None if paper is None else tuple(float(v) for v in paper),
                     None if d.get("paper_residual_rms_mm") is None else float(d["paper_residual_rms_mm"]))


def apply_to_rig(rig: Rig, result: TipResult, date: str, method: str = "pivot") -> Rig:
    """``rig`` with its ``[tip]`` replaced by ``result`` (``method``: ``pivot``, the
    least-squares fit, or ``paper``, eq. (10)-(13))."""
    how = "eq. (12)-(13) on P' measured by the PSVS, " if method == "paper" else ""
    note = f"{how}{result.samples} poses pivoting on the tip, residual RMS {result.residual_rms_mm:.3f} mm"
    return dataclasses.replace(rig, tip=Tip(result.tob_t_tip_mm, Calibration(
        method=method, date=date, note=note, sigma={"tob_t_tip_mm": round(result.sigma_mm, 6)})))


def pattern_centre_px(image: np.ndarray, min_contrast_dn: float = 40.0) -> np.ndarray:
    """Section 4.1: the centre (u, v) px of a dark printed pattern (a circle or a square) on
    white paper in one view's grey image (the other view covered): the darkness-weighted
    centroid of the pixels darker than halfway between the paper (the image's 90th
    percentile) and the print (its darkest pixel); with the pattern's blur symmetric the edge adds
    no bias.  ValueError when nothing darker than ``min_contrast_dn`` below the paper is seen."""
    img = np.asarray(image, dtype=float)
    white, black = np.percentile(img, 90.0), float(img.min())
    if white - black < min_contrast_dn:
        raise ValueError(f"no pattern in the image (contrast {white - black:.0f} DN < {min_contrast_dn:g})")
    dark = np.clip(white - img, 0.0, None)
    dark[img > 0.5 * (white + black)] = 0.0
    v, u = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    total = dark.sum()
    return np.array([(u * dark).sum() / total, (v * dark).sum() / total])


def pivot_point_from_views(rig: Rig, world_T_flange_mm: np.ndarray, uv_right_px: np.ndarray,
                           uv_left_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (10)-(11): P' in the world (mm) from the pattern's centre seen in both views at N
    robot poses: each pair triangulated by the PSVS (eq. (4), the rig's model), carried to
    the world by the robot's pose and the rig's hand-eye, then averaged.  Returns (P' (3,),
    the per-pose points (N, 3)).  The observed pixels are undistorted first."""
    from humanpt.geometry.calibration import world_point_from_samples
    from humanpt.geometry.psvs import triangulate

    camera_p = triangulate(rig.params(), np.asarray(uv_right_px, dtype=float).reshape(-1, 2),
                           np.asarray(uv_left_px, dtype=float).reshape(-1, 2), method="eq4")
    return world_point_from_samples(np.asarray(world_T_flange_mm, dtype=float), rig.hand_eye.flange_T_camera_mm(),
                                    camera_p)


def paper_result(pivot_result: TipResult) -> TipResult:
    """The paper's eq. (13) result of a ``calibration_done`` given P' (``paper_tob_t_tip_mm``)
    as the tip; ValueError when the controller did not compute it."""
    if pivot_result.paper_tob_t_tip_mm is None:
        raise ValueError("the controller's result has no eq. (13) tip (no P' was given)")
    rms = pivot_result.paper_residual_rms_mm
    return dataclasses.replace(pivot_result, tob_t_tip_mm=pivot_result.paper_tob_t_tip_mm,
                               residual_rms_mm=pivot_result.residual_rms_mm if rms is None else rms)
