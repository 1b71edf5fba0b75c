"""The PSVS complex image, rendered: pure numpy, no runtime needed.

Pipeline (one image):

1. **Scene** (:meth:`Renderer.discs`): the TOB's three planar circular sources in the
   camera frame, plus optional clutter - their mirror images in a shiny plane fixed to the
   TOB, and a bright lamp - as :class:`Discs` (centre, in-plane axes, lit normal, radius,
   radiance, extra blur, occlusion).
2. **Projection** (:meth:`Renderer.blobs`): each disc through each virtual camera (right,
   left; eq. (1)-(3)) and the real lens's distortion. A disc is dropped from a view when it
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
   at 255. Views are superimposed by adding their signals before the sensor.

Speed: only small windows around each blob are rendered; the noise of the (uniform)
background is drawn for the whole frame through a 65536-entry table of the exact
quantised background distribution (one 16-bit random number per pixel); the pixels a
blob touches get exact Poisson + Gaussian noise.

Units: mm in the camera frame, pixels of the complex image (centre of pixel (row i,
column j) at (u, v) = (j, i)), DN (grey levels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr
from scipy.stats import poisson

from humanpt.geometry import PsvsParams, distort_pixels, project_pinhole, projection_jacobian

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
    index into the discs; ``label`` (m,) the disc's label.
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


def project_discs(
    params: PsvsParams,
    discs: Discs,
    view_gains: tuple[float, float],
    exposure_ms: float,
    blur_sigma_px: float,
    near_mm: float = 10.0,
) -> Blobs:
    """Project every disc through both virtual cameras; keep the visible blobs (see the
    module docstring for what hides one). Blobs are ordered right view first, then left,
    each in disc order."""
    width, height = params.image_size_px
    parts = []
    for view, camera in enumerate((params.right_camera, params.left_camera)):
        if len(discs) == 0 or view_gains[view] <= 0:
            continue
        rel = discs.centre_mm - camera.centre
        normal = discs.axes[:, :, 2]
        to_camera = -rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-12)
        facing = np.sum(normal * to_camera, axis=1)
        ok = (rel[:, 2] > near_mm) & (facing > 1e-6) & (discs.dn_per_ms > 0)
        ok &= discs.occlusion_h > -1.0
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            continue
        p = discs.centre_mm[idx]
        uv_ideal = project_pinhole(camera, p)
        # Far outside the image the distortion polynomial is meaningless: drop those first.
        near_image = (
            (uv_ideal[:, 0] > -0.5 * width)
            & (uv_ideal[:, 0] < 1.5 * width)
            & (uv_ideal[:, 1] > -0.5 * height)
            & (uv_ideal[:, 1] < 1.5 * height)
        )
        idx, p, uv_ideal = idx[near_image], p[near_image], uv_ideal[near_image]
        if idx.size == 0:
            continue
        j_pin = projection_jacobian(camera, p)  # (k, 2, 3) px/mm
        plane = discs.axes[idx][:, :, :2] * discs.radius_mm[idx][:, None, None]  # (k, 3, 2)
        jac = _distortion_jacobian(params, uv_ideal) @ (j_pin @ plane)
        if params.has_distortion:
            uv = distort_pixels(uv_ideal, params.real_camera_matrix, params.dist_coeffs)
        else:
            uv = uv_ideal
        sigma = np.sqrt(blur_sigma_px**2 + discs.blur_px[idx] ** 2)
        ext = np.sqrt(np.sum(jac**2, axis=2)) + 4.0 * sigma[:, None] + 2.0
        in_image = (
            (uv[:, 0] + ext[:, 0] > -0.5)
            & (uv[:, 0] - ext[:, 0] < width - 0.5)
            & (uv[:, 1] + ext[:, 1] > -0.5)
            & (uv[:, 1] - ext[:, 1] < height - 0.5)
            & (np.max(ext, axis=1) < _MAX_HALF_WINDOW_PX)
            & (np.abs(np.linalg.det(jac)) > 1e-9)
        )
        sel = np.flatnonzero(in_image)
        if sel.size == 0:
            continue
        d = idx[sel]
        parts.append(
            Blobs(
                uv[sel],
                jac[sel],
                discs.dn_per_ms[d] * exposure_ms * view_gains[view],
                sigma[sel],
                discs.occlusion_h[d],
                discs.occlusion_dir[d],
                np.full(sel.size, view),
                d,
                discs.label[d],
            )
        )
    if not parts:
        z = np.zeros(0)
        return Blobs(
            np.zeros((0, 2)),
            np.zeros((0, 2, 2)),
            z,
            z,
            z,
            np.zeros((0, 2)),
            z.astype(int),
            z.astype(int),
            z.astype(int),
        )
    return Blobs(
        *(
            np.concatenate([getattr(b, f) for b in parts])
            for f in (
                "centre_px",
                "jac",
                "dn",
                "sigma_px",
                "occlusion_h",
                "occlusion_dir",
                "view",
                "disc",
                "label",
            )
        )
    )


# --------------------------------------------------------------------------- exact coverage


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _segment_circle_area(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Signed area of (unit disc) intersected with the triangle (origin, a, b); a, b
    (..., 2). Summed over a closed polygon's edges it gives the polygon's intersection with
    the unit disc (signed by the polygon's orientation)."""
    d = b - a
    aa = np.sum(d * d, axis=-1)
    bb = np.sum(a * d, axis=-1)
    cc = np.sum(a * a, axis=-1) - 1.0
    disc = bb * bb - aa * cc
    safe = np.where(aa > 0, aa, 1.0)
    root = np.sqrt(np.maximum(disc, 0.0))
    hit = disc > 0
    t1 = np.where(hit, np.clip((-bb - root) / safe, 0.0, 1.0), 0.0)
    t2 = np.where(hit, np.clip((-bb + root) / safe, 0.0, 1.0), 0.0)
    p1 = a + t1[..., None] * d
    p2 = a + t2[..., None] * d
    # Outside the circle the boundary is an arc (sector), inside it is the chord.
    sector1 = np.arctan2(_cross(a, p1), np.sum(a * p1, axis=-1))
    sector2 = np.arctan2(_cross(p2, b), np.sum(p2 * b, axis=-1))
    area = 0.5 * (sector1 + _cross(p1, p2) + sector2)
    return np.where(aa > 0, area, 0.0)


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
    origin = np.round(blobs.centre_px).astype(int) - half  # (m, 2) = (u0, v0)
    jinv = np.linalg.inv(blobs.jac)  # (m, 2, 2): pixel offsets -> (s, t) radii
    grid = np.arange(size + 1) - 0.5
    du = origin[:, 0, None] + grid[None, :] - blobs.centre_px[:, 0, None]  # (m, K+1) columns
    dv = origin[:, 1, None] + grid[None, :] - blobs.centre_px[:, 1, None]  # (m, K+1) rows
    # Pixel corners in disc coordinates: (m, K+1 rows, K+1 cols, 2).
    s = jinv[:, 0, 0, None, None] * du[:, None, :] + jinv[:, 0, 1, None, None] * dv[:, :, None]
    t = jinv[:, 1, 0, None, None] * du[:, None, :] + jinv[:, 1, 1, None, None] * dv[:, :, None]
    corners = np.stack([s, t], axis=-1)
    quads = np.stack(
        [corners[:, :-1, :-1], corners[:, :-1, 1:], corners[:, 1:, 1:], corners[:, 1:, :-1]],
        axis=3,
    )  # (m, K, K, 4, 2)
    r2 = np.sum(quads * quads, axis=-1)  # (m, K, K, 4)
    proj = np.einsum("mijkc,mc->mijk", quads, blobs.occlusion_dir)
    h = blobs.occlusion_h[:, None, None, None]
    all_in = np.all((r2 <= 1.0) & (proj <= h), axis=-1)
    centre = quads.mean(axis=3)
    circum = np.sqrt(np.max(np.sum((quads - centre[:, :, :, None]) ** 2, axis=-1), axis=-1))
    far = np.sqrt(np.sum(centre * centre, axis=-1)) - circum > 1.0
    hidden = np.all(proj > h, axis=-1)
    cov = all_in.astype(float)
    edge = ~all_in & ~far & ~hidden
    if np.any(edge):
        mi = np.nonzero(edge)[0]
        q = quads[edge]  # (e, 4, 2)
        poly = _clip_quads(q, blobs.occlusion_dir[mi], blobs.occlusion_h[mi])
        area = np.sum(_segment_circle_area(poly, np.roll(poly, -1, axis=1)), axis=1)
        pixel_area = np.abs(np.linalg.det(jinv))[mi]
        cov[edge] = np.clip(np.abs(area) / pixel_area, 0.0, 1.0)
    return cov, origin


def _blur_matrices(sigma: np.ndarray, size: int) -> np.ndarray:
    """(m, K, K) banded matrices M with (M @ W @ M^T) = W convolved with a normalised,
    symmetric sampled Gaussian of sigma (truncated at 4 sigma); identity for sigma = 0."""
    k = np.arange(size)
    diff = (k[:, None] - k[None, :]).astype(float)  # (K, K)
    out = np.empty((len(sigma), size, size))
    for i, s in enumerate(sigma):
        if s <= 1e-6:
            out[i] = np.eye(size)
            continue
        radius = math.ceil(4.0 * s)
        taps = np.arange(-radius, radius + 1)
        norm = np.sum(np.exp(-0.5 * (taps / s) ** 2))
        g = np.exp(-0.5 * (diff / s) ** 2) / norm
        g[np.abs(diff) > radius] = 0.0
        out[i] = g
    return out


# --------------------------------------------------------------------------- sensor


def background_table(
    mean_e: float, read_noise_e: float, gain_e_per_dn: float, black_dn: float, full_well_e: float
) -> np.ndarray:
    """Inverse CDF (65536 entries, uint8) of a background pixel's grey level:
    ``clip(round(black + (min(Poisson(mean_e), full_well) + N(0, read)) / gain), 0, 255)``.
    Indexing it with uniform 16-bit numbers draws that distribution (to 2^-16)."""
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
        self._occ_h = occlusion_offset(c.occlusion_fraction)
        ang = math.radians(c.occlusion_angle_deg)
        self._occ_dir = np.array([math.cos(ang), math.sin(ang)])
        plane = np.asarray(c.reflection_plane_tob, dtype=float)
        norm = np.linalg.norm(plane[:3])
        self._mirror_n, self._mirror_d = plane[:3] / norm, plane[3] / norm

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
            tob_p = self.model.source_positions_mm  # (3, 3) rows A, B, C
            # Sources lie in the TOB plane; their lit face looks along -w (towards the camera
            # for a labellable view, see humanpt.geometry.target).
            tob_axes = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]]).T
            h = np.ones(3)
            h[list(c.occluded_sources)] = self._occ_h
            rot = camera_T_tob[:3, :3]
            parts.append(
                Discs.make(
                    tob_p @ rot.T + camera_T_tob[:3, 3],
                    rot @ tob_axes,
                    self.model.source_diameter_mm / 2.0,
                    c.source_dn_per_ms,
                    0.0,
                    h,
                    self._occ_dir,
                    np.arange(3),
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
                        self._occ_dir,
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
        c = self.config
        return project_discs(
            self.params, discs, self.view_gains, c.exposure_ms, c.blur_sigma_px, c.near_mm
        )

    # -- images --------------------------------------------------------------------------
    def signal(self, blobs: Blobs) -> np.ndarray:
        """Noise-free signal (H, W) float32 in DN above the background: every blob's
        coverage x brightness, blurred, views added."""
        width, height = self.params.image_size_px
        out = np.zeros((height, width), dtype=np.float32)
        if len(blobs) == 0:
            return out
        ext = blobs.half_extent_px().max(axis=1) + 4.0 * blobs.sigma_px + 1.0
        halves = 4 * np.ceil(ext / 4.0).astype(int)  # buckets of equal windows, batched
        for half in np.unique(halves):
            sel = np.flatnonzero(halves == half)
            sub = Blobs(*(getattr(blobs, f)[sel] for f in Blobs.__dataclass_fields__))
            cov, origin = coverage(sub, int(half))
            size = cov.shape[1]
            blur = _blur_matrices(sub.sigma_px, size)
            img = blur @ cov @ np.swapaxes(blur, 1, 2) * sub.dn[:, None, None]
            for k in range(len(sub)):
                u0, v0 = origin[k]
                r0, r1 = max(v0, 0), min(v0 + size, height)
                c0, c1 = max(u0, 0), min(u0 + size, width)
                if r0 < r1 and c0 < c1:
                    out[r0:r1, c0:c1] += img[k, r0 - v0 : r1 - v0, c0 - u0 : c1 - u0]
        return out

    def expose(self, signal_dn: np.ndarray, frame_index: int) -> np.ndarray:
        """The sensor: background, shot and read noise, full well, 8-bit quantisation and
        saturation; (H, W) uint8. Noise from ``default_rng([seed, frame_index])``."""
        c = self.config
        g = c.gain_e_per_dn
        if not c.noise:
            e = np.minimum((signal_dn.astype(np.float64) + self.sky_dn) * g, c.full_well_e)
            return np.clip(np.rint(c.black_level_dn + e / g), 0, 255).astype(np.uint8)
        rng = np.random.default_rng([c.seed, int(frame_index)])
        shape = signal_dn.shape
        uniform = np.frombuffer(rng.bytes(2 * signal_dn.size), dtype=np.uint16)
        frame = self._table.take(uniform)  # a new array: the background everywhere
        idx = np.flatnonzero(signal_dn.ravel() > 0)
        if idx.size:
            mean_e = (signal_dn.ravel()[idx].astype(np.float64) + self.sky_dn) * g
            e = np.minimum(rng.poisson(mean_e), c.full_well_e).astype(np.float64)
            if c.read_noise_e > 0:
                e += rng.normal(0.0, c.read_noise_e, idx.size)
            frame[idx] = np.clip(np.rint(c.black_level_dn + e / g), 0, 255).astype(np.uint8)
        return frame.reshape(shape)

    def render(
        self,
        camera_T_tob: np.ndarray | None,
        world_T_camera: np.ndarray | None = None,
        frame_index: int = 0,
    ) -> np.ndarray:
        """One complex image (H, W) uint8 of the target at ``camera_T_tob`` (mm; None: no
        target in the scene)."""
        return self.expose(
            self.signal(self.blobs(self.discs(camera_T_tob, world_T_camera))), frame_index
        )


def intensity_centroid(image: np.ndarray, background: float = 0.0) -> np.ndarray:
    """Intensity-weighted centroid (u, v) of ``image - background`` (pixel centres at
    integer coordinates): the sub-pixel blob centre of the paper's step 4."""
    w = np.asarray(image, dtype=float) - background
    rows, cols = np.indices(w.shape)
    total = w.sum()
    return np.array([(w * cols).sum() / total, (w * rows).sum() / total])
