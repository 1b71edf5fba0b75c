"""The driver tip (Section 4.1): the controller's pivot calibration (eq. (10)-(13) and a
least-squares pivot fit, :mod:`humanpt.geometry.calibration`) reports its result as the
JSON of a ``calibration_done`` event; this turns it into the rig's ``[tip]``."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.rig import Calibration, Rig, Tip

__all__ = ["TipResult", "tip_result_from_event", "apply_to_rig"]


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
                     None if paper is None else tuple(float(v) for v in paper))


def apply_to_rig(rig: Rig, result: TipResult, date: str) -> Rig:
    """``rig`` with its ``[tip]`` replaced by ``result`` (method ``pivot``)."""
    note = f"{result.samples} poses pivoting on the tip, residual RMS {result.residual_rms_mm:.3f} mm"
    return dataclasses.replace(rig, tip=Tip(result.tob_t_tip_mm, Calibration(
        method="pivot", date=date, note=note, sigma={"tob_t_tip_mm": round(result.sigma_mm, 6)})))
