"""The paper's corner detector (APPENDIX, after its ref. [41]): seeded ordered square
segmentation and two 11 x 11 X-shaped templates. Pure numpy/scipy: nothing of OpenCV's,
not even a refinement - it is the paper's method, to be compared with OpenCV's.

1. Binary image: a pixel has the SQUARE colour ("C", dark) below the threshold (the
   paper's prespecified threshold T; here the midpoint of the dark squares' and the white
   paper's grey levels, their 3rd and 97th percentiles), else the SUBSTRATE colour ("S").
2. Seeds: a seed is a "C" pixel at the centre of a 9 x 9 cross of "C" pixels (17 pixels
   instead of 81: noise pixels are rejected), or of a 5 x 5 cross (9 pixels) in a square
   too small for the 9 x 9 one.
3. Ordered segmentation: the first square is the one whose seed is nearest the initial
   point (default: the image centre, where a user aims the board). Each seed is
   propagated to its square only (the "C" pixels 4-connected to it once the one-pixel
   bridges where two squares touch at a corner are cut). The next squares are looked for
   where the previous square's centre and slope (its two side vectors) predict them: its
   four diagonal neighbours (the dark squares that share a corner with it), then two
   squares along each side; a square is accepted when its centre is within a quarter of
   a side of the prediction.
4. Corners: in a window around the square, every pixel is tested with the two templates
   "C" type (centre pixel square colour) and "S" type (centre pixel substrate colour),
   each in its four 90 degree rotations: an X whose legs are the template's diagonals
   (5 pixels each), one leg square-coloured (it points into the square), the three others
   substrate-coloured (only this square counts as square colour: the segmentation
   separated it). The detecting pixels of one orientation form a cluster at that corner
   (inner and outer side pixels of the corner); the corner is the cluster's mean.
5. Each inner corner is seen by up to two squares (the two dark squares meeting there):
   their estimates are averaged. The corners are numbered through the squares' lattice
   (the board's outer corners, one square beyond the inner ones, are dropped).

The result is pixel-quantised (the mean of a few pixel centres): typically 0.2-0.5 px from
the truth, against ~0.03 px for OpenCV's saddle-point refinement (README.md).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy import ndimage

from .board import Chessboard

__all__ = ["detect_paper", "binarize", "seeds", "X_LEG_PX"]

X_LEG_PX = 5  # an 11 x 11 template: the centre and four legs of 5 pixels along its diagonals
# The four rotations: the diagonal (du, dv) of the square-coloured leg, and which corner of
# the square (in image orientation) it detects: the leg points into the square.
_ORIENTATIONS = {(1, 1): "tl", (-1, 1): "tr", (-1, -1): "br", (1, -1): "bl"}


def binarize(grey: np.ndarray, threshold: float | None = None) -> np.ndarray:
    """(h, w) bool, True = square colour (dark). ``threshold`` in grey levels (None: the
    midpoint of the 3rd and 97th percentiles)."""
    g = np.asarray(grey, dtype=float)
    if threshold is None:
        lo, hi = np.percentile(g, [3, 97])
        threshold = 0.5 * (lo + hi)
    return g < threshold


def _shift(mask: np.ndarray, du: int, dv: int) -> np.ndarray:
    """out[v, u] = mask[v + dv, u + du] (False outside the image)."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    u0, u1 = max(0, -du), min(w, w - du)
    v0, v1 = max(0, -dv), min(h, h - dv)
    if u1 > u0 and v1 > v0:
        out[v0:v1, u0:u1] = mask[v0 + dv:v1 + dv, u0 + du:u1 + du]
    return out


def seeds(square: np.ndarray, half: int = 4) -> np.ndarray:
    """(h, w) bool: pixels at the centre of a (2 half + 1)^2 cross of square-coloured
    pixels (half = 4: the 9 x 9 template, 17 pixels; 2: the 5 x 5 one, 9 pixels)."""
    out = square.copy()
    for k in range(1, half + 1):
        for du, dv in ((k, 0), (-k, 0), (0, k), (0, -k)):
            out &= _shift(square, du, dv)
    return out


def _squares(dark: np.ndarray) -> list[dict]:
    """Segment the square-coloured areas that hold a seed: [{centre (u, v), mask window
    (v0, u0, mask)}]."""
    h, w = dark.shape
    # cut the bridges where two squares touch at a corner: a pixel stays only when it is
    # the centre of a 3 x 3 cross of dark pixels; each square is then the pixels of the
    # original mask within one pixel of its core
    core = seeds(dark, 1)
    labels, n = ndimage.label(core)
    if n == 0:
        return []
    seed9 = seeds(dark, 4)
    seed5 = seeds(dark, 2)
    out = []
    objs = ndimage.find_objects(labels)
    max_area = 0.05 * h * w
    for lab, sl in enumerate(objs, start=1):
        if sl is None:
            continue
        v0, v1 = max(0, sl[0].start - 2), min(h, sl[0].stop + 2)
        u0, u1 = max(0, sl[1].start - 2), min(w, sl[1].stop + 2)
        own = labels[v0:v1, u0:u1] == lab
        area = int(own.sum())
        if area < 20 or area > max_area:
            continue
        has_seed = (seed9[v0:v1, u0:u1] & own).any() or (seed5[v0:v1, u0:u1] & own).any()
        if not has_seed:  # noise, not a square
            continue
        mask = ndimage.binary_dilation(own, structure=ndimage.generate_binary_structure(2, 1)) & dark[v0:v1, u0:u1]
        vv, uu = np.nonzero(mask)
        out.append({"centre": np.array([uu.mean() + u0, vv.mean() + v0]), "v0": v0, "u0": u0, "mask": mask})
    return out


def _square_corners(sq: dict, shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """The X-template corners of one segmented square: {'tl'|'tr'|'br'|'bl': (u, v)}."""
    pad = X_LEG_PX + 2
    mask = np.pad(sq["mask"], pad)  # only this square is square-coloured
    out = {}
    for (du, dv), name in _ORIENTATIONS.items():
        legs_ok = np.ones_like(mask)
        for k in range(1, X_LEG_PX + 1):
            legs_ok &= _shift(mask, k * du, k * dv)  # the square-coloured leg
            for odu, odv in ((-du, -dv), (du, -dv), (-du, dv)):  # the three substrate legs
                legs_ok &= ~_shift(mask, k * odu, k * odv)
        # both template types detect: "C" (centre square-coloured) and "S" (substrate)
        vv, uu = np.nonzero(legs_ok)
        if vv.size == 0:
            continue
        pts = np.stack([uu, vv], -1).astype(float)
        # the cluster: the detecting pixels near their median (one corner per orientation)
        med = np.median(pts, axis=0)
        pts = pts[np.abs(pts - med).max(axis=1) <= 3]
        out[name] = pts.mean(axis=0) + (sq["u0"] - pad, sq["v0"] - pad)
    return out


def detect_paper(image: np.ndarray, board: Chessboard, initial_point_px=None,
                 threshold: float | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """The paper's detector on a grey image (h, w): (image_px (n, 2), index (n,)) of the
    inner corners it found, ``index`` into ``board.object_points_mm()``; None when it
    cannot number them (the lattice of squares it found is not the board's, or fewer than
    80 % of the corners)."""
    grey = np.asarray(image)
    h, w = grey.shape[:2]
    dark = binarize(grey, threshold)
    squares = _squares(dark)
    if len(squares) < 4:
        return None
    centres = np.array([s["centre"] for s in squares])
    start_pt = np.array([w / 2.0, h / 2.0]) if initial_point_px is None else np.asarray(initial_point_px, float)
    # the first square: the seed nearest the initial point
    first = int(np.argmin(np.linalg.norm(centres - start_pt, axis=1)))
    corners: dict[int, dict[str, np.ndarray]] = {}
    lattice: dict[int, tuple[int, int]] = {first: (0, 0)}
    taken: dict[tuple[int, int], int] = {(0, 0): first}
    queue = deque([first])
    while queue:  # ordered segmentation: each square predicts where its neighbours are
        k = queue.popleft()
        c = corners.setdefault(k, _square_corners(squares[k], (h, w)))
        if len(c) < 4:
            continue
        ex = 0.5 * ((c["tr"] - c["tl"]) + (c["br"] - c["bl"]))  # the square's slope: side vectors
        ey = 0.5 * ((c["bl"] - c["tl"]) + (c["br"] - c["tr"]))
        side = 0.5 * (np.linalg.norm(ex) + np.linalg.norm(ey))
        i, j = lattice[k]
        for di, dj in ((1, 1), (-1, 1), (1, -1), (-1, -1), (2, 0), (-2, 0), (0, 2), (0, -2)):
            if (i + di, j + dj) in taken:
                continue
            predicted = squares[k]["centre"] + di * ex + dj * ey
            d = np.linalg.norm(centres - predicted, axis=1)
            m = int(np.argmin(d))
            if d[m] < 0.25 * side and m not in lattice:
                lattice[m] = (i + di, j + dj)
                taken[(i + di, j + dj)] = m
                queue.append(m)
    # corner lattice: square (i, j)'s top-left corner is lattice point (i, j)
    offsets = {"tl": (0, 0), "tr": (1, 0), "bl": (0, 1), "br": (1, 1)}
    sums: dict[tuple[int, int], list[np.ndarray]] = {}
    for k, (i, j) in lattice.items():
        for name, p in corners.get(k, {}).items():
            oi, oj = offsets[name]
            sums.setdefault((i + oi, j + oj), []).append(p)
    if not sums:
        return None
    keys = np.array(list(sums))
    i_min, j_min = keys.min(axis=0)
    ni, nj = keys.max(axis=0) - keys.min(axis=0) + 1
    cols, rows = board.pattern_size
    if (ni, nj) == (cols + 2, rows + 2):
        def index(i, j):  # lattice i along the board's x
            return (i - 1) + (j - 1) * cols, 1 <= i <= cols and 1 <= j <= rows
    elif (ni, nj) == (rows + 2, cols + 2):
        def index(i, j):  # the board turned by 90 deg in the image: x = -j, y = i
            return (cols - j) + (i - 1) * cols, 1 <= j <= cols and 1 <= i <= rows
    else:
        return None
    pts, idx = [], []
    for (i, j), ps in sums.items():
        n, inner = index(i - i_min, j - j_min)
        if inner:
            pts.append(np.mean(ps, axis=0))
            idx.append(n)
    if len(idx) < 0.8 * board.n_corners:
        return None
    order = np.argsort(idx)
    return np.asarray(pts)[order], np.asarray(idx)[order]
