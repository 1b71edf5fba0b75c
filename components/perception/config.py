"""Configuration of the perception component (section ``[perception]``).

Live parameters (``humanpt param perception KEY=VALUE``, or a ``param`` input): ``method``,
``threshold``, ``invert``, ``mask``, ``track_roi``, the blob checks' ``check_blobs``,
``degraded_*`` (but ``degraded_clear_frames``). Everything else is fixed at start.

Brightness is in DN (grey levels of an 8-bit image; a mono16 image is scaled to 8 bits
first). Image coordinates are pixels of the complex image (u right, v down, pixel centres at
integers). Lengths are mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

from humanpt.geometry import TRIANGULATION_METHODS
from humanpt.runtime.config import Range, live

__all__ = ["PerceptionConfig", "METHODS"]

METHODS = ("weighted", "paper")
POLICIES = ("rebuild", "exclude", "keep")


def _check(owner: str, name: str, value, *, positive=False, nonneg=False, integer=False):
    if integer:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{owner}.{name} must be an integer, got {value!r}")
    elif isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{owner}.{name} must be a finite number, got {value!r}")
    if positive and not value > 0:
        raise ValueError(f"{owner}.{name} must be > 0, got {value}")
    if nonneg and not value >= 0:
        raise ValueError(f"{owner}.{name} must be >= 0, got {value}")


@dataclass(frozen=True)
class PerceptionConfig:
    """Perception: complex image -> tob measurement (README.md has the table).

    Run-time parameters: ``method`` (``"weighted"``, the default method, or ``"paper"``, the
    reference method of Section 4), ``threshold`` (T, DN), ``invert`` (the sources are darker
    than the background: work on 255 - I), ``mask`` (rectangles ``[u, v, width, height]``
    in px whose pixels are ignored), ``track_roi`` (measure windows around the last FULL
    measurement's blobs first, ``roi_margin_px`` beyond the largest blob).

    The PSVS and the target come from the rig (``[runtime] rig``,
    :class:`humanpt.geometry.rig.Rig`), not from here.  The working depth range
    ``min_depth_mm`` .. ``max_depth_mm`` (z of the sources in the camera frame) and the
    ``triangulation`` of the weighted method (the paper method always uses eq. (4)).
    """

    method: Literal["weighted", "paper"] = live("weighted", "weighted (default) or paper")
    threshold: Annotated[float, Range(0, 255, "DN")] = live(60.0, "binarisation threshold T (DN)")
    invert: bool = live(False, "sources darker than the background: use 255 - I")
    mask: tuple[tuple[Annotated[int, Range(0, 20_000, "px")], Annotated[int, Range(0, 20_000, "px")], Annotated[int, Range(0, 20_000, "px")], Annotated[int, Range(0, 20_000, "px")]], ...] = live(
        (), "rectangles [u, v, width, height] (px) to ignore"
    )
    track_roi: bool = live(True, "search around the last measurement first")
    roi_margin_px: Annotated[int, Range(0, 20000, "px")] = 40
    # geometry (the PSVS and the target: the rig)
    min_depth_mm: Annotated[float, Range(1, 1e5, "mm")] = 200.0
    max_depth_mm: Annotated[float, Range(1, 1e5, "mm")] = 2000.0
    triangulation: Literal["eq4", "eq2", "lsq"] = "eq4"
    # paper method
    paper_cross_px: tuple[Annotated[int, Range(1, 1000, "px")], ...] = (9, 5)
    paper_scanline_tol_px: Annotated[float, Range(0, 1000, "px")] = 3.0
    # weighted method: detection and shape checks
    noise_k: Annotated[float, Range(0, 1000, "noise SDs")] = 8.0
    aperture_pad_px: Annotated[float, Range(0, 1000, "px")] = 3.0
    min_area_px: Annotated[int, Range(1, 10000000, "px")] = 4
    max_area_px: Annotated[int, Range(1, 10000000, "px")] = 3000
    max_elongation: Annotated[float, Range(1, 1000, "")] = 4.0
    min_contrast_dn: Annotated[float, Range(0, 255, "DN")] = 20.0
    size_ratio_range: tuple[Annotated[float, Range(0.01, 100, "")], Annotated[float, Range(0.01, 100, "")]] = (0.5, 1.8)
    max_blobs: Annotated[int, Range(3, 10000, "blobs")] = 24
    # weighted method: correspondence
    epipolar_tol_px: Annotated[float, Range(0, 1000, "px")] = 2.0
    epipolar_sigma_px: Annotated[float, Range(1e-6, 1000, "px")] = 0.05
    side_sigma_mm: Annotated[float, Range(1e-6, 1000, "mm")] = 0.5
    max_area_ratio: Annotated[float, Range(1, 1000, "")] = 2.5
    # blob checks (issue 18): is each source of a FULL measurement seen whole? (checks.py)
    check_blobs: bool = live(True, "check each source's blobs against the measured pose")
    degraded_policy: Literal["rebuild", "exclude", "keep"] = live(
        "rebuild", "a degraded source: rebuilt from the others (rebuild), dropped (exclude) or kept (keep)")
    degraded_flux_tol: Annotated[float, Range(0, 1, "fraction")] = live(
        0.05, "allowed brightness difference of a source from the others (plus the noise's)")
    degraded_view_tol: Annotated[float, Range(0, 10, "log ratio")] = live(
        0.05, "allowed brightness difference of a source's two views (plus the noise's)")
    degraded_shape_tol: Annotated[float, Range(0, 100, "disc variances")] = live(
        0.15, "allowed anisotropy of a blob beyond its predicted ellipse (plus the noise's)")
    degraded_noise_k: Annotated[float, Range(0, 100, "noise SDs")] = live(
        5.0, "the noise's allowance: this many SDs of the background noise's effect")
    degraded_paper_factor: Annotated[float, Range(1, 100, "")] = live(
        3.5, "the paper method's limits are this many times wider (binary areas and shapes)")
    degraded_clear_frames: Annotated[int, Range(1, 100000, "measurements")] = 5
    # bad images
    max_saturated_fraction: Annotated[float, Range(0, 1, "")] = 0.25
    # a paired blob with more aperture pixels at full scale (255) than this: saturated
    saturated_blob_px: Annotated[int, Range(0, 1000000, "px")] = 3
    # mirror drift watch: the running median of v_L - v_R of FULL measurements (rig model)
    drift_warn_px: Annotated[float, Range(0.01, 1000, "px")] = 0.5
    drift_window: Annotated[int, Range(1, 100000, "measurements")] = 30

    def __post_init__(self) -> None:
        own = "perception"
        if self.method not in METHODS:
            raise ValueError(f"{own}.method must be one of {METHODS}, got {self.method!r}")
        _check(own, "threshold", self.threshold, nonneg=True)
        if self.threshold >= 255:
            raise ValueError(f"{own}.threshold must be below 255 DN, got {self.threshold}")
        if not isinstance(self.invert, bool) or not isinstance(self.track_roi, bool):
            raise ValueError(f"{own}.invert and track_roi must be true or false")
        object.__setattr__(self, "mask", tuple(tuple(r) for r in self.mask))
        for rect in self.mask:
            if len(rect) != 4 or not all(
                isinstance(x, int) and not isinstance(x, bool) for x in rect
            ):
                raise ValueError(
                    f"{own}.mask: a rectangle is [u, v, width, height] (integers), got {rect!r}"
                )
            if rect[2] <= 0 or rect[3] <= 0:
                raise ValueError(
                    f"{own}.mask: rectangle {list(rect)} has no area (width, height > 0)"
                )
        _check(own, "roi_margin_px", self.roi_margin_px, nonneg=True, integer=True)
        _check(own, "min_depth_mm", self.min_depth_mm, positive=True)
        _check(own, "max_depth_mm", self.max_depth_mm, positive=True)
        if not self.min_depth_mm < self.max_depth_mm:
            raise ValueError(f"{own}: min_depth_mm must be below max_depth_mm")
        if self.triangulation not in TRIANGULATION_METHODS:
            raise ValueError(f"{own}.triangulation must be one of {TRIANGULATION_METHODS}")
        crosses = tuple(self.paper_cross_px)
        if not crosses or any(
            isinstance(c, bool) or not isinstance(c, int) or c < 3 or c % 2 == 0 for c in crosses
        ):
            raise ValueError(
                f"{own}.paper_cross_px must be odd sizes >= 3 (e.g. [9, 5]), got {crosses}"
            )
        object.__setattr__(self, "paper_cross_px", crosses)
        for name in (
            "paper_scanline_tol_px",
            "noise_k",
            "aperture_pad_px",
            "epipolar_tol_px",
            "epipolar_sigma_px",
            "side_sigma_mm",
            "min_contrast_dn",
        ):
            _check(own, name, getattr(self, name), positive=name != "noise_k", nonneg=True)
        for name in ("min_area_px", "max_area_px", "max_blobs"):
            _check(own, name, getattr(self, name), positive=True, integer=True)
        if self.min_area_px > self.max_area_px:
            raise ValueError(f"{own}: min_area_px must not exceed max_area_px")
        if self.max_blobs < 2 or self.max_blobs > 64:
            raise ValueError(f"{own}.max_blobs must be within 2 and 64, got {self.max_blobs}")
        _check(own, "max_elongation", self.max_elongation)
        _check(own, "max_area_ratio", self.max_area_ratio)
        if self.max_elongation < 1 or self.max_area_ratio < 1:
            raise ValueError(f"{own}: max_elongation and max_area_ratio must be >= 1")
        lo, hi = self.size_ratio_range
        _check(own, "size_ratio_range", lo, positive=True)
        _check(own, "size_ratio_range", hi, positive=True)
        if not lo < 1 < hi:
            raise ValueError(f"{own}.size_ratio_range must bracket 1, got {self.size_ratio_range}")
        if not isinstance(self.check_blobs, bool):
            raise ValueError(f"{own}.check_blobs must be true or false")
        if self.degraded_policy not in POLICIES:
            raise ValueError(f"{own}.degraded_policy must be one of {POLICIES}, got {self.degraded_policy!r}")
        for name in ("degraded_flux_tol", "degraded_view_tol", "degraded_shape_tol", "degraded_noise_k"):
            _check(own, name, getattr(self, name), nonneg=True)
        if self.degraded_flux_tol >= 1:
            raise ValueError(f"{own}.degraded_flux_tol must be below 1, got {self.degraded_flux_tol}")
        _check(own, "degraded_paper_factor", self.degraded_paper_factor, positive=True)
        if self.degraded_paper_factor < 1:
            raise ValueError(f"{own}.degraded_paper_factor must be >= 1, got {self.degraded_paper_factor}")
        _check(own, "degraded_clear_frames", self.degraded_clear_frames, positive=True, integer=True)
        _check(own, "max_saturated_fraction", self.max_saturated_fraction, positive=True)
        _check(own, "saturated_blob_px", self.saturated_blob_px, nonneg=True, integer=True)
        _check(own, "drift_warn_px", self.drift_warn_px, positive=True)
        _check(own, "drift_window", self.drift_window, positive=True, integer=True)
        if self.max_saturated_fraction > 1:
            raise ValueError(f"{own}.max_saturated_fraction must be in (0, 1]")
