"""The perception core's compiled kernels (numba): pure functions on arrays, compiled on
first use and cached on disk (``cache=True``: a later process loads the machine code
instead of compiling); ``error_model="numpy"``: a division by zero gives inf or NaN, as
the numpy code they replace, not an exception. Imported only by the detectors when they first run, so importing
humanpt (or a core that never measures) does not import numba.

* :func:`histogram_level`: the grey-level histogram of windows of an image, subsampled on a
  regular grid, and its median and one-sided robust sigma
  (:func:`humanpt.perception.weighted.background_and_noise`).
* :func:`label_runs`: the 8-connected shapes of the pixels above a level in windows of an
  image, from runs of pixels joined by union-find, with their pixel counts, boxes, pixel
  sums and first pixels; only the outermost shapes (a shape in the hole of another is
  not one: ``cv2.findContours``' ``RETR_EXTERNAL``), at most 256 (the largest boxes).
* :func:`detect_windows`: the weighted method's detector in one call - the level from
  the histogram, the shapes, the candidate limits and the aperture refinement of each
  candidate with its local background ring, moments, peak, saturated count and noise
  (:func:`humanpt.perception.weighted.detect_weighted` describes the steps).

Windows are ``(u0, v0, u1, v1)`` rows of an int64 (t, 4) array, disjoint, inside the
image; coordinates are the image's pixels (centres at integers).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_RING_PX = 2.0
_ITERATIONS = 2
MAX_SHAPES = 256


@njit(cache=True, nogil=True, error_model="numpy")
def histogram_level(gray, keep, has_keep, windows, phase_u, step):
    """(median, sigma) DN of the pixels of ``windows`` of ``gray`` on the grid of every
    ``step``-th row (from each window's first) and every column whose ``phase_u[w] + (u -
    u0)`` is a multiple of ``step``, masked ones (``keep`` 0) left out: the median and
    ``median - P15.87`` (at least 0.5), as ``np.searchsorted`` on the float32 cumulative
    histogram (``cv2.calcHist``'s). (0, 0.5) when no pixel is counted."""
    hist = np.zeros(256, np.int64)
    for w in range(windows.shape[0]):
        u0, v0, u1, v1 = windows[w, 0], windows[w, 1], windows[w, 2], windows[w, 3]
        first = u0 + (-phase_u[w]) % step
        for v in range(v0, v1, step):
            for u in range(first, u1, step):
                if has_keep and keep[v, u] == 0:
                    continue
                hist[gray[v, u]] += 1
    total = 0
    for k in range(256):
        total += hist[k]
    if total == 0:
        return 0.0, 0.5
    half = np.float32(total) * np.float32(0.5)
    low = np.float32(total) * np.float32(0.1587)
    median = -1
    lowest = -1
    cdf = 0
    for k in range(256):
        cdf += hist[k]
        if lowest < 0 and np.float32(cdf) >= low:
            lowest = k
        if median < 0 and np.float32(cdf) >= half:
            median = k
            break
    return float(median), max(float(median - lowest), 0.5)


# (numba's own sorts are large generic code that takes seconds to compile: these are small)
@njit(cache=True, nogil=True, error_model="numpy")
def _order(key):
    """Indices that sort ``key`` (float64) ascending, stable (a bottom-up merge sort)."""
    n = key.shape[0]
    idx = np.arange(n)
    tmp = np.empty(n, np.int64)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid, hi = min(lo + width, n), min(lo + 2 * width, n)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if key[idx[j]] < key[idx[i]]:
                    tmp[k] = idx[j]
                    j += 1
                else:
                    tmp[k] = idx[i]
                    i += 1
                k += 1
            while i < mid:
                tmp[k] = idx[i]
                i += 1
                k += 1
            while j < hi:
                tmp[k] = idx[j]
                j += 1
                k += 1
        for k in range(n):
            idx[k] = tmp[k]
        width *= 2
    return idx


@njit(cache=True, nogil=True, error_model="numpy")
def _smallest(key, count):
    """The indices of the ``count`` smallest of ``key`` (ties: the earlier), ascending."""
    chosen = np.zeros(key.shape[0], np.bool_)
    order = _order(key)
    m = min(count, key.shape[0])
    for k in range(m):
        chosen[order[k]] = True
    out = np.empty(m, np.int64)
    k = 0
    for i in range(key.shape[0]):
        if chosen[i]:
            out[k] = i
            k += 1
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_small(a):
    """``a`` sorted ascending in place (an insertion sort: a handful of values)."""
    for i in range(1, a.shape[0]):
        x = a[i]
        j = i - 1
        while j >= 0 and a[j] > x:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = x


@njit(cache=True, nogil=True, error_model="numpy")
def _find(parent, i):
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True, nogil=True, error_model="numpy")
def label_runs(gray, level_dn, windows):
    """The 8-connected shapes of the pixels of ``gray`` above ``level_dn`` (an integer)
    in each window (a shape never crosses a window's edge).

    Returns ``run_v, run_s, run_e`` (r,) the runs (row, first column, one past the last),
    ``comp`` (r,) each run's shape (-1: a shape left out), ``box`` (m, 4) each shape's
    (u_min, v_min, u_max, v_max) (inclusive), ``area`` (m,), ``sums`` (m, 2) the sums of
    its pixels' u and v, ``first`` (m, 2) its first pixel in raster order (u, v),
    ``window`` (m,) the window it lies in. Only the outermost shapes, at most
    :data:`MAX_SHAPES` (the largest boxes). Shapes are numbered in ascending raster order
    of their first pixel within each window."""
    cap = 256
    while True:  # (the runs' arrays are never reassigned in the scan: that would slow it down)
        run_v = np.empty(cap, np.int64)
        run_s = np.empty(cap, np.int64)
        run_e = np.empty(cap, np.int64)
        parent = np.empty(cap, np.int64)
        gap = np.empty(cap, np.int64)
        bg_s = np.empty(cap, np.int64)
        bg_e = np.empty(cap, np.int64)
        bg_parent = np.empty(cap, np.int64)
        n = _scan_runs(gray, level_dn, windows, run_v, run_s, run_e, parent, gap, bg_s, bg_e, bg_parent)
        if n >= 0:
            break
        cap *= 4
    # shapes: numbered by their first run (the root is the shape's smallest run index)
    comp = np.empty(n, np.int64)
    m = 0
    for r in range(n):
        root = _find(parent, r)
        if root == r:
            comp[r] = m
            m += 1
        else:
            comp[r] = comp[root]
    box = np.empty((m, 4), np.int64)
    area = np.zeros(m, np.int64)
    sums = np.zeros((m, 2), np.int64)
    first = np.empty((m, 2), np.int64)
    window = np.empty(m, np.int64)
    seen = np.zeros(m, np.bool_)
    w = 0
    for r in range(n):
        c = comp[r]
        s, e, v = run_s[r], run_e[r], run_v[r]
        length = e - s
        if not seen[c]:
            seen[c] = True
            box[c, 0], box[c, 1], box[c, 2], box[c, 3] = s, v, e - 1, v
            first[c, 0], first[c, 1] = s, v
            while not (windows[w, 0] <= s < windows[w, 2] and windows[w, 1] <= v < windows[w, 3]):
                w = (w + 1) % windows.shape[0]
            window[c] = w
        else:
            box[c, 0] = min(box[c, 0], s)
            box[c, 2] = max(box[c, 2], e - 1)
            box[c, 3] = v
        area[c] += length
        sums[c, 0] += (s + e - 1) * length // 2
        sums[c, 1] += v * length
    # only the outermost shapes: a shape whose first pixel's left neighbour is background
    # not joined to the outside lies in a hole of another
    outer = np.ones(m, np.bool_)
    for r in range(n):
        if _find(parent, r) == r and gap[r] >= 0 and _find(bg_parent, gap[r]) != 0:
            outer[comp[r]] = False
    found = 0
    for c in range(m):
        if outer[c]:
            found += 1
    if found > MAX_SHAPES:  # the largest boxes, ties in descending raster order
        order = _descending_raster(first, outer, windows)
        size = np.empty(order.shape[0])
        for k in range(order.shape[0]):
            c = order[k]
            size[k] = -(box[c, 2] - box[c, 0] + 1) * (box[c, 3] - box[c, 1] + 1)
        drop = _order(size)[MAX_SHAPES:]
        for k in drop:
            outer[order[k]] = False
    # renumber the kept shapes
    new = np.full(m, -1, np.int64)
    k = 0
    for c in range(m):
        if outer[c]:
            new[c] = k
            for q in range(4):
                box[k, q] = box[c, q]
            area[k] = area[c]
            sums[k, 0], sums[k, 1] = sums[c, 0], sums[c, 1]
            first[k, 0], first[k, 1] = first[c, 0], first[c, 1]
            window[k] = window[c]
            k += 1
    for r in range(n):
        comp[r] = new[comp[r]]
    return run_v[:n], run_s[:n], run_e[:n], comp, box[:k], area[:k], sums[:k], first[:k], window[:k]


@njit(cache=True, nogil=True, error_model="numpy")
def _scan_runs(gray, level_dn, windows, run_v, run_s, run_e, parent, gap, bg_s, bg_e, bg_parent):
    """The runs of pixels above ``level_dn`` of each window's rows, in raster order, joined
    by union-find (``parent``) with the previous row's runs they touch (8-connected); their
    count, or -1 when the arrays are too short.

    The background between them too (the gaps of rows that hold a run; ``bg_s``, ``bg_e``,
    from index 1), joined 4-connected by union-find (``bg_parent``) with the previous row's
    gaps, node 0 standing for the background outside the window (a whole row without a run,
    the window's edges and first and last rows reach it). ``gap[r]``: the gap just left of
    run r (-1 at the window's left edge): a shape whose first run's gap is not joined to
    node 0 lies in a hole of another shape."""
    cap = run_v.shape[0]
    cap_bg = bg_s.shape[0]
    level = np.uint8(level_dn)
    n = 0
    nb = 1
    bg_parent[0] = 0
    for w in range(windows.shape[0]):
        u0, v0, u1, v1 = windows[w, 0], windows[w, 1], windows[w, 2], windows[w, 3]
        width = u1 - u0
        prev_a, prev_b = n, n  # the previous row's runs
        prev_ga, prev_gb = nb, nb  # and gaps
        above = True  # the row above is all background (or outside the window)
        for v in range(v0, v1):
            row = gray[v, u0:u1]
            top = np.uint8(0)
            for x in row:  # (a maximum first, vectorised: most rows hold no shape)
                top = max(top, x)
            if top <= level:  # all background: the previous row's gaps reach the outside
                for q in range(prev_ga, prev_gb):
                    _join(bg_parent, q, 0)
                prev_a, prev_b = n, n
                prev_ga, prev_gb = nb, nb
                above = True
                continue
            edge = above or v == v1 - 1
            above = False
            cur_a, cur_g = n, nb
            u = 0
            while u < width:
                s = u
                if row[u] > level:
                    while u < width and row[u] > level:
                        u += 1
                    if n == cap:
                        return -1
                    run_v[n], run_s[n], run_e[n] = v, u0 + s, u0 + u
                    parent[n] = n
                    gap[n] = nb - 1 if s > 0 else -1
                    n += 1
                else:
                    while u < width and row[u] <= level:
                        u += 1
                    if nb == cap_bg:
                        return -1
                    bg_s[nb], bg_e[nb] = s, u
                    bg_parent[nb] = 0 if edge or s == 0 or u == width else nb
                    nb += 1
            # join with the previous row's runs that touch (8-connected): [s, e) and
            # [s2, e2) touch when s <= e2 and s2 <= e
            p = prev_a
            for r in range(cur_a, n):
                while p < prev_b and run_e[p] < run_s[r]:
                    p += 1
                q = p
                while q < prev_b and run_s[q] <= run_e[r]:
                    _join(parent, r, q)
                    q += 1
            # and the gaps with the previous row's gaps they share a column with (4-connected)
            p = prev_ga
            for r in range(cur_g, nb):
                while p < prev_gb and bg_e[p] <= bg_s[r]:
                    p += 1
                q = p
                while q < prev_gb and bg_s[q] < bg_e[r]:
                    _join(bg_parent, r, q)
                    q += 1
            prev_a, prev_b = cur_a, n
            prev_ga, prev_gb = cur_g, nb
    return n


@njit(cache=True, nogil=True, error_model="numpy")
def _join(parent, a, b):
    """Union of a's and b's sets; the smaller root stays the root."""
    a, b = _find(parent, a), _find(parent, b)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@njit(cache=True, nogil=True, error_model="numpy")
def _descending_raster(first, use, windows):
    """The shapes with ``use`` in descending raster order (v, then u) of their first pixel."""
    count = 0
    for c in range(first.shape[0]):
        if use[c]:
            count += 1
    idx = np.empty(count, np.int64)
    key = np.empty(count)
    k = 0
    span = 1
    for w in range(windows.shape[0]):
        span = max(span, windows[w, 2] + 1)
    for c in range(first.shape[0]):
        if use[c]:
            idx[k] = c
            key[k] = -float(first[c, 1] * span + first[c, 0])
            k += 1
    order = _order(key)
    out = np.empty(count, np.int64)
    for k in range(count):
        out[k] = idx[order[k]]
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def detect_windows(gray, keep, has_keep, windows, phase_u, step, threshold, noise_k, aperture_pad_px,
                   min_area_px, max_area_px, max_radius_px, max_elongation, min_contrast_dn, max_blobs):
    """The weighted detector on ``windows`` of ``gray`` (module docstring; the steps:
    :func:`humanpt.perception.weighted.detect_weighted`). Returns ``(uv, fields, moments,
    noise, saturated, rejected)`` of the n accepted blobs in descending raster order of
    each shape's first pixel: ``uv`` (n, 2) centres, ``fields`` (5, n) area, size,
    elongation, peak, flux, ``moments`` (n, 3) m_uu, m_vv, m_uv, ``noise`` (n, 2) the flux's
    and the anisotropy's SD, ``saturated`` (n,) aperture pixels at 255; ``rejected`` the
    shapes left out."""
    background, sigma = histogram_level(gray, keep, has_keep, windows, phase_u, step)
    level = max(threshold, background + noise_k * sigma)
    if level >= 255.0:
        return np.zeros((0, 2)), np.zeros((5, 0)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0, np.int64), 0
    level_dn = int(math.floor(level))
    run_v, run_s, run_e, comp, box, area, sums, first, window = label_runs(gray, level_dn, windows)
    m = box.shape[0]
    nothing = (np.zeros((0, 2)), np.zeros((5, 0)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0, np.int64))
    # candidates: area limits, not touching their window's edge, not larger than a source
    cand = np.zeros(m, np.bool_)
    for c in range(m):
        wd = windows[window[c]]
        w = box[c, 2] - box[c, 0] + 1
        h = box[c, 3] - box[c, 1] + 1
        cand[c] = (min_area_px <= area[c] <= max_area_px and box[c, 0] > wd[0] and box[c, 1] > wd[1]
                   and box[c, 2] + 1 < wd[2] and box[c, 3] + 1 < wd[3] and max(w, h) <= 2.0 * max_radius_px)
    order = _descending_raster(first, cand, windows)
    rejected = m - order.shape[0]
    if order.shape[0] > max_blobs:  # the largest, ties in that order
        neg = np.empty(order.shape[0])
        for k in range(order.shape[0]):
            neg[k] = -float(area[order[k]])
        best = _smallest(neg, max_blobs)
        rejected += order.shape[0] - max_blobs
        kept = np.empty(best.shape[0], np.int64)
        for k in range(best.shape[0]):
            kept[k] = order[best[k]]
        order = kept
    n = order.shape[0]
    if n == 0:
        return nothing[0], nothing[1], nothing[2], nothing[3], nothing[4], rejected
    # every candidate's window: S x S about its rounded centroid, S = 2 half + 1
    r_ap = np.empty(n)
    cu = np.empty(n)
    cv = np.empty(n)
    largest = 0.0
    for i in range(n):
        c = order[i]
        r_ap[i] = 0.5 * max(box[c, 2] - box[c, 0] + 1, box[c, 3] - box[c, 1] + 1) + aperture_pad_px
        largest = max(largest, r_ap[i])
        cu[i] = sums[c, 0] / area[c]
        cv[i] = sums[c, 1] / area[c]
    half = int(math.ceil(largest + _RING_PX + 1.0))
    size_w = 2 * half + 1
    # each shape's runs (a counting sort of the runs by shape): runs_of[first_run[c] ..
    # first_run[c + 1]] are shape c's
    first_run = np.zeros(m + 1, np.int64)
    for r in range(run_v.shape[0]):
        if comp[r] >= 0:
            first_run[comp[r] + 1] += 1
    for c in range(m):
        first_run[c + 1] += first_run[c]
    fill = first_run[:m].copy()
    runs_of = np.empty(first_run[m], np.int64)
    for r in range(run_v.shape[0]):
        if comp[r] >= 0:
            runs_of[fill[comp[r]]] = r
            fill[comp[r]] += 1
    out = np.zeros((n, 13))
    saturated = np.zeros(n, np.int64)
    ok = np.zeros(n, np.bool_)
    value = np.empty((size_w, size_w))  # grey level of a usable pixel, -1 otherwise
    for i in range(n):
        c = order[i]
        wd = windows[window[c]]
        xc = int(np.rint(cu[i]))
        yc = int(np.rint(cv[i]))
        x0, y0 = xc - half, yc - half
        # usable pixels: in the shape's window, not masked, and not another shape's (above
        # the level and not this shape's)
        for j in range(size_w):
            y = y0 + j
            for k in range(size_w):
                x = x0 + k
                if wd[0] <= x < wd[2] and wd[1] <= y < wd[3] and not (has_keep and keep[y, x] == 0):
                    g = gray[y, x]
                    value[j, k] = g if g <= level_dn else -1.0
                else:
                    value[j, k] = -1.0
        for k in range(first_run[c], first_run[c + 1]):
            r = runs_of[k]
            j = run_v[r] - y0
            if 0 <= j < size_w:
                y = run_v[r]
                for x in range(max(run_s[r], x0), min(run_e[r], x0 + size_w)):
                    if not (has_keep and keep[y, x] == 0):
                        value[j, x - x0] = gray[y, x]
        # the aperture and its ring about the estimate (relative to the window's centre
        # pixel: the distances are exact), re-centred _ITERATIONS times
        ra = r_ap[i]
        r2a = ra * ra
        rr = ra + _RING_PX
        r2r = rr * rr
        cx = cu[i] - xc
        cy = cv[i] - yc
        local_bg = background
        n_ring = 0.0
        flux = 0.0
        safe = 1.0
        good = False
        mom = np.zeros(6)
        top = 0.0
        full = 0
        for _ in range(_ITERATIONS):
            # integer sums (exact): count and grey level times 1, x, y, x^2, xy, y^2
            s0 = np.zeros(6)
            s1 = np.zeros(6)
            n_all = 0.0
            i_all = 0.0
            top = 0.0
            full = 0
            for j in range(size_w):
                gy = float(j - half)
                dy = gy - cy
                for k in range(size_w):
                    g = value[j, k]
                    if g < 0.0:
                        continue
                    gx = float(k - half)
                    dx = gx - cx
                    d2 = dx * dx
                    d2 += dy * dy
                    if d2 <= r2r:
                        n_all += 1.0
                        i_all += g
                        if d2 <= r2a:
                            s0[0] += 1.0
                            s0[1] += gx
                            s0[2] += gy
                            s0[3] += gx * gx
                            s0[4] += gx * gy
                            s0[5] += gy * gy
                            s1[0] += g
                            s1[1] += g * gx
                            s1[2] += g * gy
                            s1[3] += g * gx * gx
                            s1[4] += g * gx * gy
                            s1[5] += g * gy * gy
                            if g > top:
                                top = g
                            if g >= 255.0:
                                full += 1
            n_ring = n_all - s0[0]
            local_bg = (i_all - s1[0]) / max(n_ring, 1.0) if n_ring >= 8 else background
            for q in range(6):
                mom[q] = s1[q] - local_bg * s0[q]
            flux = mom[0]
            good = flux > 0
            safe = flux if good else 1.0
            if good:
                cx = mom[1] / safe
                cy = mom[2] / safe
        mxx = mom[3] / safe - cx * cx
        myy = mom[5] / safe - cy * cy
        mxy = mom[4] / safe - cx * cy
        peak = top - local_bg
        # the background noise of the flux and of the moments' anisotropy
        n_ap = math.pi * (ra * ra)
        flux_sd = sigma * math.sqrt(n_ap + n_ap * n_ap / max(n_ring, 1.0))
        aniso_sd = sigma * math.sqrt(math.pi / 12.0) * ra**3.0 / safe
        mean = 0.5 * (mxx + myy)
        spread = math.sqrt(0.25 * ((mxx - myy) * (mxx - myy)) + mxy * mxy)
        lam_major = mean + spread
        lam_minor = mean - spread
        elongation = math.sqrt(abs(lam_major / max(lam_minor, 1e-12))) if lam_minor > 0 else math.inf
        size = 4.0 * math.sqrt(max(lam_major - 1.0 / 12.0, 0.0))
        u = cx + xc
        v = cy + yc
        ok[i] = (good and peak >= min_contrast_dn and elongation <= max_elongation
                 and abs(u - cu[i]) <= ra and abs(v - cv[i]) <= ra)
        row = out[i]
        row[0], row[1], row[2], row[3], row[4], row[5], row[6] = u, v, area[c], size, elongation, peak, flux
        row[7], row[8], row[9], row[10], row[11] = mxx, myy, mxy, flux_sd, aniso_sd
        saturated[i] = full
    n_ok = 0
    for i in range(n):
        if ok[i]:
            n_ok += 1
    rejected += n - n_ok
    uv = np.empty((n_ok, 2))
    fields = np.empty((5, n_ok))  # area, size, elongation, peak, flux
    moments = np.empty((n_ok, 3))
    noise = np.empty((n_ok, 2))
    full_scale = np.empty(n_ok, np.int64)
    k = 0
    for i in range(n):
        if ok[i]:
            row = out[i]
            uv[k, 0], uv[k, 1] = row[0], row[1]
            for q in range(5):
                fields[q, k] = row[2 + q]
            moments[k, 0], moments[k, 1], moments[k, 2] = row[7], row[8], row[9]
            noise[k, 0], noise[k, 1] = row[10], row[11]
            full_scale[k] = saturated[i]
            k += 1
    return uv, fields, moments, noise, full_scale, rejected


@njit(cache=True, nogil=True, error_model="numpy")
def score_pairs(uv, size, area, peak, ii, jj, p, res, gates, sorted_sides_mm, max_candidates):
    """The scored correspondence's search (:func:`humanpt.perception.correspondence
    .match_scored`) on every ordered pair (``ii`` right, ``jj`` left) of n blobs with their
    eq. (4) points ``p`` (P, 3) and signed epipolar residuals ``res`` (P,): the gates, each
    candidate's chi-square, the ``max_candidates`` best, then the best set of three
    disjoint pairs whose triangle fits the model, the best two whose distance is one of its
    sides, and the best one.

    ``gates``: disparity low, high, |dv| limit, a_u * source diameter, b/2, size ratio low,
    high, depth low, high, epipolar tolerance, epipolar sigma, log area ratio limit, area
    sigma, peak sigma, side tolerance, side sigma. Returns the candidates' indices into the
    P pairs (c,), their chi-squares (c,), and the best three, two and one as indices into
    the candidates (-1: none)."""
    d_lo, d_hi, v_gate, a_diam, half_b = gates[0], gates[1], gates[2], gates[3], gates[4]
    lo, hi, z_lo, z_hi, tol_px, sigma_px = gates[5], gates[6], gates[7], gates[8], gates[9], gates[10]
    log_area_max, area_sigma, peak_sigma, side_tol, side_sigma = gates[11], gates[12], gates[13], gates[14], gates[15]
    n = uv.shape[0]
    top = 1e-6
    for i in range(n):
        top = max(top, max(peak[i], 1e-6))
    dim = np.empty(n)
    for i in range(n):
        dim[i] = math.log(top / max(peak[i], 1e-6))
    count = ii.shape[0]
    index = np.empty(count, np.int64)
    chi2 = np.empty(count)
    c = 0
    for k in range(count):
        i, j = ii[k], jj[k]
        du = uv[j, 0] - uv[i, 0]
        dv = uv[j, 1] - uv[i, 1]
        if not (du >= d_lo and du <= d_hi and abs(dv) <= v_gate):
            continue
        z = p[k, 2]
        expected = a_diam / (z + half_b)
        ratio_r, ratio_l = size[i] / expected, size[j] / expected
        log_area = math.log(area[i] / area[j])
        if not (z >= z_lo and z <= z_hi and abs(res[k]) <= tol_px and ratio_r >= lo and ratio_r <= hi
                and ratio_l >= lo and ratio_l <= hi and abs(log_area) <= log_area_max):
            continue
        e, a = res[k] / sigma_px, log_area / area_sigma
        index[c] = k
        chi2[c] = e * e + a * a + (dim[i] * dim[i] + dim[j] * dim[j]) / (peak_sigma * peak_sigma)
        c += 1
    index, chi2 = index[:c], chi2[:c]
    if c > max_candidates:  # the best, in their order
        best = _smallest(chi2, max_candidates)
        for k in range(best.shape[0]):  # (best is ascending: k <= best[k])
            index[k], chi2[k] = index[best[k]], chi2[best[k]]
        c = max_candidates
        index, chi2 = index[:c], chi2[:c]
    three = np.full(3, -1, np.int64)
    two = np.full(2, -1, np.int64)
    one = -1
    if c == 0:
        return index, chi2, three, two, one
    one = 0
    for a in range(1, c):
        if chi2[a] < chi2[one]:
            one = a
    side = np.empty(3)
    best_total = math.inf
    for a in range(c):
        ka = index[a]
        for b in range(a + 1, c):
            kb = index[b]
            if _share_a_blob(ii, jj, ka, kb):
                continue
            for d in range(b + 1, c):
                kd = index[d]
                if _share_a_blob(ii, jj, kd, ka) or _share_a_blob(ii, jj, kd, kb):
                    continue
                side[0] = _distance(p, ka, kb)
                side[1] = _distance(p, kb, kd)
                side[2] = _distance(p, kd, ka)
                _sort_small(side)
                fits = True
                for q in range(3):
                    if not abs(side[q] - sorted_sides_mm[q]) <= side_tol:
                        fits = False
                if not fits:
                    continue
                e0 = (side[0] - sorted_sides_mm[0]) / side_sigma
                e1 = (side[1] - sorted_sides_mm[1]) / side_sigma
                e2 = (side[2] - sorted_sides_mm[2]) / side_sigma
                total = (chi2[a] + chi2[b] + chi2[d]) + (e0 * e0 + e1 * e1 + e2 * e2)
                if total < best_total:
                    best_total = total
                    three[0], three[1], three[2] = a, b, d
    best_total = math.inf
    for a in range(c):
        ka = index[a]
        for b in range(a + 1, c):
            kb = index[b]
            if _share_a_blob(ii, jj, ka, kb):
                continue
            dist = _distance(p, ka, kb)
            err = math.inf
            for q in range(3):
                err = min(err, abs(dist - sorted_sides_mm[q]))
            if not err <= side_tol:
                continue
            e = err / side_sigma
            total = chi2[a] + chi2[b] + e * e
            if total < best_total:
                best_total = total
                two[0], two[1] = a, b
    return index, chi2, three, two, one


@njit(cache=True, nogil=True, error_model="numpy")
def _share_a_blob(ii, jj, a, b):
    """Do pairs a and b (blob indices ii, jj) have a blob in common?"""
    return ii[a] == ii[b] or ii[a] == jj[b] or jj[a] == ii[b] or jj[a] == jj[b]


@njit(cache=True, nogil=True, error_model="numpy")
def _distance(p, a, b):
    dx = p[a, 0] - p[b, 0]
    dy = p[a, 1] - p[b, 1]
    dz = p[a, 2] - p[b, 2]
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True, nogil=True, error_model="numpy")
def _max_nan(a, b):
    """The larger, NaN when either is (as ``np.max``)."""
    if a != a or b != b:
        return math.nan
    return max(a, b)


@njit(cache=True, nogil=True, error_model="numpy")
def _median3(a, b, c):
    """The median of three as sum - max - min (NaN when any is)."""
    return (a + b + c) - _max_nan(a, _max_nan(b, c)) - min(a, min(b, c))


@njit(cache=True, nogil=True, error_model="numpy")
def source_figures(jac, flux, moments, noise, has_noise, tol2, noise_k, tol_factor):
    """The blob checks' figures (:func:`humanpt.perception.checks.check_sources`) of the
    three sources A, B, C from ``jac`` (3, 2, 2, 2) each view's d(u, v)/d(s, t) of the
    source's disc, ``flux`` (3, 2), ``moments`` (3, 2, 3) (m_uu, m_vv, m_uv) and ``noise``
    (3, 2, 2) of their right and left blobs. Returns brightness, view log ratio,
    anisotropy (3,), their background noise SDs (3 checks, 3) and limits (3 checks, 3)."""
    det = np.empty((3, 2))
    q = np.empty((3, 2))
    disc_var = np.empty((3, 2))
    rest = np.empty((3, 2, 3))
    for k in range(3):
        for v in range(2):
            j00, j01, j10, j11 = jac[k, v, 0, 0], jac[k, v, 0, 1], jac[k, v, 1, 0], jac[k, v, 1, 1]
            det[k, v] = abs(j00 * j11 - j01 * j10)
            q[k, v] = flux[k, v] / (math.pi * det[k, v])
            disc_var[k, v] = det[k, v] / 4.0
            # the moments left after the predicted disc's (J J^T / 4)
            rest[k, v, 0] = moments[k, v, 0] - (j00 * j00 + j01 * j01) / 4.0
            rest[k, v, 1] = moments[k, v, 1] - (j10 * j10 + j11 * j11) / 4.0
            rest[k, v, 2] = moments[k, v, 2] - (j00 * j10 + j01 * j11) / 4.0
    brightness = np.empty(3)
    view_log_ratio = np.empty(3)
    anisotropy = np.empty(3)
    med_r = _median3(q[0, 0], q[1, 0], q[2, 0])
    med_l = _median3(q[0, 1], q[1, 1], q[2, 1])
    views = np.empty(3)
    for k in range(3):
        brightness[k] = math.sqrt((q[k, 0] / med_r) * (q[k, 1] / med_l))
        views[k] = math.log(q[k, 0] / q[k, 1])
    med_v = _median3(views[0], views[1], views[2])
    for k in range(3):
        view_log_ratio[k] = views[k] - med_v
    # what all six blobs share is not damage: the median blob's rest is taken off
    six = np.empty(6)
    for f in range(3):
        for k in range(3):
            six[2 * k], six[2 * k + 1] = rest[k, 0, f], rest[k, 1, f]
        _sort_small(six)
        shared = 0.5 * (six[2] + six[3])
        for k in range(3):
            rest[k, 0, f] -= shared
            rest[k, 1, f] -= shared
    for k in range(3):
        a0 = math.hypot(0.5 * (rest[k, 0, 0] - rest[k, 0, 1]), rest[k, 0, 2]) / disc_var[k, 0]
        a1 = math.hypot(0.5 * (rest[k, 1, 0] - rest[k, 1, 1]), rest[k, 1, 2]) / disc_var[k, 1]
        anisotropy[k] = _max_nan(a0, a1)
    sd = np.zeros((3, 3))
    if has_noise:
        rel = np.empty((3, 2))
        for k in range(3):
            for v in range(2):
                x = noise[k, v, 0] / flux[k, v]
                rel[k, v] = x * x
        total_r = rel[0, 0] + rel[1, 0] + rel[2, 0]
        total_l = rel[0, 1] + rel[1, 1] + rel[2, 1]
        for k in range(3):
            view_sd = math.sqrt((rel[k, 0] + total_r / 2.0) + (rel[k, 1] + total_l / 2.0))
            sd[0, k] = 0.5 * view_sd
            sd[1, k] = view_sd
            sd[2, k] = _max_nan(noise[k, 0, 1] / disc_var[k, 0], noise[k, 1, 1] / disc_var[k, 1])
    limits = np.empty((3, 3))
    for c in range(3):
        for k in range(3):
            x = noise_k * sd[c, k]
            limits[c, k] = math.sqrt(tol2[c] + x * x) * tol_factor
    return brightness, view_log_ratio, anisotropy, sd, limits


@njit(cache=True, nogil=True, error_model="numpy")
def merge_windows(uv, half_px, width, height):
    """Square windows ``(u0, v0, u1, v1)`` of half size ``half_px`` about centres (k, 2),
    clipped to the image; the first overlapping pair (i < j, in order) merged into i's
    place as their bounding box, j removed, until no two overlap; then the empty ones left
    out (:func:`humanpt.perception.blobs.windows_around`)."""
    n = uv.shape[0]
    b = np.empty((n, 4), np.int64)
    for i in range(n):
        b[i, 0] = int(max(math.floor(uv[i, 0] - half_px), 0.0))
        b[i, 1] = int(max(math.floor(uv[i, 1] - half_px), 0.0))
        b[i, 2] = int(min(math.ceil(uv[i, 0] + half_px) + 1.0, float(width)))
        b[i, 3] = int(min(math.ceil(uv[i, 1] + half_px) + 1.0, float(height)))
    merged = True
    while merged:
        merged = False
        for i in range(n):
            for j in range(i + 1, n):
                if b[i, 0] < b[j, 2] and b[j, 0] < b[i, 2] and b[i, 1] < b[j, 3] and b[j, 1] < b[i, 3]:
                    b[i, 0], b[i, 1] = min(b[i, 0], b[j, 0]), min(b[i, 1], b[j, 1])
                    b[i, 2], b[i, 3] = max(b[i, 2], b[j, 2]), max(b[i, 3], b[j, 3])
                    for r in range(j, n - 1):
                        for q in range(4):
                            b[r, q] = b[r + 1, q]
                    n -= 1
                    merged = True
                    break
            if merged:
                break
    k = 0
    for i in range(n):
        if b[i, 2] > b[i, 0] and b[i, 3] > b[i, 1]:
            for q in range(4):
                b[k, q] = b[i, q]
            k += 1
    return b[:k]
