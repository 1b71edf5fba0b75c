"""PSVS calibration: the bundle adjustment against exact synthetic views (the geometry's
own forward model with known parameters), the rig it writes, bad input, and on the twin
against the world's truth - including issue 17's acceptance: after `calibrate psvs` the
0.05 deg mirror tilt that costs ~8 mm with the nominal rig costs under 0.1 mm on the
recorded path."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanpt.calibration.psvs import (
    CalibrationError,
    StereoViews,
    apply_to_rig,
    estimate_psvs,
)
from humanpt.geometry.psvs import project, virtual_rotation_from_mirror_tilt_deg
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import make_transform, matrix_from_rotvec
from humanpt.runtime.rigfile import load_rig, write_rig
from humanpt.twin import evaluate
from humanpt.twin.cal_psvs import calibrate_psvs_on_twin, depth_errors_mm, plan_camera_T_tob
from humanpt.twin.run import SystemConfig, run
from humanpt.twin.worlds import World


def _views(true_psvs, n=24, noise_px=0.0, depths=(450.0, 800.0), seed=3):
    """Exact images (the geometry's forward model) of the rig's target at planned poses."""
    rng = np.random.default_rng(seed)
    tob = Rig().target_model().source_positions_mm
    right, left = [], []
    for camera_T_tob in plan_camera_T_tob(n, seed, depths):
        p = tob @ camera_T_tob[:3, :3].T + camera_T_tob[:3, 3]
        ur, ul = project(true_psvs.params(), p)
        right.append(ur + rng.normal(0, noise_px, ur.shape))
        left.append(ul + rng.normal(0, noise_px, ul.shape))
    return StereoViews(np.array(right), np.array(left))


def test_exact_views_give_the_true_rotation_and_baseline():
    rig = Rig()
    true = dataclasses.replace(rig.psvs, rotvec_left_deg=(0.04, 0.1, -0.03), baseline_mm=90.4)
    est = estimate_psvs(rig, _views(true))
    assert est.rms_px < 1e-6
    np.testing.assert_allclose(est.rotvec_left_deg, true.rotvec_left_deg, atol=1e-6)
    assert est.baseline_mm == pytest.approx(90.4, abs=1e-5)


def test_noisy_views_land_within_their_sigma_and_distortion_is_removed():
    rig = dataclasses.replace(Rig(), psvs=dataclasses.replace(Rig().psvs, dist_coeffs=(-0.01, 0.0, 0.0, 0.0, 0.0)))
    true = dataclasses.replace(rig.psvs, rotvec_left_deg=(0.0, 0.1, 0.0))
    est = estimate_psvs(rig, _views(true, n=40, noise_px=0.03))
    for k, axis in enumerate("xyz"):
        s = est.sigma[f"rotvec_left_deg_{axis}"]
        assert 0 < s < 0.01
        assert abs(est.rotvec_left_deg[k] - true.rotvec_left_deg[k]) < 4 * s, (axis, est.rotvec_left_deg, s)
    assert abs(est.baseline_mm - 90.0) < 4 * est.sigma["baseline_mm"]
    assert 0.02 < est.rms_px < 0.04  # the noise's own size


def test_apply_to_rig_writes_a_rig_that_reads_back(tmp_path):
    rig = Rig()
    true = dataclasses.replace(rig.psvs, rotvec_left_deg=(0.0, 0.1, 0.0))
    est = estimate_psvs(rig, _views(true))
    new = apply_to_rig(rig, est, "2026-11-23T00:00:00Z")
    assert new.psvs.rotvec_left_deg == pytest.approx(est.rotvec_left_deg)
    assert new.psvs.rotvec_right_deg == rig.psvs.rotvec_right_deg  # the reference view is held
    assert new.psvs_calibration.method == "psvs-ba" and set(new.psvs_calibration.sigma) >= {"baseline_mm",
                                                                                              "rotvec_left_deg"}
    assert load_rig(write_rig(tmp_path / "rig.toml", new)) == new


def test_bad_input_is_named():
    rig = Rig()
    views = _views(rig.psvs, n=12)
    with pytest.raises(CalibrationError, match="too few views"):
        estimate_psvs(rig, StereoViews(views.uv_right_px[:3], views.uv_left_px[:3]))
    one_depth = _views(rig.psvs, n=12, depths=(600.0, 610.0))
    with pytest.raises(CalibrationError, match="one depth"):
        estimate_psvs(rig, one_depth)
    with pytest.raises(CalibrationError, match="swapped"):  # right and left exchanged: behind the cameras
        estimate_psvs(rig, StereoViews(views.uv_left_px, views.uv_right_px))
    with pytest.raises(CalibrationError, match="differ in shape"):
        StereoViews(views.uv_right_px, views.uv_left_px[:5])


def test_a_wrong_pair_is_dropped():
    rig = Rig()
    views = _views(rig.psvs, n=20, noise_px=0.02)
    left = views.uv_left_px.copy()
    left[4, 1, 1] += 1.5  # one source of one view mismatched by 1.5 px
    est = estimate_psvs(rig, StereoViews(views.uv_right_px, left))
    assert not est.used[4] and est.used.sum() == 19
    assert est.rms_px < 0.03


def test_twin_mirror_tilt_is_calibrated_and_the_path_error_goes(tmp_path):
    world = World.only("mirror_tilt")
    true_rot = virtual_rotation_from_mirror_tilt_deg(0.05)  # (0, 0.1, 0) deg
    est, report, truth = calibrate_psvs_on_twin(world, Rig(), seed=1, frames_per_pose=2)
    assert len(report) > 3 and any("against the twin's truth" in line for line in truth)
    np.testing.assert_allclose(est.rotvec_left_deg, true_rot, atol=0.003)
    rig = apply_to_rig(Rig(), est, "twin")
    true_rig = dataclasses.replace(Rig(), psvs=SystemConfig.for_scenario("static", world=world).sim_camera.psvs)
    assert depth_errors_mm(Rig(), true_rig)[1, 2] > 7.0  # the nominal rig: ~8 mm at 600 mm
    assert depth_errors_mm(rig, true_rig)[1].max() < 0.05
    # the acceptance: the recorded path (arc, lock-step) with the calibrated rig
    cfg = SystemConfig.for_scenario("arc", 0, rig=rig, world=world)
    res = run(cfg, robot="standin", duration_s=cfg.operator.start_delay_s + 8.0,
              record_from_s=cfg.operator.start_delay_s, digest=False)
    _, err, _ = evaluate.path_truth_errors(res.world, after_ns=evaluate.scenario_start_ns(res.world))
    assert len(err) > 20
    assert np.abs(err[:, :3]).max() < 0.1, np.abs(err[:, :3]).max(axis=0)


def test_twin_views_see_only_the_world_through_perception():
    # The same seed gives the same views; a view gain of 0 (the target in one half only)
    # gives none: the estimate refuses.
    from humanpt.twin.cal_psvs import gather_views

    a = gather_views(World.ideal(), Rig(), seed=2, n_poses=4, frames_per_pose=1)
    b = gather_views(World.ideal(), Rig(), seed=2, n_poses=4, frames_per_pose=1)
    np.testing.assert_array_equal(a.uv_right_px, b.uv_right_px)
    one_view = World("left dark", (), {"sim_camera": {"view_gain_left": 0.0}})
    with pytest.raises(CalibrationError, match="too few views"):
        calibrate_psvs_on_twin(one_view, Rig(), seed=0, n_poses=6, frames_per_pose=1)


def test_plan_keeps_the_target_in_front_and_spread_over_depth():
    plan = plan_camera_T_tob(36, 0)
    assert plan[:, 2, 3].min() == pytest.approx(450.0) and plan[:, 2, 3].max() == pytest.approx(800.0)
    assert make_transform(matrix_from_rotvec(np.zeros(3)), np.zeros(3)).shape == (4, 4)
