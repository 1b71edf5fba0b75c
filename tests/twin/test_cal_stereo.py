"""The stereo pair's calibration on the twin (issue 35: the job's stage on an ordinary pair,
humanpt.twin.cal_stereo) against the world's truth: the realistic world's cameras are its
PSVS's virtual cameras apart, with its focal error (a_u = a_v = 1003 px, the error source's
stated size), its lens distortion (k1 = -0.01), its mirror tilt and its thicker splitter;
the true baseline is the distance of the virtual cameras' optical centres (the geometry
library's eq. (2) cameras of the world's PSVS), computed here independently of the
calibration's code."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanpt.geometry.rig import Rig, Stereo
from humanpt.geometry.transforms import transform_from_x
from humanpt.sim_camera.config import SimCameraConfig
from humanpt.twin.cal_camera import world_camera
from humanpt.twin.cal_stereo import ACCEPT_SIGMAS, calibrate_stereo_on_twin, true_flange_T_camera
from humanpt.twin.worlds import World

SEED = 0


@pytest.fixture(scope="module")
def calibrated():
    rig = dataclasses.replace(Rig(), kind="stereo", stereo=Stereo.of_psvs(Rig().psvs))
    return calibrate_stereo_on_twin(World.realistic(), rig, SEED)


def test_the_pairs_focal_lengths_and_baseline_are_the_worlds_within_their_sigma(calibrated):
    result, report, truth = calibrated
    world = world_camera(World.realistic(), SEED).psvs.params()  # the world's PSVS: its virtual cameras
    true_baseline = float(np.linalg.norm(np.subtract(world.left_camera.centre_mm, world.right_camera.centre_mm)))
    assert 90.0 < true_baseline < 91.0  # the nominal pair's 90.33 mm, the splitter a little thicker
    assert len(result.pairs) == 16 and result.rejected == ()  # every planned pose seen whole by both cameras
    for cal in (result.left, result.right):
        for key in ("a_u", "a_v"):
            sigma = cal.sigma[key]
            assert 0.0 < sigma < 2.0, (cal.view, key, sigma)  # a calibrated pair: a fraction of a pixel
            assert abs(getattr(cal, key) - 1003.0) <= ACCEPT_SIGMAS * sigma, (cal.view, key, getattr(cal, key), sigma)
        assert cal.dist_coeffs[0] == pytest.approx(-0.01, abs=0.002)
    assert 0.0 < result.sigma_baseline_mm < 0.5
    assert abs(result.baseline_mm - true_baseline) <= ACCEPT_SIGMAS * result.sigma_baseline_mm, (
        result.baseline_mm, true_baseline, result.sigma_baseline_mm)
    # the report and its checks say the same: five figures, all within their acceptance
    assert [c.what for c in truth.checks] == ["left camera a_u off the truth", "left camera a_v off the truth",
                                             "right camera a_u off the truth", "right camera a_v off the truth",
                                             "baseline off the truth"]
    assert all(c.met for c in truth.checks), [c.line() for c in truth.checks]
    assert any(line.startswith("baseline ") for line in report)
    (after,) = [line for line in truth if "worst point error with the pair after" in line]
    assert "600 mm: " in after


def test_a_pair_with_a_longer_baseline_triangulates_points_that_much_farther():
    """By hand: a pair believed 1 % wider than it is puts every point 1 % farther along its
    ray (the depth f B / d scales with B): at 450, 600 and 800 mm, 4.5, 6 and 8 mm deep and,
    50 mm off the axis, 0.5 mm aside; the true pair itself, exactly."""
    from humanpt.twin.cal_stereo import point_errors_mm

    true = Stereo.of_psvs(Rig().psvs)
    wide = dataclasses.replace(true, right_T_left_x=(1.01 * true.right_T_left_x[0], *true.right_T_left_x[1:]))
    np.testing.assert_allclose(point_errors_mm(true, true), 0.0, atol=1e-9)
    np.testing.assert_allclose(point_errors_mm(wide, true), [[0.5, 0.5, 4.5], [0.5, 0.5, 6.0], [0.5, 0.5, 8.0]],
                               atol=0.01)


def test_the_hand_eyes_truth_is_the_rigs_camera_frame():
    """The hand-eye is reported against the world's pose of the RIG's camera frame: on a pair
    whose rig puts that frame on the right camera (camera_T_right identity), the world's
    right virtual camera (by hand: 45 mm along x and -45 mm along z of the nominal PSVS's
    camera frame, which sits at (0, 60, 100) mm on the flange: (45, 60, 55) mm); on the PSVS,
    the world camera's own."""
    cam = SimCameraConfig(stereo=True)
    rig = dataclasses.replace(Rig(), kind="stereo", stereo=Stereo())  # camera frame = right camera
    got = true_flange_T_camera(cam, rig)
    np.testing.assert_allclose(got, transform_from_x(np.array([45.0, 60.0, 55.0, 0, 0, 0])), atol=1e-9)
    # the rig of the PSVS's own pair (Stereo.of_psvs): the frame is the PSVS camera's
    paired = dataclasses.replace(rig, stereo=Stereo.of_psvs(Rig().psvs))
    np.testing.assert_allclose(true_flange_T_camera(cam, paired), cam.flange_T_camera, atol=1e-9)
    np.testing.assert_allclose(true_flange_T_camera(SimCameraConfig(), Rig()), SimCameraConfig().flange_T_camera)
