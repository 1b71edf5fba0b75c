"""What both detectors return: the accepted blobs of one complex image.

A blob is one light source seen through one of the two virtual cameras; the complex image
does not say which, so the correspondence step decides. Coordinates are observed
(distorted) pixels of the whole complex image, pixel centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Blobs", "Region", "Shapes", "Mosaic", "full_region", "clip_region", "find_shapes",
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


def find_shapes(binary: np.ndarray, max_shapes: int = 256) -> Shapes:
    """Every 8-connected shape of ``binary`` ((H, W) uint8, 0 / 255), found by its outer
    contour (``cv2.findContours``, fast on a sparse image) and measured by a connected
    component labelling of its bounding box only (exact pixel count and mean, holes left
    out). At most ``max_shapes``, the ones with the largest boxes."""
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return Shapes(*(np.zeros(0, int) for _ in range(5)), np.zeros((0, 2)), (),
                      np.zeros((0, 2), int))
    boxes = [cv2.boundingRect(c) for c in contours]
    if len(contours) > max_shapes:
        b = np.array(boxes, dtype=int).reshape(-1, 4)
        keep = np.sort(np.argsort(-(b[:, 2] * b[:, 3]), kind="stable")[:max_shapes])
        contours = [contours[i] for i in keep]
        boxes = [boxes[i] for i in keep]
    area, centroid, masks, first = [], [], [], []
    for c, (x, y, w, h) in zip(contours, boxes, strict=True):
        _, labels, stats, cents = cv2.connectedComponentsWithStats(
            binary[y : y + h, x : x + w], connectivity=8, ltype=cv2.CV_32S
        )
        u, v = c[0, 0].tolist()  # the contour starts at the shape's first pixel
        first.append((u, v))
        k = labels[v - y, u - x]  # the component of a contour pixel
        area.append(stats[k, cv2.CC_STAT_AREA])
        cu, cv = cents[k].tolist()
        centroid.append((cu + x, cv + y))
        masks.append(labels == k)
    b = np.array(boxes, dtype=int).reshape(-1, 4)
    return Shapes(
        b[:, 0],
        b[:, 1],
        b[:, 2],
        b[:, 3],
        np.array(area, dtype=int),
        np.array(centroid, dtype=float).reshape(-1, 2),
        tuple(masks),
        np.array(first, dtype=int).reshape(-1, 2),
    )


def windows_around(uv_px: np.ndarray, half_px: float, width: int, height: int) -> list[Region]:
    """Square windows of half size ``half_px`` around centres (k, 2), clipped to the image,
    overlapping ones merged into their bounding box until no two overlap (a shape is then
    whole in at most one window)."""
    uv = np.asarray(uv_px, dtype=float).reshape(-1, 2)
    # every window at once: (u0, v0, u1, v1) clipped to the image
    box = np.concatenate((np.maximum(np.floor(uv - half_px), 0.0),
                          np.minimum(np.ceil(uv + half_px) + 1.0, (width, height))), axis=1)
    boxes = [tuple(b) for b in box.astype(int).tolist()]
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    boxes[i] = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return [b for b in boxes if b[2] > b[0] and b[3] > b[1]]


@dataclass(frozen=True)
class Mosaic:
    """Disjoint windows of an image packed side by side into one small image, so that a
    detector measures them all in one call: ``gray`` (H, W) uint8, ``keep`` (H, W) uint8
    (255 = an image pixel the detector may use, 0 = a gap or a masked pixel), ``tiles``
    (t, 4) int each window's (x0, y0, x1, y1) in the mosaic, ``offset`` (t, 2) int what
    takes a mosaic pixel of that window to the image's (u, v). The windows are ``gap_px``
    apart: a blob's centroid window (the detector's) never reaches another window."""

    gray: np.ndarray
    keep: np.ndarray
    tiles: np.ndarray
    offset: np.ndarray

    @staticmethod
    def pack(gray: np.ndarray, keep: np.ndarray | None, windows: list[Region], gap_px: int) -> Mosaic:
        height = max(v1 - v0 for _, v0, _, v1 in windows)
        width = sum(u1 - u0 for u0, _, u1, _ in windows) + gap_px * (len(windows) - 1)
        out = np.zeros((height, width), np.uint8)
        use = np.zeros((height, width), np.uint8)
        tiles, offset = [], []
        x = 0
        for u0, v0, u1, v1 in windows:
            w, h = u1 - u0, v1 - v0
            out[:h, x : x + w] = gray[v0:v1, u0:u1]
            use[:h, x : x + w] = 255 if keep is None else keep[v0:v1, u0:u1]
            tiles.append((x, 0, x + w, h))
            offset.append((u0 - x, v0))
            x += w + gap_px
        return Mosaic(out, use, np.array(tiles, dtype=int), np.array(offset, dtype=int))
