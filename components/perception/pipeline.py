"""One complex image -> blobs -> pairs, points, target frame, for either method.

:class:`Perception` holds what follows from a :class:`PerceptionConfig` and the rig
(:class:`humanpt.geometry.rig.Rig`: PSVS parameters, target model; plus the mask image and
the correspondence settings) and measures prepared images - detection, correspondence, the
blob checks and their policy (:mod:`humanpt.perception.checks`); the core
(:mod:`humanpt.perception.core`) adds the message plumbing, the region of interest and
the events. Benchmarks and tests use it directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.rig import Rig

from .blobs import EMPTY, Blobs, Region, clip_region, full_region, windows_around
from .checks import CheckSettings, SourceCheck, apply_policy, check_sources
from .config import PerceptionConfig
from .correspondence import Match, MatchSettings, match_scan_line, match_scored
from .image import mask_array
from .paper import detect_paper
from .weighted import detect_weighted

__all__ = ["Perception", "Result"]


@dataclass(frozen=True)
class Result:
    """``blobs`` (all accepted), ``match`` (what is published: after the blob checks'
    policy) and the ``region`` searched (u0, v0, u1, v1); ``check`` the blob checks of a
    FULL correspondence (None when not checked); ``found`` the correspondence before the
    policy (``match`` when nothing was changed)."""

    blobs: Blobs
    match: Match
    region: Region
    check: SourceCheck | None = None
    found: Match | None = None

    @property
    def paired(self) -> Match:
        """What the correspondence found (before the checks' policy)."""
        return self.match if self.found is None else self.found


class Perception:
    """The measuring part of the component, for one configuration (immutable)."""

    def __init__(self, config: PerceptionConfig, rig: Rig | None = None):
        self.config = config
        self.rig = Rig() if rig is None else rig
        self.params = self.rig.params()
        self.model = self.rig.target_model()
        self.size_px = self.params.image_size_px
        self.keep = mask_array(config.mask, self.size_px)
        self.settings = MatchSettings(
            params=self.params,
            model=self.model,
            min_depth_mm=config.min_depth_mm,
            max_depth_mm=config.max_depth_mm,
            epipolar_tol_px=config.epipolar_tol_px,
            epipolar_sigma_px=config.epipolar_sigma_px,
            side_sigma_mm=config.side_sigma_mm,
            max_area_ratio=config.max_area_ratio,
            size_ratio_range=config.size_ratio_range,
            triangulation=config.triangulation,
        )
        self.check_settings = CheckSettings(
            flux_tol=config.degraded_flux_tol,
            view_tol=config.degraded_view_tol,
            shape_tol=config.degraded_shape_tol,
            noise_k=config.degraded_noise_k,
            tol_factor=config.degraded_paper_factor if config.method == "paper" else 1.0,
        )
        # The largest half-extent a source can have: at the nearest working depth, seen by
        # the right camera, with the size tolerance.
        self.max_radius_px = (
            0.5
            * config.size_ratio_range[1]
            * self.params.a_u
            * self.model.source_diameter_mm
            / (config.min_depth_mm + self.params.baseline_mm / 2.0)
            + 2.0
        )
        # the tracking windows' histogram grid: as if packed side by side this far apart
        # (further than a blob's aperture window, 2 ceil(radius + pad + ring + 1) + 1, reaches)
        self.gap_px = 2 * math.ceil(self.max_radius_px + config.aperture_pad_px + 3.0) + 2

    @property
    def full_region(self) -> Region:
        return full_region(*self.size_px)

    def warm_up(self) -> Result:
        """Search, then track, a synthetic image of the target (each source a blurred spot
        where the rig's model projects it, the target square to the camera at the
        geometric mean of the working depths): on a fresh install this compiles the
        detector's kernels (numba: 10-20 s, once; then its disk cache loads them in ~0.3 s),
        so a live process does it before it says it is up rather than on its first image.
        Returns the tracking step's result (FULL on a rig whose model is consistent)."""
        from humanpt.geometry.psvs import project

        c = self.config
        depth_mm = math.sqrt(c.min_depth_mm * c.max_depth_mm)
        p_mm = self.model.source_positions_mm + (0.0, 0.0, depth_mm)
        uv_r, uv_l = project(self.params, p_mm)
        sigma_px = max(1.0, 0.25 * self.params.a_u * self.model.source_diameter_mm / depth_mm)
        width, height = self.size_px
        v, u = np.mgrid[0:height, 0:width]
        gray = np.full((height, width), 12.0)
        for cu, cv in np.vstack((uv_r, uv_l)):
            gray += 220.0 * np.exp(-((u - cu) ** 2 + (v - cv) ** 2) / (2.0 * sigma_px ** 2))
        gray = np.clip(np.rint(gray), 0, 255).astype(np.uint8)
        found = self.measure(gray)
        used = found.paired.pairs.ravel() if len(found.paired.pairs) else np.arange(len(found.blobs))
        return self.track(gray, found.blobs.uv_px[used], found.blobs.size_px[used])

    def detect(self, gray: np.ndarray, region: Region) -> Blobs:
        """The configured method's detector on ``region`` of a prepared image."""
        c = self.config
        if c.method == "paper":
            return detect_paper(gray, c.threshold, c.paper_cross_px, region)
        return self._detect_weighted(gray, region, self.keep)

    def _detect_weighted(self, gray, region, keep) -> Blobs:
        c = self.config
        return detect_weighted(
            gray,
            region,
            threshold=c.threshold,
            noise_k=c.noise_k,
            aperture_pad_px=c.aperture_pad_px,
            min_area_px=c.min_area_px,
            max_area_px=c.max_area_px,
            max_radius_px=self.max_radius_px,
            max_elongation=c.max_elongation,
            min_contrast_dn=c.min_contrast_dn,
            max_blobs=c.max_blobs,
            keep=keep,
            gap_px=self.gap_px,
        )

    def match(self, blobs: Blobs) -> Match:
        if self.config.method == "paper":
            return match_scan_line(blobs, self.settings, self.config.paper_scanline_tol_px)
        return match_scored(blobs, self.settings)

    def measure(self, gray: np.ndarray, region: Region | None = None) -> Result:
        """Detect and match in ``region`` (default: the whole image) of a prepared image
        (see :func:`humanpt.perception.image.prepare`)."""
        region = self.full_region if region is None else clip_region(region, *self.size_px)
        return self._finish(self.detect(gray, region), region)

    def _finish(self, blobs: Blobs, region: Region) -> Result:
        """Correspondence, blob checks and their policy on detected blobs."""
        match = self.match(blobs)
        if not self.config.check_blobs:
            return Result(blobs, match, region)
        check = check_sources(blobs, match, self.params, self.model, self.check_settings)
        checked = apply_policy(match, check, self.config.degraded_policy, self.model)
        return Result(blobs, checked, region, check, None if checked is match else match)

    def track(self, gray: np.ndarray, uv_px: np.ndarray, size_px: np.ndarray) -> Result:
        """Measure while tracking: only the windows around the predicted blobs (``uv_px``
        (k, 2) the last FULL measurement's centres, ``size_px`` (k,) their sizes), each
        ``roi_margin_px`` plus the largest blob's size around its blob, overlapping ones
        merged: the cost follows the blobs, not the image's size (:meth:`track_detect`,
        then the correspondence and the blob checks as :meth:`measure`). The caller
        searches the whole image (:meth:`measure`) when this is not FULL.
        ``Result.region``: the windows' bounding box."""
        return self._finish(*self.track_detect(gray, uv_px, size_px))

    def track_detect(self, gray: np.ndarray, uv_px: np.ndarray, size_px: np.ndarray) -> tuple[Blobs, Region]:
        """The detection step of :meth:`track`: (blobs, the windows' bounding box). The
        weighted method measures the windows in one call on the image's own pixels (same
        blobs, order and centres as a search of the image finds there); the paper method
        searches their bounding box (:meth:`roi_around`)."""
        if self.config.method == "paper":
            region = self.roi_around(uv_px, size_px)
            return self.detect(gray, region), region
        pad = self.config.roi_margin_px + float(np.max(size_px, initial=0.0))
        windows = windows_around(uv_px, pad, *self.size_px)
        if not windows:
            return EMPTY, (0, 0, 0, 0)
        blobs = self._detect_weighted(gray, windows, self.keep)
        if len(windows) == 1:
            return blobs, windows[0]
        box = np.array(windows)
        region = (int(box[:, 0].min()), int(box[:, 1].min()), int(box[:, 2].max()), int(box[:, 3].max()))
        return blobs, region

    def roi_around(self, uv_px: np.ndarray, blob_size_px: np.ndarray) -> Region:
        """The region of interest around centres (k, 2): their bounding box grown by
        ``roi_margin_px`` plus the largest blob's size."""
        pad = self.config.roi_margin_px + float(np.max(blob_size_px, initial=0.0))
        lo = np.floor(uv_px.min(axis=0) - pad).astype(int)
        hi = np.ceil(uv_px.max(axis=0) + pad).astype(int) + 1
        return clip_region((int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])), *self.size_px)
