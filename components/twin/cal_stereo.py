"""Stereo pair calibration on the digital twin (issue 35): the board seen by BOTH of the
world's cameras at once, at a spread of poses a user would hold it at, rendered by the
twin's renderer with the world's TRUE cameras (each camera's optics, sensor and the pair's
pose: the world's PSVS's virtual cameras apart, as ``[sim_camera] stereo`` renders them,
which may differ from the rig's); :func:`humanpt.calibration.stereo.calibrate_stereo`
estimates from the image pairs only (Zhang per camera, then ``cv2.stereoCalibrate``, the
jackknife's 1-sigma). The world's truth is read here only to place the board in front of
the true cameras and to report the estimate against it.

Used by the job (:mod:`humanpt.twin.teach`) in place of the camera (and mirror) stage when
the rig is a stereo pair. Entry point: :func:`calibrate_stereo_on_twin`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from humanpt.calibration.board import Chessboard
from humanpt.calibration.camera import CalibrationError, CameraSettings
from humanpt.calibration.handeye import pose_difference
from humanpt.calibration.stereo import (
    StereoCalibration,
    apply_stereo_to_rig,
    calibrate_stereo,
    stereo_report_lines,
)
from humanpt.geometry.rig import Rig, Stereo, StereoCamera
from humanpt.geometry.transforms import (
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    transform_points,
)
from humanpt.sim_camera.board import render_board
from humanpt.sim_camera.config import SimCameraConfig

from .cal_camera import TWIN_BOARD, world_camera
from .report import Check, TruthLines
from .worlds import World

__all__ = ["calibrate_stereo_on_twin", "plan_pair_poses", "render_pairs", "world_pair", "true_flange_T_camera",
           "point_errors_mm", "truth_lines", "ACCEPT_SIGMAS", "DEFAULT_PAIRS"]

DEFAULT_PAIRS = 16
# How far (in its own jackknife 1-sigma) a focal length or the baseline may be from the truth.
ACCEPT_SIGMAS = 3.0

Progress = Callable[[int, int], None]


def world_pair(world: World, seed: int) -> tuple[SimCameraConfig, Stereo]:
    """The world's TRUE pair: its camera (sim_camera config, rendered as a pair) and the pair
    as a :class:`Stereo` (each camera's intrinsics and distortion, ``right_T_left``,
    ``camera_T_right`` the true right camera in the world camera's frame). Truth: for
    rendering and for the report against it only."""
    cam = dataclasses.replace(world_camera(world, seed), stereo=True)
    return cam, Stereo.of_psvs(cam.psvs)


def true_flange_T_camera(camera: SimCameraConfig, rig: Rig) -> np.ndarray:
    """The world's true pose (4, 4) mm of the RIG's camera frame on the flange (to report a
    hand-eye against): the world camera's ``flange_T_camera`` for the PSVS; on a stereo pair
    (the world renders a pair and the rig is one) the rig's camera frame sits at the rig's
    ``camera_T_right`` from the TRUE right camera (a calibration of the pair finds the right
    camera, not where the frame was put on it)."""
    f_T_c = np.asarray(camera.flange_T_camera, dtype=float)
    if not (camera.stereo and rig.kind == "stereo"):
        return f_T_c
    c_T_right_true = Stereo.of_psvs(camera.psvs).camera_T_right_mm()
    return f_T_c @ c_T_right_true @ invert_transform(rig.stereo.camera_T_right_mm())


def _project(cam: StereoCamera, cam_T_board: np.ndarray, points_mm: np.ndarray) -> np.ndarray:
    """The board's points (n, 3) as ``cam`` sees them (n, 2) px (OpenCV's model, the rig's
    numbers), NaN for a point behind it."""
    import cv2

    p = transform_points(cam_T_board, points_mm)
    if np.any(p[:, 2] <= 1.0):
        return np.full((len(p), 2), np.nan)
    uv, _ = cv2.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix(),
                              np.asarray(cam.dist_coeffs, dtype=float))
    return uv.reshape(-1, 2)


def point_errors_mm(believed: Stereo, true: Stereo, depths_mm=(450.0, 600.0, 800.0),
                    field_mm: float = 50.0) -> np.ndarray:
    """(len(depths), 3) error (mm) of points triangulated with the pair ``believed`` from
    their exact images through the pair ``true`` (each camera's distortion undone, then
    ``cv2.triangulatePoints``, as perception triangulates): for each depth the worst
    |error| over a 5 x 5 grid within ``field_mm`` of the right camera's axis, of x, y, z
    (the right camera's frame; as :func:`humanpt.twin.cal_psvs.depth_errors_mm` for the PSVS)."""
    import cv2

    def normalised(cam: StereoCamera, uv: np.ndarray) -> np.ndarray:
        return cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.camera_matrix(),
                                   np.asarray(cam.dist_coeffs, dtype=float)).reshape(-1, 2)

    g = np.linspace(-field_mm, field_mm, 5)
    out = []
    for z in depths_mm:
        pts = np.array([(x, y, z) for x in g for y in g])
        uv_r = _project(true.right, np.eye(4), pts)
        uv_l = _project(true.left, invert_transform(true.right_T_left_mm()), pts)
        x = cv2.triangulatePoints(invert_transform(believed.right_T_left_mm())[:3, :], np.eye(4)[:3, :],
                                  normalised(believed.left, uv_l).T, normalised(believed.right, uv_r).T)
        out.append(np.max(np.abs((x[:3] / x[3]).T - pts), axis=0))
    return np.array(out)


def plan_pair_poses(stereo: Stereo, board: Chessboard, n_pairs: int, seed: int,
                    margin_px: float = 12.0) -> np.ndarray:
    """(n_pairs, 4, 4) ``right_T_board_mm``: poses a user would hold the board at where both
    cameras of ``stereo`` (the rig's: a pose only needs to fit) see it whole, every corner
    at least ``margin_px`` inside both images: depth 500-850 mm, tilted 15-35 deg
    (alternating directions, as :func:`humanpt.twin.cal_camera.plan_board_poses`), turned up to
    +-10 deg about the optical axis, the board's centre swept 3 x 3 over the region both
    cameras see at that depth. :class:`CalibrationError` when they cannot be found."""
    rng = np.random.default_rng([int(seed), 1703])
    w, h = stereo.image_width_px, stereo.image_height_px
    right, left = stereo.right, stereo.left
    left_T_right = invert_transform(stereo.right_T_left_mm())
    c_left = stereo.right_T_left_mm()[:3, 3]  # the left camera's centre in the right camera
    obj = board.object_points_mm()
    centre_mm = obj.mean(axis=0)
    x0, x1, y0, y1 = board.extent_mm()
    outline = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x0, y1, 0.0], [x1, y1, 0.0]])
    poses, k, tries = [], 0, 0
    while len(poses) < n_pairs:
        tries += 1
        if tries > 400 * n_pairs:
            raise CalibrationError(f"could not plan {n_pairs} board poses that both cameras of the rig's pair see whole "
                                   f"at 500-850 mm (baseline {stereo.baseline_mm():.0f} mm)")
        ang = 2 * math.pi * (k % 8) / 8 + rng.uniform(-0.3, 0.3)
        tilt = math.radians(rng.uniform(15.0, 35.0))
        rot = matrix_from_rotvec(np.array([tilt * math.cos(ang), tilt * math.sin(ang),
                                           math.radians(rng.uniform(-10.0, 10.0))]))
        z = rng.uniform(500.0, 850.0)
        # what both cameras see at depth z (the right camera's x; the left one's shifted by its centre)
        lo = max(-right.u0 / right.a_u * z, c_left[0] - left.u0 / left.a_u * z)
        hi = min((w - right.u0) / right.a_u * z, c_left[0] + (w - left.u0) / left.a_u * z)
        if hi <= lo:
            continue
        fx = 0.5 + 0.25 * ((k % 3) - 1) + rng.uniform(-0.06, 0.06)
        fy = 0.5 + 0.25 * (((k // 3) % 3) - 1) + rng.uniform(-0.06, 0.06)
        aim = np.array([lo + fx * (hi - lo), (fy * h - right.v0) / right.a_v * z, z])
        right_T_board = make_transform(rot, aim - rot @ centre_mm)
        if not np.all(transform_points(right_T_board, outline)[:, 2] > 100.0):
            continue
        inside = True
        for cam, T in ((right, right_T_board), (left, left_T_right @ right_T_board)):
            uv = _project(cam, T, obj)
            if not np.all((uv > margin_px) & (uv < (w - 1 - margin_px, h - 1 - margin_px))):
                inside = False
                break
        if inside:
            poses.append(right_T_board)
            k += 1
    return np.array(poses)


def render_pairs(world_cam: SimCameraConfig, camera_T_board: np.ndarray, board: Chessboard, seed: int,
                 progress: Progress | None = None) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The world's pair of images of the board at each pose ``camera_T_board`` (N, 4, 4) mm
    (the world camera's frame): [(name, left (h, w) uint8, right)], each camera its own view
    of the world's PSVS optics and its own sensor noise, no beam splitter (no ghost), as the
    stereo camera renders (:meth:`humanpt.sim_camera.render.Renderer.stereo_pair`)."""
    params = world_cam.psvs.params()
    cfg = dataclasses.replace(world_cam, ghost_gain=0.0)
    rngs = {v: np.random.default_rng([int(seed), 1704, i]) for i, v in enumerate(("left", "right"))}
    out = []
    for k, T in enumerate(camera_T_board):
        imgs = {v: render_board(params, v, T, board, cfg, rngs[v]) for v in ("left", "right")}
        out.append((f"pair-{k:02d}", imgs["left"], imgs["right"]))
        if progress is not None:
            progress(k + 1, len(camera_T_board))
    return out


def calibrate_stereo_on_twin(world: World, rig: Rig, seed: int, progress: Progress | None = None,
                             n_pairs: int = DEFAULT_PAIRS, settings: CameraSettings | None = None,
                             board: Chessboard = TWIN_BOARD, detector: str = "opencv",
                             ) -> tuple[StereoCalibration, list[str], TruthLines]:
    """Calibrate the stereo pair on the twin of ``world`` (seed: the poses and the noise):
    ``n_pairs`` poses planned with the rig's pair (``rig.stereo``; of a PSVS rig, its
    virtual cameras as a pair), the board placed there in front of the world's TRUE right
    camera, both cameras' images rendered, the pair calibrated from them. ``progress(done,
    total)``: pairs rendered, then images read. Returns (result for
    :func:`humanpt.calibration.stereo.apply_stereo_to_rig`, report lines, lines against the
    twin's truth with their checks). Raises
    :class:`humanpt.calibration.camera.CalibrationError` (the reason)."""
    believed = rig.stereo if rig.kind == "stereo" else Stereo.of_psvs(rig.psvs)
    truth_cam, truth = world_pair(world, seed)  # TRUTH: renders; reported against, never estimated from
    right_T_board = plan_pair_poses(believed, board, n_pairs, seed)
    camera_T_board = truth.camera_T_right_mm() @ right_T_board  # held in front of the true cameras
    total = 3 * n_pairs
    pairs = render_pairs(truth_cam, camera_T_board, board, seed,
                         None if progress is None else lambda k, _n: progress(k, total))
    result = calibrate_stereo(pairs, board, settings, detector,
                              None if progress is None else lambda k, _n: progress(n_pairs + k, total))
    report = [f"stereo pair calibration on the twin (world {world.name}, seed {seed}): board {board.cols} x "
              f"{board.rows} inner corners, {board.square_mm:g} mm squares, {n_pairs} pairs seen by both cameras"]
    report += stereo_report_lines(result)
    return result, report, truth_lines(result, truth, believed)


def truth_lines(result: StereoCalibration, truth: Stereo, before: Stereo | None = None) -> TruthLines:
    """The estimate against the world's true pair, with the checks: each camera's focal
    lengths and the baseline within :data:`ACCEPT_SIGMAS` of their own 1-sigma; what the
    pair ``before`` and the calibrated one get wrong in triangulated points
    (:func:`point_errors_mm`)."""
    lines = TruthLines(["against the twin's truth (the world's cameras):"])
    for cal, cam in ((result.left, truth.left), (result.right, truth.right)):
        s = cal.sigma
        for key in ("a_u", "a_v"):
            est, true, sd = getattr(cal, key), getattr(cam, key), max(s.get(key, 0.0), 1e-9)
            lines.checks.append(Check("stereo", f"{cal.view} camera {key} off the truth", abs(est - true) / sd,
                                      ACCEPT_SIGMAS, "sigma"))
        lines.append(f"  {cal.view}: a_u {cal.a_u:.2f} (true {cam.a_u:.2f}, {cal.a_u - cam.a_u:+.2f} px, "
                     f"{(cal.a_u - cam.a_u) / max(s.get('a_u', 0.0), 1e-9):+.1f} sigma)  a_v {cal.a_v:.2f} (true "
                     f"{cam.a_v:.2f}, {(cal.a_v - cam.a_v) / max(s.get('a_v', 0.0), 1e-9):+.1f} sigma)  u0 "
                     f"{cal.u0:.2f} (true {cam.u0:.2f})  v0 {cal.v0:.2f} (true {cam.v0:.2f})  k1 "
                     f"{cal.dist_coeffs[0]:+.5f} (true {cam.dist_coeffs[0]:+.5f})")
    true_T = truth.right_T_left_mm()
    db = result.baseline_mm - truth.baseline_mm()
    sd_b = max(result.sigma_baseline_mm, 1e-9)
    dt, da = pose_difference(result.right_T_left_mm, true_T)
    lines.append(f"  baseline {result.baseline_mm:.3f} mm (true {truth.baseline_mm():.3f}, {db:+.3f} mm, "
                 f"{db / sd_b:+.1f} sigma); right_T_left off by {dt:.3f} mm, {da:.4f} deg (acceptance: focal "
                 f"lengths and baseline within {ACCEPT_SIGMAS:g} sigma)")
    lines.checks.append(Check("stereo", "baseline off the truth", abs(db) / sd_b, ACCEPT_SIGMAS, "sigma"))
    after = apply_stereo_to_rig(Rig(), result, "").stereo  # the calibrated pair (its right camera's frame)
    for name, pair in (("before", before), ("after", after)):
        if pair is None:
            continue
        err = point_errors_mm(pair, truth)
        lines.append(f"  worst point error with the pair {name:6s} (x, y, z mm, within 50 mm of the axis): "
                     + "; ".join(f"{z:.0f} mm: {e[0]:.3f} {e[1]:.3f} {e[2]:.3f}"
                                 for z, e in zip((450, 600, 800), err, strict=True)))
    return lines
