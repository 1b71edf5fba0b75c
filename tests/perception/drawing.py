"""Test images drawn with numpy: anti-aliased discs with known centres (supersampled area
coverage), optional Gaussian blur, noise and 8-bit quantisation. Not a PSVS renderer - the
twin's renderer (humanpt.sim_camera) is used for the acceptance tests."""

from __future__ import annotations

import cv2
import numpy as np


def disc_coverage(shape, centre_uv, radius_px, supersample: int = 8) -> np.ndarray:
    """(H, W) float in [0, 1]: the fraction of each pixel covered by the disc (pixel
    centres at integers), from ``supersample`` x ``supersample`` samples per pixel."""
    h, w = shape
    cu, cv = centre_uv
    cov = np.zeros((h, w))
    u0 = max(int(np.floor(cu - radius_px - 1)), 0)
    u1 = min(int(np.ceil(cu + radius_px + 2)), w)
    v0 = max(int(np.floor(cv - radius_px - 1)), 0)
    v1 = min(int(np.ceil(cv + radius_px + 2)), h)
    if u0 >= u1 or v0 >= v1:
        return cov
    s = supersample
    sub = (np.arange(s) + 0.5) / s - 0.5
    uu = (np.arange(u0, u1)[:, None] + sub[None, :]).ravel()
    vv = (np.arange(v0, v1)[:, None] + sub[None, :]).ravel()
    inside = ((uu[None, :] - cu) ** 2 + (vv[:, None] - cv) ** 2) <= radius_px**2
    cov[v0:v1, u0:u1] = inside.reshape(v1 - v0, s, u1 - u0, s).mean(axis=(1, 3))
    return cov


def draw(
    discs,
    shape=(480, 640),
    background_dn: float = 14.0,
    blur_sigma_px: float = 0.7,
    noise_dn: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """uint8 image of discs ``[(u, v, radius_px, amplitude_dn), ...]`` over a flat
    background, blurred, with Gaussian noise of ``noise_dn`` (plus shot-like noise growing
    with the signal) and quantised."""
    img = np.full(shape, float(background_dn))
    for u, v, r, amp in discs:
        img += amp * disc_coverage(shape, (u, v), r)
    if blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma_px)
    if noise_dn > 0:
        rng = np.random.default_rng(seed)
        sigma = np.sqrt(noise_dn**2 + np.maximum(img - background_dn, 0) / 40.0)
        img = img + rng.standard_normal(shape) * sigma
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def scene(
    camera_T_tob_mm: np.ndarray,
    params=None,
    model=None,
    extra_discs=(),
    amplitude_dn=(200.0, 180.0),
    noise_dn: float = 0.64,
    seed: int = 0,
    hidden=(),
    **kw,
):
    """A complex image of the target at ``camera_T_tob_mm`` (4, 4): each source drawn in
    both views as a disc of the projected radius (no perspective shape, no renderer - a
    test stand-in), plus ``extra_discs``; ``hidden`` lists (source 0-2, view 0 right /
    1 left) not drawn. Returns (image, uv_right (3, 2), uv_left (3, 2)), sources in A, B,
    C order."""
    from humanpt.geometry import PsvsParams, TargetModel, project, transform_points

    params = params or PsvsParams()
    model = model or TargetModel.isosceles(driver_length_mm=None)
    p = transform_points(camera_T_tob_mm, model.source_positions_mm)
    uv_r, uv_l = project(params, p)
    discs = []
    for k in range(3):
        views = (
            (uv_r, params.right_camera, amplitude_dn[0]),
            (uv_l, params.left_camera, amplitude_dn[1]),
        )
        for view, (uv, cam, amp) in enumerate(views):
            if (k, view) in hidden:
                continue
            depth = p[k, 2] - cam.centre[2]
            discs.append(
                (uv[k, 0], uv[k, 1], 0.5 * params.a_u * model.source_diameter_mm / depth, amp)
            )
    w, h = params.image_size_px
    img = draw(list(discs) + list(extra_discs), shape=(h, w), noise_dn=noise_dn, seed=seed, **kw)
    return img, uv_r, uv_l


def pose(x_mm_deg) -> np.ndarray:
    """camera_T_tob (4, 4) from X = (x, y, z mm, yaw, pitch, roll deg)."""
    from humanpt.geometry import transform_from_x

    return transform_from_x(np.asarray(x_mm_deg, dtype=float))
