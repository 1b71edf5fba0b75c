"""The default detector: background-subtracted, intensity-weighted subpixel centroids with
shape checks.

1. Background and noise of the searched region from its grey-level histogram (median, and
   the median minus the 15.9th percentile as a one-sided robust sigma: the sources only
   occupy the top of the histogram).
2. Detection: pixels above ``max(T, background + noise_k * sigma)`` (so a brighter
   ambient raises the level by itself), 8-connected components
   (``cv2.connectedComponentsWithStats``). Components outside the area limits, touching the
   border of the searched region (a cut shape has a biased centre), or too large for a
   source at the nearest working depth are rejected.
3. Centre: in a circular aperture of radius ``max(width, height)/2 + aperture_pad_px``
   around the component - wide enough to take in the blurred edge that lies below the
   threshold - each pixel weighs ``I - b``, with ``b`` the mean of a 2-px ring just outside
   the aperture (local background, so a glow nearby does not pull the centre). The weights
   are not clipped at 0, so background noise averages out instead of adding a positive
   bias; the aperture is re-centred on the estimate twice so that it is symmetric about
   the result. Pixels of other components and masked pixels are left out. All blobs are
   refined together in one (n, S, S) stack of windows.
4. Shape checks on the weighted moments: positive flux, peak at least ``min_contrast_dn``
   above the local background, major/minor axis ratio at most ``max_elongation``. Each
   blob's aperture pixels at full scale (255) are counted (``Blobs.saturated_px``): a
   clipped peak biases the centre, the core reports it.

Why weights and not the binary mean: the mean of thresholded pixel positions moves in
steps as pixels cross T (pixel locking, ~0.05-0.1 px for 8 px shapes); the weighted
centroid of a blurred, pixel-integrated spot has no such steps and its noise is set by the
photon and read noise only (a few thousandths of a pixel for the default twin).
"""

from __future__ import annotations

import bisect
import dataclasses
import math

import cv2
import numpy as np

from .blobs import EMPTY, Blobs, Region, find_shapes

__all__ = ["background_and_noise", "detect_weighted"]

_RING_PX = 2.0
_ITERATIONS = 2


def background_and_noise(sub: np.ndarray, keep: np.ndarray | None = None) -> tuple[float, float]:
    """(background, sigma) in DN of a uint8 image region from its histogram: the median
    grey level and ``median - P15.87`` (>= 0.5 DN). ``keep`` (uint8, 255 = use) leaves
    masked pixels out. A large region is subsampled on a regular grid (>= ~8000 pixels):
    the histogram of the background does not need every pixel."""
    step = max(1, int(math.sqrt(sub.size / 8000.0)))
    if step > 1:
        sub = np.ascontiguousarray(sub[::step, ::step])
        keep = None if keep is None else np.ascontiguousarray(keep[::step, ::step])
    hist = cv2.calcHist([sub], [0], keep, [256], [0, 256]).ravel()
    total = hist.sum()
    if total <= 0:
        return 0.0, 0.5
    cdf = np.cumsum(hist)
    median = float(np.searchsorted(cdf, 0.5 * total))
    low = float(np.searchsorted(cdf, 0.1587 * total))
    return median, max(median - low, 0.5)


_BASES: dict[int, np.ndarray] = {}


def _moment_basis(half: int) -> np.ndarray:
    """(S*S, 6), S = 2 half + 1: per pixel of an S x S window (rows first) 1, x, y, x^2,
    x y, y^2, the pixel's offsets (x, y) from the window's centre pixel (integers)."""
    basis = _BASES.get(half)
    if basis is None:
        gy, gx = np.mgrid[-half : half + 1, -half : half + 1].astype(np.float64)
        gx, gy = gx.ravel(), gy.ravel()
        basis = np.stack((np.ones_like(gx), gx, gy, gx * gx, gx * gy, gy * gy), axis=1)
        basis.setflags(write=False)
        if half <= 256:
            _BASES[half] = basis
    return basis


def _windows_view(image: np.ndarray, size: int, rows: list[int], cols: list[int]) -> np.ndarray:
    """(m, S, S) copies of the S x S windows of ``image`` at corners (rows[i], cols[i]),
    every window inside the image (slices copied: no index arrays)."""
    out = np.empty((len(rows), size, size), image.dtype)
    for i, (r, c) in enumerate(zip(rows, cols, strict=True)):
        out[i] = image[r : r + size, c : c + size]
    return out


def _gather(image: np.ndarray, size: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(m, S, S) pixels of ``image`` at (m, S, 1) rows and (m, 1, S) columns (clipped)."""
    return image[rows, cols]


def detect_weighted(
    gray: np.ndarray,
    region: Region,
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
    tiles: np.ndarray | None = None,
    offset: np.ndarray | None = None,
) -> Blobs:
    """Detect and measure the blobs in ``region`` of ``gray`` ((H, W) uint8, sources
    bright, masked pixels 0; ``keep`` the mask, 255 = usable). ``max_radius_px``: the
    largest half-extent a source can have (nearest working depth); larger shapes are
    clutter. Returns :class:`Blobs` in whole-image pixels, at most ``max_blobs`` (the
    largest), in descending raster order of each shape's first pixel (the whole image's
    ``cv2.findContours`` order). See the module docstring for the steps.

    ``tiles`` (t, 4), ``offset`` (t, 2): ``region`` is a :class:`~humanpt.perception.blobs
    .Mosaic` of t windows (``keep`` 0 between them), left to right: each window's (x0, y0,
    x1, y1) in the region and what takes its pixels to the image's; a shape touching its
    window's border is rejected as one touching the region's. Default: one window, the
    region."""
    u0, v0, u1, v1 = region
    sub = gray[v0:v1, u0:u1]
    if sub.size == 0:
        return EMPTY
    keep_sub = None if keep is None else keep[v0:v1, u0:u1]
    height, width = sub.shape
    if tiles is None:
        tiles = np.array([(0, 0, width, height)])
        offset = np.array([(u0, v0)])
    background, sigma = background_and_noise(sub, keep_sub)
    level = max(float(threshold), background + noise_k * sigma)
    if level >= 255:
        return EMPTY
    _, binary = cv2.threshold(sub, level, 255, cv2.THRESH_BINARY)
    shapes = find_shapes(binary)
    if len(shapes) == 0:
        return EMPTY
    # (per-shape numbers as plain Python numbers: the same values and comparisons as the
    # arrays, without numpy's per-call overhead on a handful of shapes)
    x, y, w, h = shapes.x.tolist(), shapes.y.tolist(), shapes.w.tolist(), shapes.h.tolist()
    area = shapes.area.tolist()
    windows = tiles.tolist()
    starts = [t[0] for t in windows]
    tile_of = [bisect.bisect_right(starts, u) - 1 for u in x]  # the window each shape lies in
    tx0, ty0, tx1, ty1 = ([windows[t][k] for t in tile_of] for k in range(4))
    cand = [
        i
        for i in range(len(shapes))
        if min_area_px <= area[i] <= max_area_px
        and x[i] > tx0[i]
        and y[i] > ty0[i]
        and x[i] + w[i] < tx1[i]
        and y[i] + h[i] < ty1[i]
        and max(w[i], h[i]) <= 2.0 * max_radius_px
    ]
    rejected = len(shapes) - len(cand)
    if len(cand) == 0:
        return dataclasses.replace(EMPTY, rejected=rejected)
    if len(cand) > max_blobs:
        cand = np.array(cand)
        order = np.argsort(-shapes.area[cand], kind="stable")[:max_blobs]
        rejected += len(cand) - max_blobs
        cand = np.sort(cand[order]).tolist()
    cand_l, cand = cand, np.array(cand)
    centroid = shapes.centroid[cand]  # (m, 2)
    r_ap_l = [0.5 * max(w[i], h[i]) + aperture_pad_px for i in cand_l]
    r_ap = np.array(r_ap_l)  # (m,)
    half = int(math.ceil(max(r_ap_l) + _RING_PX + 1.0))
    size_w = 2 * half + 1
    # window corners: the rounded centre - half (np.rint and round both round half to even)
    y0 = [round(v) - half for v in centroid[:, 1].tolist()]
    x0 = [round(u) - half for u in centroid[:, 0].tolist()]
    inside = min(y0) >= 0 and min(x0) >= 0 and max(y0) + 2 * half < height
    inside = inside and max(x0) + 2 * half < width
    if inside:  # no window reaches out of the region: no clipping, every pixel valid
        rows, cols = y0, x0  # the windows' corners: copied by slices
        windows_of = _windows_view
    else:
        ys = np.array(y0)[:, None] + np.arange(size_w)  # (m, S)
        xs = np.array(x0)[:, None] + np.arange(size_w)
        ys_c = np.clip(ys, 0, height - 1)
        xs_c = np.clip(xs, 0, width - 1)
        rows, cols = ys_c[:, :, None], xs_c[:, None, :]
        windows_of = _gather
    win_dn = windows_of(sub, size_w, rows, cols)  # (m, S, S) uint8
    # Pixels of other shapes (above the level and not this shape's) are left out.
    own = np.zeros(win_dn.shape, bool)
    for i, k in enumerate(cand_l):
        oy = y[k] - y0[i]
        ox = x[k] - x0[i]
        mask = shapes.masks[k]
        sy0, sx0 = max(oy, 0), max(ox, 0)
        sy1, sx1 = min(oy + mask.shape[0], size_w), min(ox + mask.shape[1], size_w)
        own[i, sy0:sy1, sx0:sx1] = mask[sy0 - oy : sy1 - oy, sx0 - ox : sx1 - ox]
    valid = own | (win_dn <= level)
    if not inside:
        valid &= (ys == ys_c)[:, :, None] & (xs == xs_c)[:, None, :]
    if keep_sub is not None:
        valid &= windows_of(keep_sub, size_w, rows, cols) > 0
    m = len(cand)
    # (the valid pixels' count and grey levels, (2, m, S*S): every sum below is a product
    # of these with a 0/1 mask and the window's moment basis, one matrix product for all
    # blobs; the grey levels and pixel offsets are integers, so every such sum is exact)
    counted = np.empty((2, m, size_w * size_w))
    flat_valid = valid.reshape(m, -1)
    np.copyto(counted[0], flat_valid)
    np.multiply(win_dn.reshape(m, -1), flat_valid, out=counted[1])
    basis = _moment_basis(half)  # (S*S, 6): 1, x, y, x^2, xy, y^2 about the window's centre
    grid_x, grid_y = basis[:, 1], basis[:, 2]
    # the centres relative to their window's centre pixel (exact: an integer near them,
    # so the distances below are the region's to the last bit)
    xc, yc = np.array(x0) + half, np.array(y0) + half
    cx = centroid[:, 0] - xc
    cy = centroid[:, 1] - yc
    r2 = np.empty((2, m, 1))
    r2[0, :, 0] = r_ap * r_ap  # the aperture; the aperture and its ring (r_ap >= 0)
    r2[1, :, 0] = (r_ap + _RING_PX) ** 2
    inside_r = np.empty((2, m, size_w * size_w))
    masked = np.empty((2, 2, m, size_w * size_w))
    for _ in range(_ITERATIONS):
        dx = grid_x - cx[:, None]  # (m, S*S)
        dy = grid_y - cy[:, None]
        d2 = dx * dx
        d2 += dy * dy
        np.less_equal(d2, r2, out=inside_r)  # 1.0 within (the aperture, its outer ring's edge)
        # masked[a, g]: (aperture, aperture + ring)[a] x (count, grey level)[g]
        np.multiply(inside_r[:, None], counted[None], out=masked)
        sums = (masked.reshape(4 * m, -1) @ basis).reshape(2, 2, m, 6)
        n_ap, n_ring = sums[0, 0, :, 0], sums[1, 0, :, 0] - sums[0, 0, :, 0]
        local_bg = np.where(
            n_ring >= 8, (sums[1, 1, :, 0] - sums[0, 1, :, 0]) / np.maximum(n_ring, 1), background
        )
        # sums of (I - b) over the aperture: flux, first and second moments (m, 6)
        moment = sums[0, 1] - local_bg[:, None] * sums[0, 0]
        flux = moment[:, 0]
        good = flux > 0
        safe = np.where(good, flux, 1.0)
        cx = np.where(good, moment[:, 1] / safe, cx)
        cy = np.where(good, moment[:, 2] / safe, cy)
    # central second moments of the last weights about the result
    mxx = moment[:, 3] / safe - cx * cx
    myy = moment[:, 5] / safe - cy * cy
    mxy = moment[:, 4] / safe - cx * cy
    # the brightest aperture pixel less the local background (an empty aperture has no
    # flux and is rejected)
    peak = masked[0, 1].max(axis=1) - local_bg
    full_scale = np.count_nonzero(masked[0, 1] >= 255.0, axis=1)  # saturated aperture pixels
    # Background noise of the flux and of the moments' anisotropy (for the blob checks),
    # over a circular aperture of radius R (~pi R^2 pixels): sigma per aperture pixel plus
    # the local background's error over the whole aperture; the anisotropy's two parts
    # ((m_uu - m_vv)/2, m_uv) each sigma sqrt(sum ((dx^2 - dy^2)/2)^2) / flux, the sum
    # ~ pi R^6 / 12. (The sources' own shot noise is left out: the background's dominates
    # faint blobs.)
    n_ap = np.pi * r_ap**2
    flux_sd = sigma * np.sqrt(n_ap + n_ap**2 / np.maximum(n_ring, 1))
    aniso_sd = sigma * np.sqrt(np.pi / 12.0) * r_ap**3 / safe
    # Shape checks, all blobs at once.
    mean = 0.5 * (mxx + myy)
    spread = np.sqrt(0.25 * ((mxx - myy) * (mxx - myy)) + mxy * mxy)
    lam_major = mean + spread
    lam_minor = mean - spread
    # (lam_major >= lam_minor > 0 where it is used: the abs only keeps sqrt quiet elsewhere)
    elongation = np.where(lam_minor > 0, np.sqrt(np.abs(lam_major / np.maximum(lam_minor, 1e-12))), np.inf)
    # A uniform disc of radius R has a variance R^2/4 per axis; the pixel adds 1/12.
    size = 4.0 * np.sqrt(np.maximum(lam_major - 1.0 / 12.0, 0.0))
    centre = np.array((cx + xc, cy + yc))  # (2, m) in the region
    ok = good & (peak >= min_contrast_dn) & (elongation <= max_elongation)
    ok &= (np.abs(centre - centroid.T) <= r_ap).all(axis=0)
    n_ok = int(np.count_nonzero(ok))
    rejected += m - n_ok
    if n_ok == 0:
        return dataclasses.replace(EMPTY, rejected=rejected)
    # back to the image: each shape's window's offset
    shift = offset[np.array(tile_of)[cand]] if len(offset) > 1 else offset[0]
    fields = (centre.T + shift, shapes.area[cand].astype(float), size, elongation, peak, flux,
              np.array((mxx, myy, mxy)).T, np.array((flux_sd, aniso_sd)).T, full_scale)
    if n_ok < m:
        fields = tuple(f[ok] for f in fields)
    blobs = Blobs(*fields[:5], rejected, *fields[5:])
    if len(tiles) > 1:  # the whole image's order: descending (v, u) of the first pixel
        first = shapes.first[cand] + shift
        if n_ok < m:
            first = first[ok]
        order = np.lexsort((first[:, 0], first[:, 1]))[::-1]
        if np.any(order != np.arange(len(order))):
            blobs = blobs.take(order)
    return blobs
