"""The PSVS complex image, rendered: pure numpy, no runtime needed.

Pipeline (one image):

1. **Scene** (:meth:`Renderer.discs`): the TOB's three planar circular sources in the
   camera frame, plus optional clutter - their mirror images in a shiny plane fixed to the
   TOB, and a bright lamp - as :class:`Discs` (centre, in-plane axes, lit normal, radius,
   radiance, extra blur, occlusion).
2. **Projection** (:meth:`Renderer.blobs`): each disc through each virtual camera (right,
   left; eq. (1)-(3), each with its own principal point and rotation - a tilted mirror)
   and the real lens's distortion; optionally dimmed by the source's angular fall-off
   (``source_falloff_exponent``) and doubled by the beam splitter's ghost (``ghost_gain``). A disc is dropped from a view when it
   is behind (or nearer than ``near_mm`` to) that virtual camera, when its lit face looks
   away from it, or when its window misses the image. Around its projected centre a disc is
   the unit circle mapped by the local Jacobian ``J = d(u, v)/d(s, t)`` (pinhole and
   distortion, (s, t) in disc radii) - exact to first order (perspective and distortion
   curvature across a 5 mm disc move its edge by well under 0.01 px).
3. **Coverage** (:func:`coverage`): the exact area of each pixel inside the (possibly
   partly occluded) ellipse - every pixel square is mapped into the disc's frame, clipped
   by the occluder's half plane and intersected with the unit circle analytically - so
   the centroid carries no sampling bias (only the pixel-locking inherent in any pixel
   grid: below 0.005 px for the default 7.8 px blobs, below 0.01 px from 4 px blobs).
4. **Optics**: a Gaussian point spread (``blur_sigma_px``, plus a disc's own extra blur),
   applied as a separable, normalised, symmetric kernel - it moves no centroid.
5. **Sensor** (:meth:`Renderer.expose`): background (black level + ambient), shot noise
   (Poisson in electrons), read noise (Gaussian), full well, rounding to 8 bits, clipping
   at 255. Views are superimposed by adding their signals before the sensor. Optional:
   fixed-pattern noise (``dsnu_dn``, ``prnu``: one pattern per seed) and blooming along
   the columns (``blooming``, :func:`bloom_columns`).
6. **Exposure** (:meth:`Renderer.exposure_signal_pixels`): given the poses at the start
   and end of the exposure, the signal is averaged over sub-exposures (motion blur).

Speed: only small windows around each blob are rendered (:meth:`Renderer.signal_pixels`:
the nonzero pixels, no full frame); coverage runs in the window that holds the ellipse and
computes exact areas only for the pixels its boundary crosses. The (uniform) background
comes from a bank of independent draws of the exact quantised background distribution
(:func:`background_table`), built once per seed: each frame copies the run at an offset
drawn from its own generator, so every pixel has exactly that distribution and the same
pixel sees a different draw in every frame (two frames' runs often overlap in the bank,
shifted: one frame's background may be a shifted copy of part of another's, which leaves
per-pixel statistics and the blobs' centroid noise as they are). The pixels a blob touches
get exact Poisson + Gaussian noise.

Units: mm in the camera frame, pixels of the complex image (centre of pixel (row i,
column j) at (u, v) = (j, i)), DN (grey levels).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from humanpt.geometry import PsvsParams, distort_pixels
from humanpt.geometry.transforms import interpolate_transform

from .config import SimCameraConfig

__all__ = [
    "Discs",
    "Blobs",
    "Renderer",
    "coverage",
    "occlusion_offset",
    "background_table",
    "intensity_centroid",
]

VIEWS = ("right", "left")
# A source's axes in the TOB frame: e1 = u, e2 = v, lit normal -w.
_TOB_AXES = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]]).T
_TOB_AXES.flags.writeable = False
_MAX_SUBEXPOSURES = 64  # motion blur: sub-exposures of one image at most
_MAX_HALF_WINDOW_PX = 400  # a blob wider than 800 px (a source ~1 cm from the lens) is dropped


# --------------------------------------------------------------------------- scene


@dataclass(frozen=True)
class Discs:
    """n planar circular light sources in the camera frame.

    ``centre_mm`` (n, 3); ``axes`` (n, 3, 3) with columns e1, e2 (unit, in the disc's
    plane) and the lit normal (unit, the side the light leaves from); ``radius_mm`` (n,);
    ``dn_per_ms`` (n,) radiance (DN per ms of exposure for a fully covered pixel, before the
    view gain); ``blur_px`` (n,) extra Gaussian blur; ``occlusion_h`` (n,) and
    ``occlusion_dir`` (n, 2): the disc is visible where ``dir . (s, t) <= h`` ((s, t) in
    radii along e1, e2; h >= 1 means nothing hidden); ``label`` (n,) an integer tag
    (0, 1, 2 = sources A, B, C; 10 + i their reflections; 20 the lamp).
    """

    centre_mm: np.ndarray
    axes: np.ndarray
    radius_mm: np.ndarray
    dn_per_ms: np.ndarray
    blur_px: np.ndarray
    occlusion_h: np.ndarray
    occlusion_dir: np.ndarray
    label: np.ndarray

    @staticmethod
    def make(
        centre_mm,
        axes,
        radius_mm,
        dn_per_ms,
        blur_px=0.0,
        occlusion_h=1.0,
        occlusion_dir=(1.0, 0.0),
        label=0,
    ) -> Discs:
        """Build from array-likes; scalars broadcast to the number of centres."""
        c = np.asarray(centre_mm, dtype=float).reshape(-1, 3)
        n = len(c)

        def vec(v, shape=()):
            return np.broadcast_to(np.asarray(v, dtype=float), (n, *shape)).copy()

        return Discs(
            c,
            vec(axes, (3, 3)),
            vec(radius_mm),
            vec(dn_per_ms),
            vec(blur_px),
            vec(occlusion_h),
            vec(occlusion_dir, (2,)),
            np.broadcast_to(np.asarray(label, dtype=int), (n,)).copy(),
        )

    @staticmethod
    def concat(parts: list[Discs]) -> Discs:
        parts = [p for p in parts if len(p)]
        if not parts:
            return Discs.make(np.zeros((0, 3)), np.eye(3), 1.0, 0.0)
        if len(parts) == 1:
            return parts[0]
        return Discs(*(np.concatenate([getattr(p, f) for p in parts]) for f in Discs._fields()))

    @staticmethod
    def _fields() -> tuple[str, ...]:
        return (
            "centre_mm",
            "axes",
            "radius_mm",
            "dn_per_ms",
            "blur_px",
            "occlusion_h",
            "occlusion_dir",
            "label",
        )

    def __len__(self) -> int:
        return len(self.centre_mm)


def occlusion_offset(fraction: float) -> float:
    """Offset h of the straight edge that hides ``fraction`` of a unit disc (the part
    beyond ``dir . q > h``): solves ``(acos h - h sqrt(1 - h^2)) / pi = fraction``.
    0 -> 1 (nothing hidden), 0.5 -> 0, 1 -> -1."""
    f = float(fraction)
    if not 0.0 <= f <= 1.0:
        raise ValueError(f"occluded fraction must be in [0, 1], got {f}")
    lo, hi = -1.0, 1.0
    for _ in range(60):  # bisection: the hidden area falls monotonically with h
        mid = 0.5 * (lo + hi)
        hidden = (math.acos(mid) - mid * math.sqrt(1.0 - mid * mid)) / math.pi
        if hidden > f:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _perpendicular_axes(normal: np.ndarray) -> np.ndarray:
    """(n, 3, 3) axes [e1, e2, normal] for unit normals (n, 3)."""
    helper = np.where(
        np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    )
    e1 = np.cross(helper, normal)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(normal, e1)
    return np.stack([e1, e2, normal], axis=-1)


# --------------------------------------------------------------------------- projection


@dataclass(frozen=True)
class Blobs:
    """m projected discs (a disc seen in a view is one blob).

    ``centre_px`` (m, 2) the projected (distorted) disc centre, u, v; ``jac`` (m, 2, 2)
    ``d(u, v)/d(s, t)`` with (s, t) in disc radii; ``dn`` (m,) DN of a fully covered pixel
    at this exposure, after the view gain; ``sigma_px`` (m,) total blur; ``occlusion_h``,
    ``occlusion_dir`` as in :class:`Discs`; ``view`` (m,) 0 right, 1 left; ``disc`` (m,)
    index into the discs; ``label`` (m,) the disc's label (100 + it for the splitter's
    ghost of a blob).
    """

    centre_px: np.ndarray
    jac: np.ndarray
    dn: np.ndarray
    sigma_px: np.ndarray
    occlusion_h: np.ndarray
    occlusion_dir: np.ndarray
    view: np.ndarray
    disc: np.ndarray
    label: np.ndarray

    def __len__(self) -> int:
        return len(self.centre_px)

    def half_extent_px(self) -> np.ndarray:
        """(m, 2) half widths of the (unblurred) ellipse along u and v."""
        return np.sqrt(np.sum(self.jac**2, axis=2))


def _distortion_jacobian(params: PsvsParams, uv_ideal: np.ndarray) -> np.ndarray:
    """d(observed px)/d(ideal px), (m, 2, 2), by central differences (the model is a
    smooth polynomial; 1e-3 px steps are exact to ~1e-9)."""
    m = len(uv_ideal)
    if not params.has_distortion:
        return np.broadcast_to(np.eye(2), (m, 2, 2)).copy()
    h = 1e-3
    k = params.real_camera_matrix
    out = np.empty((m, 2, 2))
    for j in range(2):
        step = np.zeros(2)
        step[j] = h
        plus = distort_pixels(uv_ideal + step, k, params.dist_coeffs)
        minus = distort_pixels(uv_ideal - step, k, params.dist_coeffs)
        out[:, :, j] = (plus - minus) / (2 * h)
    return out


def _no_blobs() -> Blobs:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=int)
    return Blobs(np.zeros((0, 2)), np.zeros((0, 2, 2)), z, z, z, np.zeros((0, 2)), zi, zi, zi)


def project_discs(
    params: PsvsParams,
    discs: Discs,
    view_gains: tuple[float, float],
    exposure_ms: float,
    blur_sigma_px: float,
    near_mm: float = 10.0,
    falloff_exponent: float = 0.0,
) -> Blobs:
    """Project every disc through both virtual cameras; keep the visible blobs (see the
    module docstring for what hides one). Blobs are ordered right view first, then left,
    each in disc order. Both views in one vectorised pass (eq. (2) and its Jacobian
    written out: the formulas of the geometry library's ``project_pinhole`` and
    ``projection_jacobian``, with each virtual camera's own principal point and rotation).
    ``falloff_exponent`` n > 0 dims each blob by ``cos(angle)^n``, the angle between the
    disc's lit normal and the direction to that virtual camera (0: a Lambertian source,
    the same radiance from every direction)."""
    width, height = params.image_size_px
    n = len(discs)
    views = [v for v in (0, 1) if view_gains[v] > 0] if n else []
    if not views:
        return _no_blobs()
    cams = [(params.right_camera, params.left_camera)[v] for v in views]
    # (view, disc) pairs, view-major: rel (V, n, 3) from each optical centre.
    rel = discs.centre_mm - np.array([c.centre_mm for c in cams])[:, None]
    dist = np.sqrt(np.einsum("vni,vni->vn", rel, rel))
    toward = -np.einsum("vni,ni->vn", rel, discs.axes[:, :, 2])  # lit normal . to-camera * dist
    rotated = not all(c.is_parallel for c in cams)
    if rotated:  # each view's own axes (a tilted mirror): R^T (P - O), as project_pinhole
        rots = np.array([c.rotation for c in cams])  # (V, 3, 3)
        rel = np.einsum("vni,vij->vnj", rel, rots)
    ok = (rel[:, :, 2] > near_mm) & (toward > 1e-6 * np.maximum(dist, 1e-12))
    ok &= (discs.dn_per_ms > 0) & (discs.occlusion_h > -1.0)
    keep = np.flatnonzero(ok)
    if keep.size == 0:
        return _no_blobs()
    row, disc = np.divmod(keep, n)
    # brightness factor of each (view, disc): the source's angular fall-off cos^n
    cos_view = (toward / np.maximum(dist, 1e-12)).reshape(-1).take(keep)
    rel = rel.reshape(-1, 3).take(keep, axis=0)
    per_row = not (len(cams) == 1 or _same_intrinsics(cams[0], cams[1]))
    if per_row:
        a_u, a_v, u0, v0, skew = (
            np.array([getattr(c, f) for c in cams])[row] for f in ("a_u", "a_v", "u0", "v0", "skew")
        )
    else:
        cam = cams[0]
        a_u, a_v, u0, v0, skew = cam.a_u, cam.a_v, cam.u0, cam.v0, cam.skew
    inv_z = 1.0 / rel[:, 2]
    x = rel[:, 0] * inv_z
    y = rel[:, 1] * inv_z
    uv_ideal = np.empty((len(x), 2))
    uv_ideal[:, 0] = u0 + a_u * x + skew * y
    uv_ideal[:, 1] = v0 + a_v * y
    # Far outside the image the distortion polynomial is meaningless: drop those first.
    near_image = (
        (uv_ideal > (-0.5 * width, -0.5 * height)) & (uv_ideal < (1.5 * width, 1.5 * height))
    ).all(axis=1)
    if not near_image.all():
        sel = np.flatnonzero(near_image)
        if sel.size == 0:
            return _no_blobs()
        inv_z, x, y, row, disc, uv_ideal, cos_view = (
            a[sel] for a in (inv_z, x, y, row, disc, uv_ideal, cos_view)
        )
        if per_row:
            a_u, a_v, skew = a_u[sel], a_v[sel], skew[sel]
    # d(u, v)/d(s, t): eq. (2)'s Jacobian d(u, v)/d(x, y, z) times the disc's in-plane axes
    # P (columns e1, e2, in radii): du = (a_u (P_x - x P_z) + skew (P_y - y P_z)) / z,
    # dv = a_v (P_y - y P_z) / z, with x = X/Z, y = Y/Z.
    axes = discs.axes.take(disc, axis=0)[:, :, :2]  # (k, 3, 2) camera frame
    if rotated:
        axes = np.swapaxes(rots, 1, 2).take(row, axis=0) @ axes  # R^T e: the view's frame
    plane = axes * (discs.radius_mm.take(disc) * inv_z)[:, None, None]  # (k, 3, 2), / z
    along_x = plane[:, 0] - x[:, None] * plane[:, 2]
    along_y = plane[:, 1] - y[:, None] * plane[:, 2]
    jac = np.empty((len(x), 2, 2))
    if per_row:
        a_u, a_v, skew = a_u[:, None], a_v[:, None], skew[:, None]
        jac[:, 0] = a_u * along_x + skew * along_y
    elif skew == 0.0:
        jac[:, 0] = a_u * along_x
    else:
        jac[:, 0] = a_u * along_x + skew * along_y
    jac[:, 1] = a_v * along_y
    if params.has_distortion:
        jac = _distortion_jacobian(params, uv_ideal) @ jac
        uv = distort_pixels(uv_ideal, params.real_camera_matrix, params.dist_coeffs)
    else:
        uv = uv_ideal
    sigma = np.sqrt(blur_sigma_px**2 + discs.blur_px.take(disc) ** 2)
    ext = np.sqrt((jac * jac).sum(axis=2)) + (4.0 * sigma + 2.0)[:, None]
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    in_image = ((uv + ext > -0.5) & (uv - ext < (width - 0.5, height - 0.5))).all(axis=1)
    in_image &= (ext.max(axis=1) < _MAX_HALF_WINDOW_PX) & (np.abs(det) > 1e-9)
    if not in_image.all():
        sel = np.flatnonzero(in_image)
        if sel.size == 0:
            return _no_blobs()
        uv, jac, sigma, row, disc = uv[sel], jac[sel], sigma[sel], row[sel], disc[sel]
        cos_view = cos_view[sel]
    view = np.array(views).take(row)
    dn = discs.dn_per_ms.take(disc) * exposure_ms * np.asarray(view_gains, dtype=float).take(view)
    if falloff_exponent > 0:
        dn = dn * np.clip(cos_view, 0.0, 1.0) ** falloff_exponent
    return Blobs(
        uv,
        jac,
        dn,
        sigma,
        discs.occlusion_h.take(disc),
        discs.occlusion_dir.take(disc, axis=0),
        view,
        disc,
        discs.label.take(disc),
    )


def _same_intrinsics(a, b) -> bool:
    return (a.a_u, a.a_v, a.u0, a.v0, a.skew) == (b.a_u, b.a_v, b.u0, b.v0, b.skew)


# --------------------------------------------------------------------------- exact coverage


def _edge_areas(ax, ay, rr, dx, dy, aa, inv_aa) -> np.ndarray:
    """Signed area of (unit disc) intersected with the triangle (origin, a, a + d), for
    arrays of segments from a = (ax, ay) along d = (dx, dy); ``rr = |a|^2``,
    ``aa = |d|^2``, ``inv_aa = 1 / aa`` (any finite value where aa = 0). Summed over a
    closed polygon's edges it gives the polygon's intersection with the unit disc (signed
    by the polygon's orientation).

    The segment meets the circle at p1 = a + t1 d and p2 = a + t2 d (t clipped to [0, 1]):
    outside the circle the boundary is an arc - the sectors a -> p1 and p2 -> b - inside
    it is the chord p1 -> p2. With X = a x d and B = a . d: a x p1 = t1 X,
    a . p1 = rr + t1 B, p2 x b = (1 - t2) X, p2 . b = rr + B + t2 (B + aa),
    p1 x p2 = (t2 - t1) X. Where the line misses the circle, t1 = t2 is the segment's point
    nearest the origin and the two sectors add up to the whole sector a -> b; a zero-length
    edge (aa = 0, hence X = B = 0) has no area."""
    cross = ax * dy - ay * dx
    dot = ax * dx + ay * dy
    root = np.sqrt(np.maximum(dot * dot - aa * (rr - 1.0), 0.0))
    t1 = np.clip((-dot - root) * inv_aa, 0.0, 1.0)
    t2 = np.clip((root - dot) * inv_aa, 0.0, 1.0)
    sector1 = np.arctan2(t1 * cross, rr + t1 * dot)
    sector2 = np.arctan2((1.0 - t2) * cross, (rr + dot) + t2 * (dot + aa))
    return 0.5 * (sector1 + sector2 + (t2 - t1) * cross)


def _segment_circle_area(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`_edge_areas` of the segments a -> b, points (..., 2)."""
    ax, ay = a[..., 0], a[..., 1]
    dx, dy = b[..., 0] - ax, b[..., 1] - ay
    aa = dx * dx + dy * dy
    return _edge_areas(ax, ay, ax * ax + ay * ay, dx, dy, aa, 1.0 / np.where(aa > 0, aa, 1.0))


def _clip_quads(quads: np.ndarray, direction: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Clip convex quads (e, 4, 2) to the half plane ``direction . q <= h``; returns
    (e, 8, 2) polygons (missing vertices repeat the previous one: zero-length edges)."""
    f = np.einsum("eki,ei->ek", quads, direction) - h[:, None]  # > 0: hidden
    inside = f <= 0.0
    nxt = np.roll(quads, -1, axis=1)
    f_next = np.roll(f, -1, axis=1)
    inside_next = np.roll(inside, -1, axis=1)
    denom = f - f_next
    t = np.where(np.abs(denom) > 0, f / np.where(denom == 0, 1.0, denom), 0.0)
    crossing = quads + t[..., None] * (nxt - quads)
    slots = np.empty((len(quads), 8, 2))
    valid = np.empty((len(quads), 8), dtype=bool)
    slots[:, 0::2] = quads
    slots[:, 1::2] = crossing
    valid[:, 0::2] = inside
    valid[:, 1::2] = inside != inside_next
    # Cyclic forward fill of the missing slots (two passes reach every slot).
    for k in range(16):
        i, prev = k % 8, (k - 1) % 8
        fill = ~valid[:, i] & valid[:, prev]
        slots[fill, i] = slots[fill, prev]
        valid[:, i] |= fill
    slots[~valid] = 0.0  # nothing visible at all: a degenerate polygon, area 0
    return slots


def coverage(blobs: Blobs, half: int) -> tuple[np.ndarray, np.ndarray]:
    """Exact pixel coverage of each blob's (clipped) ellipse in a (2 half + 1)^2 window.

    Returns (coverage (m, K, K) in [0, 1], window origins (m, 2) as (column, row) of the
    window's first pixel). Pixels entirely inside get 1 and pixels surely outside 0 without
    the exact computation, which only runs on the edge pixels.
    """
    size = 2 * half + 1
    n1 = size + 1  # corners per side
    centre = blobs.centre_px
    origin = np.round(centre).astype(int) - half  # (m, 2) = (u0, v0)
    j = blobs.jac
    det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
    # J^-1 (pixel offsets -> (s, t) radii): rows (i00, i01, i10, i11), (4, m).
    jinv = np.stack([j[:, 1, 1], -j[:, 0, 1], -j[:, 1, 0], j[:, 0, 0]]) / det
    i00, i01, i10, i11 = jinv[:, :, None, None]
    grid = np.arange(n1) - 0.5
    offset = origin - centre
    du = offset[:, 0, None, None] + grid  # (m, 1, K+1): corner columns
    dv = offset[:, 1, None, None] + grid[:, None]  # (m, K+1, 1): corner rows
    # Pixel corners in disc coordinates: (m, K+1 rows, K+1 cols).
    s = i00 * du + i01 * dv
    t = i10 * du + i11 * dv
    rr = s * s + t * t
    inside = rr <= 1.0
    occluded = blobs.occlusion_h < 1.0  # h >= 1: the half plane holds the whole disc
    if occluded.any():
        od, oh = blobs.occlusion_dir, blobs.occlusion_h
        inside &= od[:, 0, None, None] * s + od[:, 1, None, None] * t <= oh[:, None, None]
    all_in = inside[:, :-1, :-1] & inside[:, :-1, 1:] & inside[:, 1:, 1:] & inside[:, 1:, :-1]
    # Every pixel is the same parallelogram in disc coordinates: a pixel whose centre is
    # farther than 1 + its circumradius from the disc's centre is surely outside.
    sc = s[:, :-1, :-1] + s[:, 1:, 1:]  # twice the pixel centres
    tc = t[:, :-1, :-1] + t[:, 1:, 1:]
    diag = np.maximum((i00 + i01) ** 2 + (i10 + i11) ** 2, (i00 - i01) ** 2 + (i10 - i11) ** 2)
    edge = sc * sc + tc * tc <= (2.0 + np.sqrt(diag)) ** 2  # 2 circumradius = sqrt(diag)
    edge &= ~all_in
    # Edge pixels by their first corner's flat index in the (m, K+1, K+1) corner grids.
    grid_edge = np.zeros(s.shape, dtype=bool)
    grid_edge[:, :-1, :-1] = edge
    base = np.flatnonzero(grid_edge)
    cov = np.zeros(s.shape)
    cov[:, :-1, :-1] = all_in
    if base.size:
        mi = base // (n1 * n1)
        # Corners of each edge pixel in order around it: (r, c), (r, c + 1), (r + 1, c + 1),
        # (r + 1, c). Its edges run along +column, +row, -column, -row: the same vectors
        # for every pixel of a blob.
        here = base[:, None] + np.array([0, 1, n1 + 1, n1])
        ax, ay = s.take(here), t.take(here)  # (e, 4)
        dx = jinv[[0, 1, 0, 1]].T * _EDGE_SIGNS  # (m, 4)
        dy = jinv[[2, 3, 2, 3]].T * _EDGE_SIGNS
        aa = dx * dx + dy * dy
        occ = occluded.take(mi)
        if not occ.any():
            area = _edge_areas(
                ax,
                ay,
                rr.take(here),
                dx.take(mi, axis=0),
                dy.take(mi, axis=0),
                aa.take(mi, axis=0),
                (1.0 / aa).take(mi, axis=0),
            ).sum(axis=1)
        else:
            area = np.empty(base.size)
            p = np.flatnonzero(~occ)
            k = mi[p]
            area[p] = _edge_areas(
                ax[p], ay[p], rr.take(here[p]), dx[k], dy[k], aa[k], 1.0 / aa[k]
            ).sum(axis=1)
            cut = np.flatnonzero(occ)
            k = mi[cut]
            poly = _clip_quads(
                np.stack([ax[cut], ay[cut]], axis=-1),
                blobs.occlusion_dir[k],
                blobs.occlusion_h[k],
            )
            area[cut] = _segment_circle_area(poly, np.roll(poly, -1, axis=1)).sum(axis=1)
        # Pixel area in disc coordinates: |det J^-1| = 1 / |det J|.
        cov.put(base, np.clip(np.abs(area) * np.abs(det).take(mi), 0.0, 1.0))
    return cov[:, :-1, :-1], origin


_EDGE_SIGNS = np.array([1.0, 1.0, -1.0, -1.0])


@lru_cache(maxsize=256)
def _blur_matrix(sigma: float, size: int) -> np.ndarray:
    """(K, K) banded matrix M with (M @ W @ M^T) = W convolved with a normalised,
    symmetric sampled Gaussian of sigma (truncated at 4 sigma); identity for sigma = 0.
    Read-only (cached)."""
    if sigma <= 1e-6:
        g = np.eye(size)
    else:
        k = np.arange(size)
        diff = (k[:, None] - k[None, :]).astype(float)  # (K, K)
        radius = math.ceil(4.0 * sigma)
        taps = np.arange(-radius, radius + 1)
        norm = np.sum(np.exp(-0.5 * (taps / sigma) ** 2))
        g = np.exp(-0.5 * (diff / sigma) ** 2) / norm
        g[np.abs(diff) > radius] = 0.0
    g.flags.writeable = False
    return g


def _blur(windows: np.ndarray, sigma: np.ndarray, size: int) -> np.ndarray:
    """Each window (m, k, k) convolved with its own Gaussian (separable, normalised) into
    a (m, size, size) window with the same centre (size - k even, >= 0): as if the input
    were padded with zeros to that size."""
    off = (size - windows.shape[1]) // 2
    cut = np.s_[off : off + windows.shape[1]]
    if np.all(sigma == sigma[0]):
        g = _blur_matrix(float(sigma[0]), size)[:, cut]
        return g @ windows @ g.T
    g = np.stack([_blur_matrix(float(s), size)[:, cut] for s in sigma])
    return g @ windows @ np.swapaxes(g, 1, 2)


@lru_cache(maxsize=64)
def _window_offsets(size: int, width: int) -> np.ndarray:
    """(size, size) flat-index offsets of a window's pixels from its first, in an image
    ``width`` pixels wide (read-only)."""
    k = np.arange(size)
    out = k[:, None] * width + k[None, :]
    out.flags.writeable = False
    return out


# --------------------------------------------------------------------------- sensor


def background_table(
    mean_e: float, read_noise_e: float, gain_e_per_dn: float, black_dn: float, full_well_e: float
) -> np.ndarray:
    """Inverse CDF (65536 entries, uint8) of a background pixel's grey level:
    ``clip(round(black + (min(Poisson(mean_e), full_well) + N(0, read)) / gain), 0, 255)``.
    Indexing it with uniform 16-bit numbers draws that distribution (to 2^-16)."""
    from scipy.special import ndtr  # here: scipy.stats costs ~0.5 s at import, once per table
    from scipy.stats import poisson

    lo = max(0, int(mean_e - 12 * math.sqrt(mean_e + 1) - 12))
    hi = int(mean_e + 12 * math.sqrt(mean_e + 1) + 12)
    n = np.arange(lo, hi + 1)
    p_n = poisson.pmf(n, mean_e)
    n = np.minimum(n, full_well_e)
    edges_dn = np.arange(-0.5, 256.0, 1.0)  # grey level k covers [k - .5, k + .5) DN
    edges_e = (edges_dn - black_dn) * gain_e_per_dn  # the same edges in electrons
    if read_noise_e > 0:
        cdf_at = ndtr((edges_e[None, :] - n[:, None]) / read_noise_e)  # (N, 257)
    else:
        cdf_at = (n[:, None] < edges_e[None, :]).astype(float)
    cdf_edges = p_n @ cdf_at  # P(value < edge)
    cdf_edges[0], cdf_edges[-1] = 0.0, 1.0  # clipping: everything below 0 is 0, above 255 is 255
    cdf = cdf_edges[1:] / p_n.sum()  # P(grey <= k), k = 0..255
    cdf[-1] = 1.0
    u = (np.arange(65536) + 0.5) / 65536.0
    return np.searchsorted(cdf, u, side="right").clip(0, 255).astype(np.uint8)


_BANK_OFFSETS = 1 << 20  # placements of the background bank (each frame draws one)
_BANK_KEY = 0x62616E6B  # the bank's own random stream, apart from every [seed, frame_index]


@lru_cache(maxsize=4)
def _background_bank(seed: int, table: bytes, n_pixels: int) -> np.ndarray:
    """``n_pixels + 2^20`` background grey levels (uint8, read-only), each an independent
    draw of the distribution ``table`` holds (the inverse CDF of :func:`background_table`,
    indexed with uniform 16-bit numbers). A frame's background is the ``n_pixels`` run
    starting at a random offset: every pixel exactly that distribution, independent
    within the frame; the same pixel of two frames has the same value only when they drew
    the same offset (probability 2^-20), though two frames' runs may overlap shifted."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_BANK_KEY,)))
    uniform = np.frombuffer(rng.bytes(2 * (n_pixels + _BANK_OFFSETS)), dtype=np.uint16)
    bank = np.frombuffer(table, dtype=np.uint8).take(uniform)
    bank.flags.writeable = False
    return bank


_FPN_KEY = 0x66706E  # the fixed pattern's own random stream ("fpn"), fixed per seed


@lru_cache(maxsize=4)
def _fixed_pattern_unit(seed: int, n_pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """Two standard-normal fields (n_pixels,) float32, read-only, drawn once per seed: the
    shapes of the DSNU (offset) and PRNU (gain) patterns, scaled by the config's sizes (so
    a larger ``dsnu_dn`` is the same pattern, stronger)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_FPN_KEY,)))
    offset = rng.standard_normal(n_pixels, dtype=np.float32)
    gain = rng.standard_normal(n_pixels, dtype=np.float32)
    offset.flags.writeable = False
    gain.flags.writeable = False
    return offset, gain


@lru_cache(maxsize=4)
def _noise_bank(seed: int, mean_e: float, read_noise_e: float, full_well_e: float, n_pixels: int):
    """``n_pixels + 2^20`` unquantised background charges (float32 electrons, read-only):
    ``min(Poisson(mean_e), full_well) + N(0, read)``, independent draws - the background
    bank of the fixed-pattern path, where every pixel has its own offset and gain and so
    its own quantised distribution (:func:`_background_bank` holds one distribution)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_BANK_KEY, 1)))
    size = n_pixels + _BANK_OFFSETS
    bank = np.minimum(rng.poisson(mean_e, size), full_well_e).astype(np.float32)
    if read_noise_e > 0:
        bank += rng.normal(0.0, read_noise_e, size).astype(np.float32)
    bank.flags.writeable = False
    return bank


def bloom_columns(
    idx: np.ndarray,
    charge_e: np.ndarray,
    shape: tuple[int, int],
    full_well_e: float,
    spill: float,
    background_e: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blooming: the charge above the full well of the pixels at flat (row-major) indices
    ``idx`` (charges ``charge_e``, electrons) spills along their columns.

    Each pixel over the well keeps ``full_well_e`` and passes ``spill`` of its excess on,
    half up, half down; a neighbour takes what fits below its well and passes the rest
    further; charge that leaves the image is lost (so is the remaining ``1 - spill``).
    Pixels not in ``idx`` hold ``background_e``. Returns (the charges at ``idx``, now
    <= full well; the flat indices of the other pixels that received charge; the charge
    (e-) each received)."""
    height, width = int(shape[0]), int(shape[1])
    charge = np.asarray(charge_e, dtype=np.float64).copy()
    over = charge > full_well_e
    none = np.zeros(0, dtype=np.intp), np.zeros(0)
    if spill <= 0 or not over.any():
        return np.minimum(charge, full_well_e), *none
    rows, cols = np.divmod(np.asarray(idx), width)
    columns = np.unique(cols[over])
    in_cols = np.isin(cols, columns)
    excess = (charge - full_well_e).clip(0.0) * spill
    per_col = np.zeros(len(columns))
    np.add.at(per_col, np.searchsorted(columns, cols[over]), excess[over])
    room = max(full_well_e - background_e, 1e-9)
    reach = int(min(math.ceil(per_col.max() / room) + 1, height))
    r0 = max(int(rows[in_cols].min()) - reach, 0)
    r1 = min(int(rows[in_cols].max()) + reach, height - 1)
    box = np.full((r1 - r0 + 1, len(columns)), float(background_e))
    member = np.full(box.shape, -1, dtype=np.intp)
    sel = np.flatnonzero(in_cols)
    ri, ci = rows[sel] - r0, np.searchsorted(columns, cols[sel])
    box[ri, ci] = charge[sel]
    member[ri, ci] = sel
    before = box.copy()
    half = 0.5 * (box - full_well_e).clip(0.0) * spill
    np.minimum(box, full_well_e, out=box)
    for order in (range(box.shape[0]), range(box.shape[0] - 1, -1, -1)):  # down, then up
        carry = np.zeros(box.shape[1])
        for r in order:
            take = np.minimum(full_well_e - box[r], carry)
            box[r] += take
            carry -= take
            carry += half[r]
    charge[sel] = box[ri, ci]
    np.minimum(charge, full_well_e, out=charge)
    gained = (box - before > 0) & (member < 0)
    gr, gc = np.nonzero(gained)
    other = (gr + r0) * width + columns[gc]
    return charge, other, (box - before)[gr, gc]


# --------------------------------------------------------------------------- renderer


class Renderer:
    """Renders complex images for one :class:`SimCameraConfig` (build a new one when the
    config changes; construction precomputes the background table)."""

    def __init__(self, config: SimCameraConfig):
        self.config = config
        self.params = config.params()
        self.model = config.target_model()
        self.view_gains = (config.view_gain_right, config.view_gain_left)
        c = config
        self.sky_dn = c.background_dn_per_ms * c.exposure_ms
        self.background_dn = c.black_level_dn + self.sky_dn
        self._table = background_table(
            self.sky_dn * c.gain_e_per_dn,
            c.read_noise_e,
            c.gain_e_per_dn,
            c.black_level_dn,
            c.full_well_e,
        )
        self._bank: np.ndarray | None = None  # built on the first noisy frame
        self._fpn: tuple[np.ndarray, np.ndarray] | None = None  # built on first use
        self._fpn_background: tuple[np.ndarray, np.ndarray] | None = None
        e0 = np.minimum((np.zeros(1) + self.sky_dn) * c.gain_e_per_dn, c.full_well_e)
        self._flat_dn = np.clip(np.rint(c.black_level_dn + e0 / c.gain_e_per_dn), 0, 255).astype(
            np.uint8
        )[0]  # the noise-free background grey level
        self._occ_h = occlusion_offset(c.occlusion_fraction)
        ang = math.radians(c.occlusion_angle_deg)
        self._occ_dir = np.array([math.cos(ang), math.sin(ang)])
        plane = np.asarray(c.reflection_plane_tob, dtype=float)
        norm = np.linalg.norm(plane[:3])
        self._mirror_n, self._mirror_d = plane[:3] / norm, plane[3] / norm
        # The TOB's sources, but for where they are (positions and axes come per image).
        self._tob_p = np.array(self.model.source_positions_mm, dtype=float)  # rows A, B, C
        h = np.ones(3)
        h[list(c.occluded_sources)] = self._occ_h
        self._sources = Discs.make(
            np.zeros((3, 3)),
            np.eye(3),
            self.model.source_diameter_mm / 2.0,
            c.source_dn_per_ms,
            0.0,
            h,
            self._occ_dir,
            np.arange(3),
        )
        for f in Discs._fields():
            getattr(self._sources, f).flags.writeable = False  # shared by every image
        self._covers: dict[tuple, Renderer] = {}  # covered() copies, by cover

    def stereo_pair(self) -> tuple[Renderer, Renderer]:
        """An ordinary stereo pair's two renderers (left, right): the PSVS's virtual
        cameras apart, each sees only its own view, as bright as in the PSVS (the same
        exposure: at full brightness, twice the PSVS's, the sources saturate and their
        centroids shift by hundredths of a pixel), no ghost (no beam splitter), each its own
        sensor noise (seeds 2 seed + 1 and 2 seed + 2). Their images side by side are what
        ``SimCameraConfig.stereo`` renders. Built once."""
        pair = getattr(self, "_pair", None)
        if pair is None:
            c = self.config
            pair = self._pair = (
                Renderer(dataclasses.replace(c, view_gain_right=0.0, ghost_gain=0.0, seed=2 * c.seed + 1)),
                Renderer(dataclasses.replace(c, view_gain_left=0.0, ghost_gain=0.0, seed=2 * c.seed + 2)))
        return pair

    def covered(self, fraction: Sequence[float], angle_rad: Sequence[float]) -> Renderer:
        """This renderer with the sources covered as the operator's truth says: per source
        A, B, C the hidden ``fraction`` of its disc (0..1; 0 leaves the configured static
        occlusion, ``occluded_sources``) and the direction ``angle_rad`` of the hidden side
        in the TOB plane. Shares everything else (tables, noise banks) with this one; kept
        per cover, so a cover held over many frames is built once."""
        key = (tuple(float(f) for f in fraction), tuple(float(a) for a in angle_rad))
        if not any(key[0]):
            return self
        hit = self._covers.get(key)
        if hit is not None:
            return hit
        h = self._sources.occlusion_h.copy()
        d = self._sources.occlusion_dir.copy()
        for k, (f, a) in enumerate(zip(*key, strict=True)):
            if f > 0.0:
                h[k] = occlusion_offset(f)
                d[k] = (math.cos(a), math.sin(a))
        other = copy.copy(self)
        other._sources = dataclasses.replace(self._sources, occlusion_h=h, occlusion_dir=d)
        for f in ("occlusion_h", "occlusion_dir"):
            getattr(other._sources, f).flags.writeable = False
        other._covers = {}
        if len(self._covers) > 64:  # a cover that changes every frame: do not hoard
            self._covers.clear()
        self._covers[key] = other
        return other

    # -- scene ---------------------------------------------------------------------------
    def discs(
        self, camera_T_tob: np.ndarray | None, world_T_camera: np.ndarray | None = None
    ) -> Discs:
        """The scene in the camera frame: the TOB's sources (when ``camera_T_tob``, (4, 4)
        mm, is given), their reflections (``reflection_gain`` > 0) and the lamp (needs
        ``world_T_camera`` when it is fixed in the world)."""
        c = self.config
        parts = []
        if camera_T_tob is not None:
            camera_T_tob = np.asarray(camera_T_tob, dtype=float)
            tob_p = self._tob_p  # (3, 3) rows A, B, C
            # Sources lie in the TOB plane; their lit face looks along -w (towards the camera
            # for a labellable view, see humanpt.geometry.target).
            tob_axes = _TOB_AXES
            h = self._sources.occlusion_h
            rot = camera_T_tob[:3, :3]
            src = self._sources
            parts.append(
                Discs(
                    tob_p @ rot.T + camera_T_tob[:3, 3],
                    np.broadcast_to(rot @ tob_axes, (3, 3, 3)),
                    src.radius_mm,
                    src.dn_per_ms,
                    src.blur_px,
                    src.occlusion_h,
                    src.occlusion_dir,
                    src.label,
                )
            )
            if c.reflection_gain > 0:
                n, d = self._mirror_n, self._mirror_d
                mirror = np.eye(3) - 2.0 * np.outer(n, n)
                tob_q = tob_p @ mirror.T + 2.0 * d * n  # q - 2 (n.q - d) n
                parts.append(
                    Discs.make(
                        tob_q @ rot.T + camera_T_tob[:3, 3],
                        rot @ mirror @ tob_axes,
                        self.model.source_diameter_mm / 2.0,
                        c.source_dn_per_ms * c.reflection_gain,
                        c.reflection_blur_px,
                        h,
                        src.occlusion_dir,
                        10 + np.arange(3),
                    )
                )
        if c.lamp_position_mm is not None:
            p = np.asarray(c.lamp_position_mm, dtype=float)
            if c.lamp_frame == "world":
                if world_T_camera is None:
                    p = None
                else:
                    wc = np.asarray(world_T_camera, dtype=float)
                    p = wc[:3, :3].T @ (p - wc[:3, 3])
            if p is not None and np.linalg.norm(p) > 1e-9:
                normal = -p / np.linalg.norm(p)  # faces the camera, like a bulb
                parts.append(
                    Discs.make(
                        p,
                        _perpendicular_axes(normal[None])[0],
                        c.lamp_diameter_mm / 2.0,
                        c.lamp_dn_per_ms,
                        label=20,
                    )
                )
        return Discs.concat(parts)

    def blobs(self, discs: Discs) -> Blobs:
        """The discs projected into both views (:func:`project_discs`), with the angular
        fall-off of ``source_falloff_exponent`` and, when ``ghost_gain`` > 0, the beam
        splitter's ghost: every blob of ``ghost_view`` again, ``ghost_gain`` times as
        bright, shifted by ``ghost_offset_px`` (label + 100)."""
        c = self.config
        blobs = project_discs(
            self.params,
            discs,
            self.view_gains,
            c.exposure_ms,
            c.blur_sigma_px,
            c.near_mm,
            c.source_falloff_exponent,
        )
        if c.ghost_gain > 0 and len(blobs):
            sel = np.flatnonzero(blobs.view == VIEWS.index(c.ghost_view))
            if sel.size:
                ghost = Blobs(*(getattr(blobs, f)[sel] for f in Blobs.__dataclass_fields__))
                ghost = dataclasses.replace(
                    ghost,
                    centre_px=ghost.centre_px + np.asarray(c.ghost_offset_px, dtype=float),
                    dn=ghost.dn * c.ghost_gain,
                    label=ghost.label + 100,
                )
                blobs = Blobs(
                    *(
                        np.concatenate([getattr(blobs, f), getattr(ghost, f)])
                        for f in Blobs.__dataclass_fields__
                    )
                )
        return blobs

    # -- images --------------------------------------------------------------------------
    def signal(self, blobs: Blobs) -> np.ndarray:
        """Noise-free signal (H, W) float32 in DN above the background: every blob's
        coverage x brightness, blurred, views added."""
        width, height = self.params.image_size_px
        out = np.zeros(height * width, dtype=np.float32)
        idx, value = self.signal_pixels(blobs)
        out[idx] = value
        return out.reshape(height, width)

    def signal_pixels(self, blobs: Blobs) -> tuple[np.ndarray, np.ndarray]:
        """The nonzero pixels of :meth:`signal` without the full frame: flat indices
        (row-major, ascending, int) and their values (float32, > 0)."""
        width, height = self.params.image_size_px
        if len(blobs) == 0:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.float32)
        ext = blobs.half_extent_px().max(axis=1)
        # Windows: the blurred blob's, in buckets of equal sizes (batched); the coverage
        # only in the smaller window that holds the ellipse.
        halves = 4 * np.ceil((ext + 4.0 * blobs.sigma_px + 1.0) / 4.0).astype(int)
        one_bucket = halves.min() == halves.max()
        indices, values = [], []
        for half in halves[:1] if one_bucket else np.unique(halves):
            if one_bucket:
                sub, sub_ext = blobs, ext
            else:
                sel = np.flatnonzero(halves == half)
                sub = Blobs(*(getattr(blobs, f)[sel] for f in Blobs.__dataclass_fields__))
                sub_ext = ext[sel]
            size = 2 * int(half) + 1
            cov_half = min(math.ceil(sub_ext.max() + 1.0), int(half))
            cov, origin = coverage(sub, cov_half)
            origin -= int(half) - cov_half
            img = _blur(cov * sub.dn[:, None, None], sub.sigma_px, size)
            flat = (origin[:, 1] * width + origin[:, 0])[:, None, None] + _window_offsets(
                size, width
            )
            keep = img > 0
            last = origin.max(axis=0) + size
            if origin.min() < 0 or last[0] > width or last[1] > height:
                # A window cut by the border keeps what is inside.
                k = np.arange(size)
                rows = origin[:, 1, None] + k  # (m, K)
                cols = origin[:, 0, None] + k
                keep &= ((rows >= 0) & (rows < height))[:, :, None]
                keep &= ((cols >= 0) & (cols < width))[:, None, :]
            indices.append(flat[keep])
            values.append(img[keep])
        idx = np.concatenate(indices) if len(indices) > 1 else indices[0]
        value = np.concatenate(values) if len(values) > 1 else values[0]
        order = np.argsort(idx, kind="stable")
        idx, value = idx.take(order), value.take(order)
        if idx.size > 1:
            first = np.empty(idx.size, dtype=bool)
            first[0] = True
            np.not_equal(idx[1:], idx[:-1], out=first[1:])
            if not first.all():  # overlapping windows: add the views (and clutter) up
                starts = np.flatnonzero(first)
                value = np.add.reduceat(value, starts)
                idx = idx[starts]
        value = value.astype(np.float32)
        if not np.all(value > 0):
            nz = np.flatnonzero(value > 0)
            idx, value = idx[nz], value[nz]
        return idx, value

    def _pattern(self, n: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The fixed pattern (offset DN (n,), gain - 1 (n,)) of ``dsnu_dn`` and ``prnu``,
        or None when both are 0."""
        c = self.config
        if c.dsnu_dn == 0 and c.prnu == 0:
            return None
        if self._fpn is None or self._fpn[0].size != n:
            unit_offset, unit_gain = _fixed_pattern_unit(c.seed, n)
            offset = (unit_offset * np.float32(c.dsnu_dn)).astype(np.float64)
            gain = np.maximum(unit_gain * np.float32(c.prnu), -1.0).astype(np.float64)
            self._fpn = (offset, gain)
        return self._fpn

    def _charge(self, charge_e, idx, shape, background_e):
        """Full well (and blooming): charges at ``idx`` capped at the well, plus the other
        pixels that received blooming charge (flat indices, electrons)."""
        c = self.config
        if c.blooming > 0:
            return bloom_columns(idx, charge_e, shape, c.full_well_e, c.blooming, background_e)
        none = np.zeros(0, dtype=np.intp), np.zeros(0)
        return np.minimum(charge_e, c.full_well_e), *none

    def expose(self, signal_dn: np.ndarray, frame_index: int) -> np.ndarray:
        """The sensor: background, shot and read noise, fixed pattern, full well (and
        blooming), 8-bit quantisation and saturation; (H, W) uint8. Noise from
        ``default_rng([seed, frame_index])``."""
        c = self.config
        if not c.noise and c.dsnu_dn == 0 and c.prnu == 0 and c.blooming == 0:
            g = c.gain_e_per_dn
            e = np.minimum((signal_dn.astype(np.float64) + self.sky_dn) * g, c.full_well_e)
            return np.clip(np.rint(c.black_level_dn + e / g), 0, 255).astype(np.uint8)
        flat = np.ravel(signal_dn)
        idx = np.flatnonzero(flat > 0)
        return self.expose_pixels(idx, flat[idx], frame_index, signal_dn.shape)

    def expose_pixels(
        self, idx: np.ndarray, signal_dn: np.ndarray, frame_index: int, shape: tuple[int, int]
    ) -> np.ndarray:
        """:meth:`expose` of a frame whose signal is ``signal_dn`` (> 0) at the flat
        (row-major, ascending) indices ``idx`` and 0 elsewhere: the same image, without a
        full-frame signal.

        Noise: each frame's background is a run of :func:`_background_bank` (exact
        background grey levels, independent pixels) at an offset drawn from
        ``default_rng([seed, frame_index])``; the signal pixels get exact Poisson shot
        noise and Gaussian read noise from the same generator.

        Fixed pattern (``dsnu_dn``, ``prnu`` > 0): the background is built from a bank of
        unquantised charges (:func:`_noise_bank`), each pixel scaled by its gain (the
        read noise too: 1 % of 0.25 DN) and offset, then quantised; signal pixels get
        ``Poisson((signal + sky) gain_e_per_dn (1 + prnu_i))`` and the offset at readout.
        Blooming (``blooming`` > 0): :func:`bloom_columns` before the read noise; a
        background pixel that receives charge gets it on top of its grey level."""
        c = self.config
        g = c.gain_e_per_dn
        n = int(shape[0]) * int(shape[1])
        pattern = self._pattern(n)
        sky_e = self.sky_dn * g
        if not c.noise:
            if pattern is None:
                frame = np.full(n, self._flat_dn, dtype=np.uint8)
            else:
                bg_e = np.minimum(sky_e * (1.0 + pattern[1]), c.full_well_e)
                frame = _grey(c.black_level_dn + pattern[0] + bg_e / g)
            if idx.size:
                e = (signal_dn.astype(np.float64) + self.sky_dn) * g
                if pattern is not None:
                    e *= 1.0 + pattern[1][idx]
                e, other, got_e = self._charge(e, idx, shape, sky_e)
                dn = c.black_level_dn + e / g
                frame[idx] = _grey(dn if pattern is None else dn + pattern[0][idx])
                if other.size:
                    frame[other] = _grey(frame[other] + got_e / g)
            return frame.reshape(shape)
        rng = np.random.default_rng([c.seed, int(frame_index)])
        if pattern is None:
            if self._bank is None or self._bank.size != n + _BANK_OFFSETS:
                self._bank = _background_bank(c.seed, self._table.tobytes(), n)
            offset = int(rng.integers(_BANK_OFFSETS))
            frame = self._bank[offset : offset + n].copy()  # the background everywhere
        else:
            bank = _noise_bank(c.seed, sky_e, c.read_noise_e, c.full_well_e, n)
            offset = int(rng.integers(_BANK_OFFSETS))
            if self._fpn_background is None or self._fpn_background[0].size != n:
                self._fpn_background = (  # float32: a 307k-pixel frame in ~1 ms
                    (c.black_level_dn + pattern[0]).astype(np.float32),
                    ((1.0 + pattern[1]) / g).astype(np.float32),
                )
            base_dn, dn_per_e = self._fpn_background
            bg_dn = bank[offset : offset + n] * dn_per_e
            bg_dn += base_dn
            np.rint(bg_dn, out=bg_dn)
            frame = np.clip(bg_dn, 0, 255).astype(np.uint8)
        if idx.size:
            mean_e = (signal_dn.astype(np.float64) + self.sky_dn) * g
            if pattern is not None:
                mean_e *= 1.0 + pattern[1][idx]
            other = np.zeros(0, dtype=np.intp)
            if c.blooming > 0:
                e, other, got_e = self._charge(rng.poisson(mean_e).astype(np.float64), idx, shape, sky_e)
            else:
                e = np.minimum(rng.poisson(mean_e), c.full_well_e).astype(np.float64)
            if c.read_noise_e > 0:
                e += rng.normal(0.0, c.read_noise_e, idx.size)
            dn = c.black_level_dn + e / g
            frame[idx] = _grey(dn if pattern is None else dn + pattern[0][idx])
            if other.size:
                frame[other] = _grey(frame[other] + got_e / g)
        return frame.reshape(shape)

    def render(
        self,
        camera_T_tob: np.ndarray | None,
        world_T_camera: np.ndarray | None = None,
        frame_index: int = 0,
        camera_T_tob_end: np.ndarray | None = None,
        world_T_camera_end: np.ndarray | None = None,
    ) -> np.ndarray:
        """One complex image (H, W) uint8 of the target at ``camera_T_tob`` (mm; None: no
        target in the scene): ``expose(signal(blobs(discs(...))), frame_index)``, byte for
        byte, computed on the blobs' pixels only.

        Motion blur: with ``camera_T_tob_end`` and/or ``world_T_camera_end`` (mm) the
        first two poses are those at the *start* of the exposure and these at its *end*;
        the signal is integrated over the exposure (:meth:`exposure_signal_pixels`). The
        image's truth is then the pose at mid-exposure,
        ``interpolate_transform(start, end, 0.5)``. Without end poses: no motion, the
        image of the given poses (as before)."""
        if camera_T_tob_end is None and world_T_camera_end is None:
            idx, value = self.signal_pixels(self.blobs(self.discs(camera_T_tob, world_T_camera)))
        else:
            idx, value = self.exposure_signal_pixels(
                (camera_T_tob, camera_T_tob if camera_T_tob_end is None else camera_T_tob_end),
                (world_T_camera, world_T_camera if world_T_camera_end is None else world_T_camera_end),
            )
        width, height = self.params.image_size_px
        return self.expose_pixels(idx, value, frame_index, (height, width))

    def render_exposure(
        self,
        camera_T_tob: Sequence[np.ndarray | None],
        world_T_camera: Sequence[np.ndarray | None] | None = None,
        frame_index: int = 0,
    ) -> np.ndarray:
        """One complex image (H, W) uint8 integrated over the exposure from K pose samples
        equally spaced over it (start ... end; see :meth:`exposure_signal_pixels`)."""
        idx, value = self.exposure_signal_pixels(camera_T_tob, world_T_camera)
        width, height = self.params.image_size_px
        return self.expose_pixels(idx, value, frame_index, (height, width))

    def exposure_signal_pixels(
        self,
        camera_T_tob: Sequence[np.ndarray | None],
        world_T_camera: Sequence[np.ndarray | None] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`signal_pixels` integrated over the exposure: ``camera_T_tob`` and
        ``world_T_camera`` are sequences of K >= 1 poses (mm) at K instants equally spaced
        over the exposure, the first at its start, the last at its end (None entries: no
        target / no camera pose; ``world_T_camera`` None: none at all; a shorter sequence
        of one pose: not moving). Between two samples a pose moves on the
        constant-velocity screw (:func:`humanpt.geometry.transforms.interpolate_transform`):
        give (start, end), or (start, middle, end) to have the truth at mid-exposure
        rendered exactly when the image moves less than ``motion_step_px``.

        The exposure is cut into N equal parts and each rendered at its middle, N so that
        every blob moves at most ``motion_step_px`` from one to the next (N = 1, the pose
        at mid-exposure, when the image moves less than that; at most 64 - a blur longer
        than 64 steps is sampled more coarsely), and the N signals are averaged: the blur
        of the motion, each sub-image with its own brightness, window and coverage. Flat
        indices (ascending) and values, as :meth:`signal_pixels`."""
        tobs = list(camera_T_tob)
        cams = [None] if world_T_camera is None else list(world_T_camera)
        if not tobs or not cams:
            raise ValueError("exposure_signal_pixels needs at least one pose sample")

        def at(samples, f):
            """The pose at the fraction f in [0, 1] of the exposure."""
            if len(samples) == 1:
                return samples[0]
            x = f * (len(samples) - 1)
            k = min(int(x), len(samples) - 2)
            a, b, g = samples[k], samples[k + 1], x - k
            if g == 0.0 or b is None:
                return a
            if g == 1.0 or a is None or a is b:
                return b
            return interpolate_transform(np.asarray(a, float), np.asarray(b, float), g, assume_valid=True)

        def still(samples):
            return all(_same_pose(samples[0], q) for q in samples[1:])

        if still(tobs) and still(cams):  # not moving: as render()
            return self.signal_pixels(self.blobs(self.discs(tobs[0], cams[0])))
        # how far the image moves: blob centres at every sample instant, path summed
        k_max = max(len(tobs), len(cams))
        fractions = np.linspace(0.0, 1.0, max(k_max, 2))
        blobs = [self.blobs(self.discs(at(tobs, f), at(cams, f))) for f in fractions]
        total = 0.0  # px: the largest blob displacement of each segment, summed
        for b0, b1 in zip(blobs[:-1], blobs[1:], strict=True):
            key0 = b0.view * 1_000_000 + b0.disc * 1000 + b0.label
            key1 = b1.view * 1_000_000 + b1.disc * 1000 + b1.label
            _, i0, i1 = np.intersect1d(key0, key1, return_indices=True)
            if i0.size:
                total += float(np.linalg.norm(b1.centre_px[i1] - b0.centre_px[i0], axis=1).max())
        n = max(1, math.ceil(total / self.config.motion_step_px - 1e-9))
        n = min(n, _MAX_SUBEXPOSURES)
        if n == 1:
            return self.signal_pixels(self.blobs(self.discs(at(tobs, 0.5), at(cams, 0.5))))
        parts = [
            self.signal_pixels(self.blobs(self.discs(at(tobs, (k + 0.5) / n), at(cams, (k + 0.5) / n))))
            for k in range(n)
        ]
        idx = np.concatenate([p[0] for p in parts])
        value = np.concatenate([p[1] for p in parts]).astype(np.float64)
        if idx.size == 0:
            return idx, value.astype(np.float32)
        order = np.argsort(idx, kind="stable")
        idx, value = idx[order], value[order]
        first = np.empty(idx.size, dtype=bool)
        first[0] = True
        np.not_equal(idx[1:], idx[:-1], out=first[1:])
        starts = np.flatnonzero(first)
        return idx[starts], (np.add.reduceat(value, starts) / n).astype(np.float32)


def _same_pose(a, b) -> bool:
    return a is b or (a is not None and b is not None and np.array_equal(a, b))


def _grey(dn: np.ndarray) -> np.ndarray:
    """DN (float) -> 8-bit grey levels: round, clip at 0 and 255."""
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def intensity_centroid(image: np.ndarray, background: float = 0.0) -> np.ndarray:
    """Intensity-weighted centroid (u, v) of ``image - background`` (pixel centres at
    integer coordinates): the sub-pixel blob centre of the paper's step 4."""
    w = np.asarray(image, dtype=float) - background
    rows, cols = np.indices(w.shape)
    total = w.sum()
    return np.array([(w * cols).sum() / total, (w * rows).sum() / total])
