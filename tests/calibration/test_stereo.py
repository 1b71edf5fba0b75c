"""``humanpt calibrate stereo`` (issue 35 item 3): an ordinary stereo pair calibrated from
image pairs of a board. The pair here is the PSVS's two virtual cameras rendered apart (each
image one camera's, as two real cameras would give): parallel cameras whose optical centres
(the geometry library's eq. (2) cameras, from the nominal rig) are the truth,
right_T_left = (c_left - c_right, no rotation), 90.33 mm apart."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.calibration.camera import CalibrationError
from humanpt.calibration.stereo import apply_stereo_to_rig, calibrate_stereo
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import x_from_transform
from humanpt.runtime.rigfile import load_rig, write_rig
from humanpt.sim_camera.board import board_corners_px, render_board
from humanpt.sim_camera.config import SimCameraConfig
from humanpt.twin.cal_camera import TWIN_BOARD, plan_board_poses
from tests.conftest import run_cli_here

MARGIN_PX = 12.0


def _truth_right_T_left() -> np.ndarray:
    p = Rig().params()
    T = np.eye(4)
    T[:3, 3] = np.subtract(p.left_camera.centre_mm, p.right_camera.centre_mm)
    return T


def _fits(p, T) -> bool:
    w, h = p.image_size_px
    for view in ("left", "right"):
        uv = board_corners_px(p, view, T, TWIN_BOARD)
        if not (np.all(uv >= MARGIN_PX) and np.all(uv[:, 0] <= w - MARGIN_PX) and np.all(uv[:, 1] <= h - MARGIN_PX)):
            return False
    return True


@pytest.fixture(scope="module")
def pairs():
    """10 pairs of the twin's board seen whole by both cameras, the sensor's noise, and one
    pair whose board only the right camera sees whole (left out, with its reason)."""
    p = Rig().params()
    rng = np.random.default_rng(11)
    poses = [T for T in plan_board_poses(p, "right", TWIN_BOARD, 60, seed=9) if _fits(p, T)]
    assert len(poses) >= 10, len(poses)
    out = [(f"pair{k:02d}", render_board(p, "left", T, TWIN_BOARD, SimCameraConfig(), rng),
            render_board(p, "right", T, TWIN_BOARD, SimCameraConfig(), rng)) for k, T in enumerate(poses[:10])]
    partial = next(T for T in plan_board_poses(p, "right", TWIN_BOARD, 60, seed=9) if not _fits(p, T)
                   and np.all(board_corners_px(p, "right", T, TWIN_BOARD)[:, 0] < 640 - MARGIN_PX))
    out.append(("partial", render_board(p, "left", partial, TWIN_BOARD, SimCameraConfig(), rng),
                render_board(p, "right", partial, TWIN_BOARD, SimCameraConfig(), rng)))
    return out


@pytest.fixture(scope="module")
def result(pairs):
    return calibrate_stereo(pairs, TWIN_BOARD)


def test_the_pairs_pose_is_found_within_its_uncertainty(result):
    truth = x_from_transform(_truth_right_T_left())
    got = x_from_transform(result.right_T_left_mm)
    assert abs(result.baseline_mm - 90.33) < 0.5, result.baseline_mm
    for k, (name, t, g) in enumerate(zip(("x_mm", "y_mm", "z_mm", "psi_deg", "theta_deg", "phi_deg"), truth, got,
                                         strict=True)):
        # within 4 jackknife sigmas, and the sigmas themselves small (a calibrated pair)
        assert abs(g - t) <= max(4 * result.sigma_x[name], 0.05), (name, g, t, result.sigma_x[name])
        assert result.sigma_x[name] < (1.0 if k < 3 else 0.1), (name, result.sigma_x[name])
    for cal in (result.left, result.right):  # each camera: the nominal a_u 1000, centre (320, 240)
        assert abs(cal.a_u - 1000.0) < 4 * cal.sigma["a_u"] + 2.0
        assert abs(cal.u0 - 320.0) < 4 * cal.sigma["u0"] + 2.0
    assert result.rms_px < 0.5
    assert [n for n, _ in result.rejected] == ["partial"] and "no board found in the left image" in result.rejected[0][1]


def test_the_rig_takes_the_pair_and_reads_back(result, tmp_path):
    rig = apply_stereo_to_rig(Rig(), result, "2026-11-27")
    assert rig.kind == "stereo" and rig.stereo.baseline_mm() == pytest.approx(result.baseline_mm)
    write_rig(tmp_path / "rig.toml", rig)
    back = load_rig(tmp_path / "rig.toml")
    assert back == rig
    assert "stereo stereo-zhang (2026-11-27)" in back.methods()


def test_too_few_pairs_and_mixed_sizes_are_refused(pairs):
    with pytest.raises(CalibrationError, match="too few pairs with the board in both images: 3 of 3"):
        calibrate_stereo(pairs[:3], TWIN_BOARD)
    name, left, right = pairs[0]
    with pytest.raises(CalibrationError, match="different sizes"):
        calibrate_stereo([(name, left, right[:400])], TWIN_BOARD)


def test_the_cli_writes_the_rig_from_a_folder_of_pairs(pairs, tmp_path):
    import cv2

    for side in ("left", "right"):
        (tmp_path / "pairs" / side).mkdir(parents=True)
    for name, left, right in pairs:
        cv2.imwrite(str(tmp_path / "pairs" / "left" / f"{name}.png"), left)
        cv2.imwrite(str(tmp_path / "pairs" / "right" / f"{name}.png"), right)
    rig_path = tmp_path / "rig.toml"
    write_rig(rig_path, Rig())
    r = run_cli_here("calibrate", "stereo", "--images", str(tmp_path / "pairs"), "--rig", str(rig_path))
    assert r.returncode == 0, r.stderr
    assert "baseline 90." in r.stdout and "left out partial" in r.stdout
    rig = load_rig(rig_path)
    assert rig.kind == "stereo" and abs(rig.stereo.baseline_mm() - 90.33) < 0.5
    assert (tmp_path / "rig.toml.bak").exists()  # the old rig kept
    # a right image without its left one: refused, the rig untouched
    cv2.imwrite(str(tmp_path / "pairs" / "right" / "lonely.png"), pairs[0][2])
    before = rig_path.read_text()
    r = run_cli_here("calibrate", "stereo", "--images", str(tmp_path / "pairs"), "--rig", str(rig_path))
    assert r.returncode == 2 and "lonely.png" in r.stderr and rig_path.read_text() == before
