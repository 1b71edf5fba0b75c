"""The paper's segmentation and pairing (Section 4, steps 2-5; Figure 6; appendix): the
reference method.

1. The grey image is converted to a binary image with the threshold T (step 2; masking and
   inversion, steps 2-3, are done by :mod:`humanpt.perception.image`).
2. Seeds: a pixel is a seed when it is the centre of the cross-shaped template of Figure 6
   made of shape pixels - a 9 x 9 cross, 17 pixels (9 + 9 - 1). Matching those 17 pixels
   everywhere is a morphological erosion of the binary image with the cross, which is how
   it is done here (``cv2.erode``). Isolated noise pixels and specks thinner than the cross
   hold no seed. The appendix says "a 9 x 9 or 5 x 5 template (the template used depends on
   the case)": shapes too small for the 9 x 9 cross are searched again with the next size
   of ``paper_cross_px`` (default 9, then 5) - with the default 5 mm sources a shape is only
   ~8 px across at 600 mm, where the 9 x 9 cross alone seeds only ~20 % of them (twin).
3. Propagation: each seed grows over its shape (its 8-connected component of the binary
   image, found by its contour and labelled in its bounding box), and the centre is the mean of the shape's
   pixel locations (step 4, "subpixel accuracy").
4. Pairing by scan line (epipolar line): the two views of a source lie on the same scan
   line, so the centres sorted by v are paired with their neighbour when within
   ``paper_scanline_tol_px``; each pair is put in order - the right view has the smaller u
   (positive disparity u_L - u_R, see :func:`humanpt.geometry.project`). The paper assumes
   "only two points are found in the same scan line"; when it is not so (two sources on one
   scan line, a stray reflection) this pairing can go wrong, which is what the default
   method's correspondence step fixes.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from .blobs import EMPTY, Blobs, Region, find_shapes

__all__ = ["cross_kernel", "seed_mask", "detect_paper", "pair_by_scan_line"]

_KERNELS: dict[int, np.ndarray] = {}


def cross_kernel(size: int) -> np.ndarray:
    """The cross-shaped template of Figure 6: ``size`` x ``size``, uint8, ones on the
    centre row and column (2 size - 1 pixels; 17 for 9 x 9)."""
    k = _KERNELS.get(size)
    if k is None:
        k = cv2.getStructuringElement(cv2.MORPH_CROSS, (size, size))
        k.setflags(write=False)
        _KERNELS[size] = k
    return k


def seed_mask(binary: np.ndarray, size: int) -> np.ndarray:
    """Seeds (uint8, 255) of a binary image (uint8, 0/255): the pixels where every pixel of
    the ``size`` x ``size`` cross is a shape pixel. Outside the image counts as
    background."""
    return cv2.erode(binary, cross_kernel(size), borderType=cv2.BORDER_CONSTANT, borderValue=0)


def detect_paper(
    gray: np.ndarray, threshold: float, crosses: tuple[int, ...], region: Region
) -> Blobs:
    """Steps 2 and 4 on ``region`` of ``gray`` (uint8, sources bright): threshold at T
    (pixels > T are shape pixels), seeds by the cross templates, propagation over the
    seeded shapes, centres as the mean of the shapes' pixel locations. Returns
    :class:`Blobs` in whole-image pixels (``peak_dn`` is the shape's brightest grey level,
    ``size_px`` the diameter of a disc of the same area, ``elongation`` 1: the paper measures
    neither)."""
    u0, v0, u1, v1 = region
    sub = gray[v0:v1, u0:u1]
    if sub.size == 0:
        return EMPTY
    _, binary = cv2.threshold(sub, float(threshold), 255, cv2.THRESH_BINARY)
    shapes = find_shapes(binary)
    if len(shapes) == 0:
        return EMPTY
    seeded = np.zeros(len(shapes), bool)
    for size in crosses:
        if size > int(max(shapes.w.max(), shapes.h.max())):
            continue  # no shape is that large: no seed anywhere
        seeds = seed_mask(binary, size)
        for i in np.flatnonzero(~seeded):
            x, y, w, h = shapes.x[i], shapes.y[i], shapes.w[i], shapes.h[i]
            # a seed's whole cross lies in one shape, so seeds in the box that are this
            # shape's pixels are its seeds
            seeded[i] = bool(np.any(seeds[y : y + h, x : x + w][shapes.masks[i]]))
        if seeded.all():
            break
    index = np.flatnonzero(seeded)
    if len(index) == 0:
        return dataclasses.replace(EMPTY, rejected=len(shapes))
    area = shapes.area[index].astype(float)
    peak = np.array(
        [
            float(
                sub[
                    shapes.y[i] : shapes.y[i] + shapes.h[i], shapes.x[i] : shapes.x[i] + shapes.w[i]
                ].max()
            )
            for i in index
        ]
    )
    return Blobs(
        shapes.centroid[index] + (u0, v0),
        area,
        2.0 * np.sqrt(area / np.pi),
        np.ones(len(index)),
        peak,
        len(shapes) - len(index),
        area,  # the paper has no flux: its checks compare the binary areas
        np.array([_shape_moments(shapes.masks[i]) for i in index]).reshape(-1, 3),
    )


def _shape_moments(mask: np.ndarray) -> tuple[float, float, float]:
    """Central second moments (m_uu, m_vv, m_uv) of a binary shape's pixel centres, px^2."""
    m = cv2.moments(mask.view(np.uint8), binaryImage=True)
    n = m["m00"]
    return m["mu20"] / n, m["mu02"] / n, m["mu11"] / n


def pair_by_scan_line(uv_px: np.ndarray, tol_px: float, max_pairs: int = 3) -> np.ndarray:
    """Step 5's correspondence as the paper does it: centres (n, 2) sorted by v; each is
    paired with the next one when their v differ by at most ``tol_px``; in each pair the
    smaller u is the right view. At most ``max_pairs`` pairs (those with the smallest
    |dv|), returned as (k, 2) int indices (right, left) ordered by v."""
    uv = np.asarray(uv_px, dtype=float)
    order = np.argsort(uv[:, 1], kind="stable")
    pairs: list[tuple[int, int, float]] = []
    i = 0
    while i < len(order) - 1:
        a, b = order[i], order[i + 1]
        dv = abs(uv[b, 1] - uv[a, 1])
        if dv <= tol_px and uv[a, 0] != uv[b, 0]:
            right, left = (a, b) if uv[a, 0] < uv[b, 0] else (b, a)
            pairs.append((int(right), int(left), dv))
            i += 2
        else:
            i += 1
    if len(pairs) > max_pairs:
        keep = sorted(range(len(pairs)), key=lambda k: pairs[k][2])[:max_pairs]
        pairs = [pairs[k] for k in sorted(keep)]
    return np.array([(r, l) for r, l, _ in pairs], dtype=int).reshape(-1, 2)
