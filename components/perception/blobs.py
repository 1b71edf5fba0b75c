"""What both detectors return: the accepted blobs of one complex image.

A blob is one light source seen through one of the two virtual cameras; the complex image
does not say which, so the correspondence step decides. Coordinates are observed
(distorted) pixels of the whole complex image, pixel centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Blobs", "Region", "Shapes", "full_region", "clip_region", "find_shapes",
           "windows_around", "EMPTY"]

Region = tuple[int, int, int, int]
"""``(u0, v0, u1, v1)``: the pixels ``u0 <= u < u1``, ``v0 <= v < v1`` of an image."""


def full_region(width: int, height: int) -> Region:
    return (0, 0, int(width), int(height))


def clip_region(region: Region, width: int, height: int) -> Region:
    u0, v0, u1, v1 = region
    return (max(0, u0), max(0, v0), min(width, u1), min(height, v1))


@dataclass(frozen=True)
class Blobs:
    """Accepted blobs, struct of arrays (n = number of blobs).

    ``uv_px`` (n, 2): centres, px. ``area_px`` (n,): pixels above the threshold.
    ``size_px`` (n,): diameter estimate along the major axis, px. ``elongation`` (n,):
    major/minor axis ratio (>= 1). ``peak_dn`` (n,): brightest pixel above the local
    background, DN. ``rejected``: candidate shapes that failed the checks.
    ``flux_dn`` (n,): summed grey levels above the local background in the blob's
    aperture, DN (the weighted method; the paper method: the binary shape's pixel count).
    ``moments_px2`` (n, 3): the blob's central second moments (m_uu, m_vv, m_uv), px^2
    (intensity-weighted by the weighted method, of the binary shape by the paper method).
    ``noise`` (n, 2): the background noise's SD of the flux (DN) and of the moments'
    anisotropy (px^2), the weighted method only. All three feed the blob checks
    (:mod:`humanpt.perception.checks`). ``saturated_px`` (n,) int: the blob's aperture
    pixels at full scale (255: its centre is biased when there are more than a few), the
    weighted method only.
    """

    uv_px: np.ndarray
    area_px: np.ndarray
    size_px: np.ndarray
    elongation: np.ndarray
    peak_dn: np.ndarray
    rejected: int = 0
    flux_dn: np.ndarray | None = None
    moments_px2: np.ndarray | None = None
    noise: np.ndarray | None = None
    saturated_px: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.uv_px.shape[0])

    def take(self, index) -> Blobs:
        """The blobs at ``index`` (indices or a boolean mask)."""
        return Blobs(
            self.uv_px[index],
            self.area_px[index],
            self.size_px[index],
            self.elongation[index],
            self.peak_dn[index],
            self.rejected,
            None if self.flux_dn is None else self.flux_dn[index],
            None if self.moments_px2 is None else self.moments_px2[index],
            None if self.noise is None else self.noise[index],
            None if self.saturated_px is None else self.saturated_px[index],
        )


EMPTY = Blobs(
    np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), 0, np.zeros(0),
    np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0, int),
)


@dataclass(frozen=True)
class Shapes:
    """The 8-connected shapes of a binary image (m shapes), struct of arrays in the binary
    image's pixels: bounding boxes ``x, y, w, h`` (int), ``area`` (pixel count, int),
    ``centroid`` (m, 2), the mean of the shape's pixel locations (u, v), ``masks``, per
    shape a (h, w) bool array of its pixels within its box, and ``first`` (m, 2) int the
    shape's first pixel in raster order (u, v). The shapes come in descending raster order
    of ``first`` (``cv2.findContours``'s order)."""

    x: np.ndarray
    y: np.ndarray
    w: np.ndarray
    h: np.ndarray
    area: np.ndarray
    centroid: np.ndarray
    masks: tuple[np.ndarray, ...]
    first: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def take(self, index) -> Shapes:
        index = np.asarray(index)
        if index.dtype == bool:
            index = np.flatnonzero(index)
        return Shapes(
            self.x[index],
            self.y[index],
            self.w[index],
            self.h[index],
            self.area[index],
            self.centroid[index],
            tuple(self.masks[i] for i in index),
            None if self.first is None else self.first[index],
        )


def find_shapes(binary: np.ndarray) -> Shapes:
    """Every 8-connected shape of ``binary`` ((H, W) uint8, 0 / 255): its exact pixel count
    and mean, only the outermost ones (a shape in a hole of another is not one, as
    ``cv2.findContours``' ``RETR_EXTERNAL``), at most 256 (the largest boxes). One compiled
    labelling by runs (:func:`humanpt.perception.kernels.label_runs`, the weighted
    detector's)."""
    from .weighted import _image_and_mask, kernels

    binary, _, _ = _image_and_mask(binary, None)
    height, width = binary.shape
    run_v, run_s, run_e, comp, box, area, sums, first, _ = kernels().label_runs(
        binary, 0, np.array([(0, 0, width, height)], np.int64))
    # descending raster order of the first pixel (the shapes come ascending)
    box, area, sums, first = box[::-1], area[::-1], sums[::-1], first[::-1]
    m = len(area)
    x, y = box[:, 0], box[:, 1]
    w, h = box[:, 2] - x + 1, box[:, 3] - y + 1
    masks = [np.zeros((hh, ww), bool) for hh, ww in zip(h.tolist(), w.tolist(), strict=True)]
    xs, ys = x.tolist(), y.tolist()
    for v, s, e, c in zip(run_v.tolist(), run_s.tolist(), run_e.tolist(), comp.tolist(), strict=True):
        if c >= 0:
            k = m - 1 - c
            masks[k][v - ys[k], s - xs[k] : e - xs[k]] = True
    centroid = sums / np.maximum(area, 1)[:, None]
    return Shapes(x, y, w, h, area, centroid, tuple(masks), first)


def windows_around(uv_px: np.ndarray, half_px: float, width: int, height: int) -> list[Region]:
    """Square windows of half size ``half_px`` around centres (k, 2), clipped to the image,
    overlapping ones merged into their bounding box until no two overlap (a shape is then
    whole in at most one window)."""
    from .weighted import kernels

    uv = np.ascontiguousarray(uv_px, dtype=float).reshape(-1, 2)
    return [tuple(b) for b in kernels().merge_windows(uv, float(half_px), int(width), int(height)).tolist()]
