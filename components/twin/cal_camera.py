"""Camera calibration on the digital twin: the twin renders a chessboard through ONE path
of the PSVS (the other mirror covered, as the paper's user does) with the world's TRUE
optics (focal length, principal points, distortion, each view's rotation) and sensor, at
poses planned from the seed; :mod:`humanpt.calibration.camera` estimates from the images
only. The world's truth is read here only to report the estimate against it.

Entry point: :func:`calibrate_camera_on_twin`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from humanpt.calibration.board import Chessboard
from humanpt.calibration.camera import (
    CalibrationError,
    CameraCalibration,
    CameraSettings,
    ViewDetection,
    calibrate_view,
    detect_views,
    report_lines,
)
from humanpt.geometry import PsvsParams
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import make_transform, matrix_from_rotvec, transform_points
from humanpt.sim_camera.board import board_corners_px, render_board
from humanpt.sim_camera.config import SimCameraConfig

from .run import with_overrides
from .worlds import World

__all__ = ["plan_board_poses", "render_views", "world_camera", "calibrate_camera_on_twin", "TWIN_BOARD",
           "JOB_VIEWS", "JOB_TILT_DEG"]

TWIN_BOARD = Chessboard(cols=11, rows=8, square_mm=20.0)
"""The board the twin shows: 11 x 8 inner corners, 20 mm squares (240 x 180 mm of pattern: a printed
A3 sheet; more corners per view than the 9 x 6 OpenCV sample, hence a tighter fit)."""

Progress = Callable[[int, int], None]


def world_camera(world: World, seed: int) -> SimCameraConfig:
    """The twin's TRUE camera (its sim_camera config in ``world``): truth, for rendering
    and for the report against it only."""
    import dataclasses

    return with_overrides(dataclasses.replace(SimCameraConfig(), seed=seed), world.overrides(), "sim_camera")


def _view_camera(params: PsvsParams, view: str):
    return params.right_camera if view == "right" else params.left_camera


JOB_VIEWS = 40
JOB_TILT_DEG = (20.0, 45.0)
"""The job's board views (``humanpt demo --calibrate``: :func:`calibrate_camera_on_twin`'s
defaults): 40 per view tilted 20-45 deg. The focal length is what the board alone gives
(no view of the target tells it: :func:`humanpt.calibration.psvs.depth_sigma_mm`) and a
fraction e of it is e x 600 mm of depth where the servo holds the target: 20 views tilted
15-35 deg gave a_u to 0.27 px (0.16 mm of depth at 600 mm), these 0.16 px (issue 32.4;
docs/results.md, "The TOB frame's depth at the servo's pose")."""


def plan_board_poses(params: PsvsParams, view: str, board: Chessboard, n_views: int, seed: int,
                     margin_px: float = 12.0, tilt_deg: tuple[float, float] = (15.0, 35.0)) -> np.ndarray:
    """(n_views, 4, 4) ``camera_T_board_mm``: poses a user would hold the board at, from the
    seed: depth 450-800 mm from ``view``'s virtual camera, tilted up to +-35 deg about x and
    y (alternating signs, so that every direction is covered) and turned up to +-10 deg
    about the optical axis, shifted so that the boards sweep the image, every corner at
    least ``margin_px`` inside it. The planner uses the given optics (the rig's nominal
    ones are fine: a pose only needs to fit)."""
    rng = np.random.default_rng([int(seed), 1701])
    cam = _view_camera(params, view)
    camera_T_view = make_transform(cam.rotation, cam.centre)
    centre_mm = board.object_points_mm().mean(axis=0)
    w, h = params.image_size_px
    poses = []
    k = 0
    tries = 0
    while len(poses) < n_views:
        tries += 1
        if tries > 200 * n_views:
            raise RuntimeError("could not plan board poses that fit the image")
        # alternate the tilt's direction: +-x, +-y and the diagonals
        ang = 2 * math.pi * (k % 8) / 8 + rng.uniform(-0.3, 0.3)
        tilt = math.radians(rng.uniform(*tilt_deg))
        rot = matrix_from_rotvec(np.array([tilt * math.cos(ang), tilt * math.sin(ang),
                                           math.radians(rng.uniform(-10.0, 10.0))]))
        z = rng.uniform(450.0, 800.0)
        # aim the board's centre at a point spread over the image (a 3 x 3 sweep)
        aim_u = w * (0.5 + 0.25 * ((k % 3) - 1)) + rng.uniform(-20, 20)
        aim_v = h * (0.5 + 0.25 * (((k // 3) % 3) - 1)) + rng.uniform(-20, 20)
        ray = np.array([(aim_u - cam.u0) / cam.a_u, (aim_v - cam.v0) / cam.a_v, 1.0])
        view_T_board = make_transform(rot, ray * z - rot @ centre_mm)
        camera_T_board = camera_T_view @ view_T_board
        uv = board_corners_px(params, view, camera_T_board, board)
        # the whole board incl. its margin must be in front and the corners inside the image
        x0, x1, y0, y1 = board.extent_mm()
        outline = transform_points(view_T_board, np.array([[x0, y0, 0], [x1, y0, 0], [x0, y1, 0], [x1, y1, 0.0]]))
        if np.all(outline[:, 2] > 100) and np.all((uv > margin_px) & (uv < (w - 1 - margin_px, h - 1 - margin_px))):
            poses.append(camera_T_board)
            k += 1
    return np.array(poses)


def render_views(world_cam: SimCameraConfig, view: str, poses: np.ndarray, board: Chessboard, seed: int,
                 progress: Progress | None = None) -> list[tuple[str, np.ndarray]]:
    """The twin's images of the board at each pose through ``view`` (the world's optics and
    sensor): [(name, (h, w) uint8)]."""
    params = world_cam.psvs.params()
    rng = np.random.default_rng([int(seed), 1702, 0 if view == "right" else 1])
    out = []
    for k, T in enumerate(poses):
        out.append((f"{view}-{k:02d}", render_board(params, view, T, board, world_cam, rng)))
        if progress is not None:
            progress(k + 1, len(poses))
    return out


def _corner_error_px(dets: list[ViewDetection], truth_uv: list[np.ndarray]) -> float:
    """RMS (px) of each detected corner against the nearest TRUE projected corner (the
    twin's truth; matching by nearness makes it independent of the detector's order)."""
    errs = []
    for d, uv in zip(dets, truth_uv, strict=True):
        if d.image_px is None:
            continue
        dist = np.linalg.norm(d.image_px[:, None, :] - uv[None, :, :], axis=2).min(axis=1)
        errs.append(dist)
    if not errs:
        return math.nan
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e**2)))


def calibrate_camera_on_twin(world: World, rig: Rig, seed: int, progress: Progress | None = None,
                             detector: str = "opencv", view: str = "both", n_views: int = JOB_VIEWS,
                             settings: CameraSettings | None = None,
                             board: Chessboard = TWIN_BOARD, tilt_deg: tuple[float, float] = JOB_TILT_DEG
                             ) -> tuple[CameraCalibration, list[str], list[str]]:
    """Calibrate the camera on the twin of ``world`` (seed: poses and noise).

    ``view``: 'right', 'left' or 'both' (each virtual camera in turn, the other path
    covered). ``detector``: 'opencv', 'paper' or 'both' (both run on the same images and
    are compared; the result is OpenCV's). ``n_views`` board poses per view, tilted
    ``tilt_deg`` (:data:`JOB_VIEWS`, :data:`JOB_TILT_DEG`: the job's; ``humanpt calibrate
    camera --twin`` passes its ``--views``). ``progress(done, total)``: images rendered and
    read. Returns (result for :func:`humanpt.calibration.camera.apply_to_rig`, report
    lines, lines against the twin's truth). Raises CalibrationError (the reason)."""
    settings = CameraSettings() if settings is None else settings
    if view not in ("right", "left", "both"):
        raise CalibrationError(f"view must be right, left or both, got {view!r}")
    if detector not in ("opencv", "paper", "both"):
        raise CalibrationError(f"detector must be opencv, paper or both, got {detector!r}")
    views = ("right", "left") if view == "both" else (view,)
    detectors = ("opencv", "paper") if detector == "both" else (detector,)
    truth_cam = world_camera(world, seed)  # TRUTH: renders the images; reported against, never estimated from
    truth = truth_cam.psvs.params()
    believed = rig.params()
    total = len(views) * n_views * (1 + len(detectors))
    done = [0]

    def tick(_k, _n):
        done[0] += 1
        if progress is not None:
            progress(done[0], total)

    results: dict[str, dict] = {d: {} for d in detectors}
    detections: dict[str, dict] = {d: {} for d in detectors}
    timing: dict[str, list[float]] = {d: [] for d in detectors}
    corner_err: dict[str, dict] = {d: {} for d in detectors}
    for v in views:
        poses = plan_board_poses(believed, v, board, n_views, seed + (0 if v == "right" else 1000), tilt_deg=tilt_deg)
        images = render_views(truth_cam, v, poses, board, seed, tick)
        truth_uv = [board_corners_px(truth, v, T, board) for T in poses]  # for the report only
        for d in detectors:
            dets = detect_views(images, board, d, tick)
            detections[d][v] = dets
            timing[d].extend(x.seconds for x in dets)
            corner_err[d][v] = _corner_error_px(dets, truth_uv)
            h, w = images[0][1].shape  # the images' size (what a real folder would give)
            results[d][v] = calibrate_view(dets, (w, h), v, settings, d)
    main = "opencv" if "opencv" in detectors else detectors[0]
    result = CameraCalibration(dict(results[main]))
    report = [f"camera calibration on the twin (world {world.name}, seed {seed}): board {board.cols} x {board.rows} "
              f"inner corners, {board.square_mm:g} mm squares, {n_views} views per virtual camera, tilted "
              f"{tilt_deg[0]:g}-{tilt_deg[1]:g} deg"]
    report += report_lines(result, detections[main])
    lines = _truth_lines(result, truth, truth_cam)
    if len(detectors) > 1:
        lines.append("detectors on the same images (corner error against the twin's truth, reprojection RMS, "
                     "time per image, focal error):")
        for d in detectors:
            for v in views:
                cal = results[d][v]
                cam = _view_camera(truth, v)
                lines.append(f"  {d:<7} {v:<5} corner error {corner_err[d][v]:.3f} px RMS   reprojection "
                             f"{cal.rms_px:.3f} px   {1e3 * np.mean(timing[d]):6.1f} ms/image   "
                             f"a_u {100 * (cal.a_u / cam.a_u - 1):+.3f} %")
    else:
        for v in views:
            lines.append(f"{v} view: corner error of the {main} detector against the twin's truth "
                         f"{corner_err[main][v]:.3f} px RMS, {1e3 * np.mean(timing[main]):.1f} ms/image")
    return result, report, lines


def _truth_lines(result: CameraCalibration, truth: PsvsParams, truth_cam: SimCameraConfig) -> list[str]:
    """The estimate against the twin's truth (read for this report only)."""
    lines = ["against the twin's truth:"]
    for v, cal in result.views.items():
        cam = _view_camera(truth, v)
        s = cal.sigma
        lines.append(f"  {v}: a_u {cal.a_u:.2f} (true {cam.a_u:.2f}, {100 * (cal.a_u / cam.a_u - 1):+.3f} %, "
                     f"{(cal.a_u - cam.a_u) / max(s.get('a_u', 1e-9), 1e-9):+.1f} sigma)  "
                     f"a_v {cal.a_v:.2f} (true {cam.a_v:.2f}, {100 * (cal.a_v / cam.a_v - 1):+.3f} %)")
        lines.append(f"  {v}: u0 {cal.u0:.2f} (true {cam.u0:.2f}, {cal.u0 - cam.u0:+.2f} px)  "
                     f"v0 {cal.v0:.2f} (true {cam.v0:.2f}, {cal.v0 - cam.v0:+.2f} px)")
        lines.append(f"  {v}: k1 {cal.dist_coeffs[0]:+.5f} (true {truth.dist_coeffs[0]:+.5f})  k2 "
                     f"{cal.dist_coeffs[1]:+.5f} (true {truth.dist_coeffs[1]:+.5f})")
    if "right" in result.views and "left" in result.views:
        r, l = result.views["right"], result.views["left"]
        tr, tl = truth.right_camera, truth.left_camera
        lines.append(f"  left - right principal point: du0 {l.u0 - r.u0:+.2f} px (true {tl.u0 - tr.u0:+.2f}), "
                     f"dv0 {l.v0 - r.v0:+.2f} px (true {tl.v0 - tr.v0:+.2f})")
    return lines
