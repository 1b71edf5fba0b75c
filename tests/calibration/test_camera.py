"""Camera calibration: the board, the rendered board against OpenCV's projection, the
paper's detector on hand-made squares, the rig convention, and Zhang on the twin against
its truth (issue 17.1)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from humanpt.calibration.board import BoardError, Chessboard, charuco_available
from humanpt.calibration.camera import (
    CalibrationError,
    CameraCalibration,
    ViewCalibration,
    apply_to_rig,
    edge_blur_px,
)
from humanpt.calibration.corners_paper import _square_corners, detect_paper, seeds
from humanpt.geometry.config import PsvsConfig
from humanpt.geometry.rig import Rig
from humanpt.runtime.rigfile import rig_from_table, rig_to_table
from humanpt.sim_camera.board import board_corners_px, render_board
from humanpt.sim_camera.config import SimCameraConfig
from humanpt.twin.cal_camera import (
    TWIN_BOARD,
    calibrate_camera_on_twin,
    plan_board_poses,
    world_camera,
)
from humanpt.twin.worlds import World

BOARD = TWIN_BOARD


def test_board_points_and_pattern():
    b = Chessboard(4, 3, 10.0)
    pts = b.object_points_mm()
    assert pts.shape == (12, 3)
    assert pts[1].tolist() == [10.0, 0.0, 0.0] and pts[4].tolist() == [0.0, 10.0, 0.0]  # x fastest (OpenCV)
    # the square touching the origin diagonally at (-1, -1) is dark, its neighbours white
    assert b.reflectance(np.array(-5.0), np.array(-5.0)) < 0.1
    assert b.reflectance(np.array(5.0), np.array(-5.0)) > 0.5
    assert np.isnan(b.reflectance(np.array(-100.0), np.array(0.0)))  # off the board
    with pytest.raises(BoardError, match="must differ"):
        Chessboard(5, 5, 10.0)


def test_charuco_is_in_this_opencv():
    # cv2.aruco.CharucoBoard / CharucoDetector: OpenCV >= 4.7 and 5.0 (README.md)
    assert charuco_available()


def test_true_corners_are_opencvs_projection():
    # independent source: cv2.projectPoints with the same intrinsics and distortion
    p = PsvsConfig(a_u=1003.0, a_v=998.0, dist_coeffs=(-0.05, 0.02, 0.001, -0.002, 0.0)).params()
    T = plan_board_poses(p, "right", BOARD, 1, seed=3)[0]
    uv = board_corners_px(p, "right", T, BOARD)
    cam = p.right_camera  # O1 = (b/2, 0, -b/2): the board in the virtual camera's frame
    p_view = (T[:3, :3] @ BOARD.object_points_mm().T).T + T[:3, 3] - cam.centre
    ref, _ = cv2.projectPoints(p_view, np.zeros(3), np.zeros(3), p.real_camera_matrix, np.array(p.dist_coeffs))
    assert np.abs(uv - ref.reshape(-1, 2)).max() < 1e-6


def test_rendered_corners_are_where_the_optics_put_them():
    # noise-free render, OpenCV's saddle point refinement: the area sampled edges put each
    # corner within a few hundredths of a pixel of its true projection
    p = PsvsConfig(a_u=1003.0, a_v=1003.0, dist_coeffs=(-0.01, 0, 0, 0, 0), du0_left_px=0.5).params()
    cfg = SimCameraConfig(noise=False)
    errs = []
    for view in ("right", "left"):
        for T in plan_board_poses(p, view, BOARD, 2, seed=1):
            img = render_board(p, view, T, BOARD, cfg, np.random.default_rng(0))
            ok, c = cv2.findChessboardCorners(img, BOARD.pattern_size)
            assert ok
            c = cv2.cornerSubPix(img, c.reshape(-1, 1, 2), (5, 5), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)).reshape(-1, 2)
            truth = board_corners_px(p, view, T, BOARD)
            errs.append(np.linalg.norm(c[:, None] - truth[None], axis=2).min(axis=1))
    rms = float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    assert rms < 0.08, rms


def test_paper_seed_needs_the_whole_cross():
    m = np.zeros((15, 15), bool)
    m[7, 3:12] = True
    m[3:12, 7] = True
    assert seeds(m, 4)[7, 7] and seeds(m, 4).sum() == 1  # the 17-pixel cross of the 9 x 9 template
    m[7, 11] = False  # one pixel of a leg missing: no 9 x 9 seed, the 5 x 5 one still
    assert not seeds(m, 4).any() and seeds(m, 2)[7, 7]


def test_paper_x_templates_find_the_corners_of_a_square():
    # a 20 x 20 px square with corners at pixel boundaries (u, v) = (9.5, 9.5) ... (29.5, 29.5):
    # each corner's cluster of detecting pixels ("C" inside, "S" outside) is centred on it
    mask = np.zeros((40, 40), bool)
    mask[10:30, 10:30] = True
    c = _square_corners({"mask": mask, "u0": 0, "v0": 0}, mask.shape)
    assert set(c) == {"tl", "tr", "br", "bl"}
    np.testing.assert_allclose(c["tl"], (9.5, 9.5), atol=0.01)
    np.testing.assert_allclose(c["br"], (29.5, 29.5), atol=0.01)
    np.testing.assert_allclose(c["tr"], (29.5, 9.5), atol=0.01)


def test_paper_detector_numbers_the_corners_like_the_truth():
    world = World.realistic()
    cam = world_camera(world, 0)
    p = cam.psvs.params()
    for T in plan_board_poses(p, "right", BOARD, 3, seed=2):
        img = render_board(p, "right", T, BOARD, cam, np.random.default_rng(1))
        found = detect_paper(img, BOARD)
        assert found is not None
        uv, idx = found
        assert len(idx) == BOARD.n_corners
        err = np.linalg.norm(uv - board_corners_px(p, "right", T, BOARD)[idx], axis=1)
        assert err.max() < 1.0 and np.sqrt(np.mean(err**2)) < 0.5


def test_edge_blur_measures_blur():
    p = Rig().params()
    T = plan_board_poses(p, "right", BOARD, 1, seed=0)[0]
    sharp = render_board(p, "right", T, BOARD, SimCameraConfig(noise=False), np.random.default_rng(0))
    blurred = cv2.GaussianBlur(sharp, (0, 0), 3.0)
    assert edge_blur_px(sharp) < 1.5
    assert 2.5 < edge_blur_px(blurred) < 4.5


def _view(view, u0, v0, a=1000.0, k1=-0.01):
    k = np.array([[a, 0, u0], [0, a, v0], [0, 0, 1.0]])
    return ViewCalibration(view, (640, 480), k, np.array([k1, 0, 0, 0, 0]), {"a_u": 0.4, "a_v": 0.4, "u0": 0.2,
                           "v0": 0.3, "k1": 0.001}, 0.06, (0.06,) * 6, tuple("abcdef"), np.zeros((6, 4, 4)),
                           324, 0.8, "opencv")


def test_apply_to_rig_convention():
    rig = Rig()
    new = apply_to_rig(rig, CameraCalibration({"right": _view("right", 321.0, 239.0, 1003.0),
                                               "left": _view("left", 321.5, 238.0, 1002.0)}), "2026-11-23")
    ps = new.psvs
    assert (ps.u0, ps.v0, ps.skew) == (321.0, 239.0, 0.0)  # the right view's
    # one lens: the two views' focal lengths, weighted by their variances (equal here)
    assert ps.a_u == pytest.approx(1002.5) and new.psvs_calibration.sigma["a_u"] == pytest.approx(0.4 / np.sqrt(2))
    assert ps.du0_left_px == pytest.approx(0.5) and ps.dv0_left_px == pytest.approx(-1.0)
    assert ps.dist_coeffs[0] == -0.01
    assert new.params().left_camera.u0 == pytest.approx(321.5)
    cal = new.psvs_calibration
    assert cal.method == "zhang" and cal.date == "2026-11-23"
    assert cal.sigma["dist_coeffs"] == 0.001
    assert "k1 0.001" in cal.note
    assert cal.sigma["du0_left_px"] == pytest.approx(np.hypot(0.2, 0.2))
    assert new.hand_eye == rig.hand_eye and new.tip == rig.tip  # only the camera part changes
    assert rig_from_table(rig_to_table(new)) == new  # what the rig file holds
    # the left view alone: placed against the rig's right view, u0, v0 kept
    left_only = apply_to_rig(rig, CameraCalibration({"left": _view("left", 322.0, 241.0)}), "d")
    assert (left_only.psvs.u0, left_only.psvs.du0_left_px, left_only.psvs.dv0_left_px) == (320.0, 2.0, 1.0)
    with pytest.raises(CalibrationError):
        apply_to_rig(rig, CameraCalibration({}), "d")


def test_zhang_on_the_realistic_twin_meets_the_acceptance():
    # issue 17 acceptance on one seed (fast settings: 12 views per virtual camera): focal
    # within 0.1 %, principal point within 0.5 px of the twin's truth, both views
    world = World.realistic()
    result, report, truth_lines = calibrate_camera_on_twin(world, Rig(), 0, n_views=12)
    truth = world_camera(world, 0).psvs.params()
    for view, cam in (("right", truth.right_camera), ("left", truth.left_camera)):
        cal = result.views[view]
        assert abs(cal.a_u / cam.a_u - 1) < 1e-3 and abs(cal.a_v / cam.a_v - 1) < 1e-3, (view, cal.a_u, cal.a_v)
        assert abs(cal.u0 - cam.u0) < 0.5 and abs(cal.v0 - cam.v0) < 0.5, (view, cal.u0, cal.v0)
        assert cal.rms_px < 0.15
        assert cal.dist_coeffs[0] == pytest.approx(truth.dist_coeffs[0], abs=0.004)
    assert any("reprojection RMS" in line and "overall" in line for line in report)
    assert any("corner error" in line for line in truth_lines)
    rig = apply_to_rig(Rig(), result, "2026-11-23")
    # the left view's principal point relative to the right one (the world: +0.5 px in u)
    assert rig.psvs.du0_left_px == pytest.approx(truth.left_camera.u0 - truth.right_camera.u0, abs=0.7)
