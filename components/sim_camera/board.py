"""A calibration board, rendered through ONE virtual camera of the PSVS (the other path
covered, as the paper's user covers a mirror to calibrate the camera).

Area sampling through the true optics: the rays through every pixel's four corners are
followed back through the lens (the true distortion, centred on the real camera's (u0, v0)),
the view's own intrinsics and principal point and its rotation to the board's plane. A
pixel whose four corners land in one square of the board is that square's colour; a pixel
that an edge crosses is supersampled (``supersample`` x ``supersample`` points, board
coordinates interpolated bilinearly between its corners: the ray-to-plane map is smooth,
its curvature across one pixel moves a point by < 1e-4 px), so the rendered edges and
corners are where the optics put them to a few hundredths of a pixel. Then the optics'
Gaussian blur (``blur_sigma_px``) and the world's sensor (shot and read noise, full well,
fixed pattern noise, 8 bits).

Units: mm (camera and board frames), pixels of the complex image (pixel (row i, column j)
centred at (u, v) = (j, i)), DN.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter, shift

from humanpt.calibration.board import Chessboard
from humanpt.geometry import PsvsParams, distort_pixels
from humanpt.geometry.distortion import undistort_pixels
from humanpt.geometry.psvs import project_pinhole
from humanpt.geometry.transforms import invert_transform, transform_points

from .config import SimCameraConfig

__all__ = ["render_board", "board_corners_px", "WHITE_DN", "BACKGROUND_REFLECTANCE"]

WHITE_DN = 210.0  # signal of the white paper above the black level (well exposed, unsaturated)
BACKGROUND_REFLECTANCE = 0.35  # the wall behind the board


def _view(params: PsvsParams, view: str):
    if view not in ("right", "left"):
        raise ValueError(f"view must be 'right' or 'left', got {view!r}")
    return params.right_camera if view == "right" else params.left_camera


def board_corners_px(params: PsvsParams, view: str, camera_T_board_mm: np.ndarray,
                     board: Chessboard) -> np.ndarray:
    """The TRUE image (u, v) px, (n, 2), of the board's inner corners (OpenCV order)
    seen through ``view`` with the lens distortion: what an ideal detector would find."""
    cam = _view(params, view)
    p_cam = transform_points(camera_T_board_mm, board.object_points_mm())
    uv = project_pinhole(cam, p_cam)
    if params.has_distortion:
        uv = distort_pixels(uv, params.real_camera_matrix, params.dist_coeffs)
    return uv


def _rays(params: PsvsParams, view: str, uv_px: np.ndarray) -> np.ndarray:
    """Observed pixels (..., 2) -> their rays' directions (..., 3) in the camera frame
    (P = O + R d, O the view's centre)."""
    cam = _view(params, view)
    uv_ideal = undistort_pixels(uv_px, params.real_camera_matrix, params.dist_coeffs)
    y = (uv_ideal[..., 1] - cam.v0) / cam.a_v
    x = (uv_ideal[..., 0] - cam.u0 - cam.skew * y) / cam.a_u
    d_view = np.stack([x, y, np.ones_like(x)], -1)
    return d_view @ cam.rotation.T


# The rays through every pixel corner of a view depend on its optics only, not on where the
# board is: computed once per optics (undistorting the whole grid was half a render's time).
_CORNER_RAYS: dict[tuple, np.ndarray] = {}


def _corner_rays(params: PsvsParams, view: str) -> np.ndarray:
    """(height + 1, width + 1, 3) :func:`_rays` of the pixel corners (u, v) = (j - 0.5,
    i - 0.5), cached per optics (read-only)."""
    cam = _view(params, view)
    width, height = params.image_size_px
    key = (view, width, height, np.asarray(params.real_camera_matrix, dtype=float).tobytes(),
           np.asarray(params.dist_coeffs, dtype=float).tobytes(), float(cam.u0), float(cam.v0), float(cam.a_u),
           float(cam.a_v), float(cam.skew), np.asarray(cam.rotation, dtype=float).tobytes())
    rays = _CORNER_RAYS.get(key)
    if rays is None:
        gu, gv = np.meshgrid(np.arange(width + 1) - 0.5, np.arange(height + 1) - 0.5)
        rays = _rays(params, view, np.stack([gu, gv], -1))
        rays.flags.writeable = False
        if len(_CORNER_RAYS) >= 4:  # a few optics at a time (a calibration's two views)
            _CORNER_RAYS.pop(next(iter(_CORNER_RAYS)))
        _CORNER_RAYS[key] = rays
    return rays


def _board_xy_of_rays(params: PsvsParams, view: str, camera_T_board_mm: np.ndarray,
                      d_cam: np.ndarray) -> np.ndarray:
    """Rays (..., 3) of the view (camera frame, :func:`_rays`) -> where they meet the
    board's plane, (..., 2) board x, y in mm (NaN: misses it or meets it behind)."""
    cam = _view(params, view)
    board_T_camera = invert_transform(camera_T_board_mm)
    o_b = board_T_camera[:3, :3] @ cam.centre + board_T_camera[:3, 3]
    d_b = d_cam @ board_T_camera[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o_b[2] / d_b[..., 2]
    t = np.where(t > 0, t, np.nan)
    return o_b[:2] + t[..., None] * d_b[..., :2]


def _reflectance(board: Chessboard, xy: np.ndarray) -> np.ndarray:
    r = board.reflectance(xy[..., 0], xy[..., 1])
    return np.where(np.isnan(r), BACKGROUND_REFLECTANCE, r)


def render_board(params: PsvsParams, view: str, camera_T_board_mm: np.ndarray, board: Chessboard,
                 cfg: SimCameraConfig, rng: np.random.Generator, supersample: int = 8) -> np.ndarray:
    """One grey image (height, width) uint8 of ``board`` at ``camera_T_board_mm`` (4, 4),
    mm, seen through ``view`` ('right' or 'left') of the PSVS ``params`` (the world's
    truth), with ``cfg``'s ghost, blur and sensor (noise drawn from ``rng``)."""
    width, height = params.image_size_px
    corners_xy = _board_xy_of_rays(params, view, camera_T_board_mm, _corner_rays(params, view))
    finite = np.isfinite(corners_xy).all(-1)
    cell = np.where(finite, board.cell_id(np.nan_to_num(corners_xy[..., 0]), np.nan_to_num(corners_xy[..., 1])), -1)
    # a pixel is one colour when its four corners fall in one cell of the board's grid
    c00, c01, c10, c11 = cell[:-1, :-1], cell[:-1, 1:], cell[1:, :-1], cell[1:, 1:]
    uniform = (c00 == c01) & (c00 == c10) & (c00 == c11)
    refl = np.empty((height, width))
    vi, ui = np.nonzero(uniform)
    # uniform pixels: the colour at the mean of their corners (all in the same cell)
    xy_mid = 0.25 * (corners_xy[:-1, :-1] + corners_xy[:-1, 1:] + corners_xy[1:, :-1] + corners_xy[1:, 1:])
    refl[vi, ui] = _reflectance(board, xy_mid[vi, ui])
    ei, ej = np.nonzero(~uniform)
    if ei.size:
        n = int(supersample)
        s = (np.arange(n) + 0.5) / n  # sample offsets inside the pixel, 0..1
        su, sv = np.meshgrid(s, s)
        su, sv = su.ravel(), sv.ravel()
        p00 = corners_xy[ei, ej][:, None]
        p01 = corners_xy[ei, ej + 1][:, None]
        p10 = corners_xy[ei + 1, ej][:, None]
        p11 = corners_xy[ei + 1, ej + 1][:, None]
        a, b = su[None, :, None], sv[None, :, None]
        xy = (1 - a) * (1 - b) * p00 + a * (1 - b) * p01 + (1 - a) * b * p10 + a * b * p11
        refl[ei, ej] = _reflectance(board, xy).mean(axis=1)
    signal_dn = refl * WHITE_DN
    if cfg.ghost_gain > 0 and cfg.ghost_view == view:
        # the beam splitter's second surface: a faint copy of this view, shifted
        du, dv = cfg.ghost_offset_px
        signal_dn = signal_dn + cfg.ghost_gain * shift(signal_dn, (dv, du), order=1, mode="nearest")
    if cfg.blur_sigma_px > 0:
        signal_dn = gaussian_filter(signal_dn, cfg.blur_sigma_px, mode="nearest", truncate=4.0)
    return _expose(signal_dn, cfg, rng)


def _expose(signal_dn: np.ndarray, cfg: SimCameraConfig, rng: np.random.Generator) -> np.ndarray:
    """The world's sensor on a signal above black (DN): PRNU, shot noise (Poisson in
    electrons), read noise, full well, DSNU, black level, 8 bits."""
    signal = signal_dn
    if cfg.prnu > 0:
        signal = signal * (1.0 + cfg.prnu * rng.standard_normal(signal.shape))
    if cfg.noise:
        e = rng.poisson(np.clip(signal, 0, None) * cfg.gain_e_per_dn).astype(float)
        e += cfg.read_noise_e * rng.standard_normal(signal.shape)
        e = np.minimum(e, cfg.full_well_e)
        signal = e / cfg.gain_e_per_dn
    else:
        signal = np.minimum(signal, cfg.full_well_e / cfg.gain_e_per_dn)
    if cfg.dsnu_dn > 0:
        signal = signal + cfg.dsnu_dn * rng.standard_normal(signal.shape)
    return np.clip(np.rint(signal + cfg.black_level_dn), 0, 255).astype(np.uint8)
