"""The default detector: background-subtracted, intensity-weighted subpixel centroids with
shape checks.

1. Background and noise of the searched region from its grey-level histogram (median, and
   the median minus the 15.9th percentile as a one-sided robust sigma: the sources only
   occupy the top of the histogram).
2. Detection: pixels above ``max(T, background + noise_k * sigma)`` (so a brighter
   ambient raises the level by itself), 8-connected shapes (runs of such pixels joined by
   union-find; only rows whose maximum exceeds the level are scanned pixel by pixel; only
   the outermost shapes, as ``cv2.findContours``' ``RETR_EXTERNAL``). Shapes outside the
   area limits, touching the border of the searched region (a cut shape has a biased
   centre), or too large for a source at the nearest working depth are rejected.
3. Centre: in a circular aperture of radius ``max(width, height)/2 + aperture_pad_px``
   around the component - wide enough to take in the blurred edge that lies below the
   threshold - each pixel weighs ``I - b``, with ``b`` the mean of a 2-px ring just outside
   the aperture (local background, so a glow nearby does not pull the centre). The weights
   are not clipped at 0, so background noise averages out instead of adding a positive
   bias; the aperture is re-centred on the estimate twice so that it is symmetric about
   the result. Pixels of other shapes and masked pixels are left out. The sums over the
   aperture (count, grey levels, first and second moments about the window's centre pixel)
   are of integers, so exact.
4. Shape checks on the weighted moments: positive flux, peak at least ``min_contrast_dn``
   above the local background, major/minor axis ratio at most ``max_elongation``. Each
   blob's aperture pixels at full scale (255) are counted (``Blobs.saturated_px``): a
   clipped peak biases the centre, the core reports it.

Why weights and not the binary mean: the mean of thresholded pixel positions moves in
steps as pixels cross T (pixel locking, ~0.05-0.1 px for 8 px shapes); the weighted
centroid of a blurred, pixel-integrated spot has no such steps and its noise is set by the
photon and read noise only (a few thousandths of a pixel for the default twin).

Steps 1-4 run in one compiled call (:mod:`humanpt.perception.kernels`, numba): no per-shape
or per-blob Python, and a cost that follows the rows holding a shape and the blobs, not
the searched region's size.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .blobs import EMPTY, Blobs, Region

__all__ = ["background_and_noise", "detect_weighted"]

_HISTOGRAM_PX = 8000.0  # a region's histogram counts about this many pixels (a regular grid)
_NO_MASK = np.zeros((1, 1), np.uint8)
_NO_MASK.flags.writeable = False
_kernels = None


def kernels():
    """:mod:`humanpt.perception.kernels`, imported (numba, and its compiled code from the
    disk cache) on the first detection, not when this module is imported."""
    global _kernels
    if _kernels is None:
        from . import kernels as k

        _kernels = k
    return _kernels


def _image_and_mask(gray: np.ndarray, keep: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, bool]:
    """The compiled kernels read pixels unchecked: the image must be (H, W) uint8 and the
    mask the same size. Both are passed as contiguous read-only arrays (a decoded message's
    pixels are read-only): one compiled variant of each kernel."""
    if gray.dtype != np.uint8 or gray.ndim != 2:
        raise ValueError(f"perception: a grey image must be (H, W) uint8, got {gray.dtype} {gray.shape}")
    gray = _read_only(gray)
    if keep is None:
        return gray, _NO_MASK, False
    if keep.dtype != np.uint8 or keep.shape != gray.shape:
        raise ValueError(f"perception: the mask must be uint8 of the image's size {gray.shape}, "
                         f"got {keep.dtype} {keep.shape}")
    return gray, _read_only(keep), True


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as a contiguous read-only array (a view when it is contiguous)."""
    if a.flags.writeable or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a).view()
        a.flags.writeable = False
    return a


def background_and_noise(sub: np.ndarray, keep: np.ndarray | None = None) -> tuple[float, float]:
    """(background, sigma) in DN of a uint8 image region from its histogram: the median
    grey level and ``median - P15.87`` (>= 0.5 DN). ``keep`` (uint8, 255 = use) leaves
    masked pixels out. A large region is subsampled on a regular grid (>= ~8000 pixels):
    the histogram of the background does not need every pixel."""
    gray, mask, has_mask = _image_and_mask(sub, keep)
    height, width = gray.shape
    step = max(1, int(math.sqrt(gray.size / _HISTOGRAM_PX)))
    windows = np.array([(0, 0, width, height)], np.int64)
    return kernels().histogram_level(gray, mask, has_mask, windows, np.zeros(1, np.int64), step)


def _windows(region, width: int, height: int, gap_px: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(windows (t, 4) int64 clipped to the image, empty ones left out; the histogram
    grid's column phase of each; its step)."""
    regions = [region] if isinstance(region[0], (int, np.integer)) else region
    boxes = []
    for u0, v0, u1, v1 in regions:
        u0, v0, u1, v1 = max(int(u0), 0), max(int(v0), 0), min(int(u1), width), min(int(v1), height)
        if u1 > u0 and v1 > v0:
            boxes.append((u0, v0, u1, v1))
    if not boxes:
        return np.zeros((0, 4), np.int64), np.zeros(0, np.int64), 1
    # the grid: as if the windows lay side by side gap_px apart, top-aligned
    phase, x = [], 0
    for u0, _, u1, _ in boxes:
        phase.append(x)
        x += u1 - u0 + gap_px
    packed = (x - gap_px) * max(v1 - v0 for _, v0, _, v1 in boxes)
    step = max(1, int(math.sqrt(packed / _HISTOGRAM_PX)))
    return np.array(boxes, np.int64), np.array(phase, np.int64), step


def detect_weighted(
    gray: np.ndarray,
    region: Region | list[Region],
    *,
    threshold: float,
    noise_k: float = 8.0,
    aperture_pad_px: float = 3.0,
    min_area_px: int = 4,
    max_area_px: int = 3000,
    max_radius_px: float = 40.0,
    max_elongation: float = 4.0,
    min_contrast_dn: float = 20.0,
    max_blobs: int = 24,
    keep: np.ndarray | None = None,
    gap_px: int = 0,
) -> Blobs:
    """Detect and measure the blobs in ``region`` of ``gray`` ((H, W) uint8, sources
    bright, masked pixels 0; ``keep`` the mask, 255 = usable). ``max_radius_px``: the
    largest half-extent a source can have (nearest working depth); larger shapes are
    clutter. Returns :class:`Blobs` in whole-image pixels, at most ``max_blobs`` (the
    largest), in descending raster order of each shape's first pixel. See the module
    docstring for the steps; they run in one compiled call
    (:func:`humanpt.perception.kernels.detect_windows`), whose cost follows the region's
    rows that hold a shape and the shapes, not the region's size.

    ``region`` may be several disjoint windows (the tracking windows), measured together:
    one histogram of all of them (its grid as if they lay side by side ``gap_px`` apart),
    and a shape touching its window's border is rejected as one touching the region's.
    Regions are clipped to the image."""
    gray, mask, has_mask = _image_and_mask(gray, keep)
    height, width = gray.shape
    windows, phase, step = _windows(region, width, height, gap_px)
    if len(windows) == 0:
        return EMPTY
    uv, fields, moments, noise, full_scale, rejected = kernels().detect_windows(
        gray, mask, has_mask, windows, phase, step, float(threshold), float(noise_k), float(aperture_pad_px),
        int(min_area_px), int(max_area_px), float(max_radius_px), float(max_elongation), float(min_contrast_dn),
        int(max_blobs))
    if len(uv) == 0:
        return dataclasses.replace(EMPTY, rejected=rejected) if rejected else EMPTY
    area, size, elongation, peak, flux = fields
    return Blobs(uv, area, size, elongation, peak, rejected, flux, moments, noise, full_scale)
