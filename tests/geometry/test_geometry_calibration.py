"""Driver-tip calibration: eq. (10)-(13) and the least-squares pivot calibration."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.geometry import (
    GeometryError,
    PsvsParams,
    TargetModel,
    calibrate_tip_paper,
    calibrate_tip_pivot,
    compose,
    estimate_camera_T_tob,
    invert_transform,
    project,
    transform_from_x,
    transform_points,
    triangulate,
    world_point_from_samples,
)

TRUE_TIP = np.array([3.0, -2.0, 58.0])  # tob frame, mm (a slightly bent needle)
PIVOT = np.array([450.0, 1200.0, 80.0])  # world frame, mm
FLANGE_T_CAMERA = transform_from_x([0.0, 80.0, 120.0, 90.0, 0.0, 0.0])
DOWN = transform_from_x([0.0, 0.0, 0.0, 0.0, 180.0, 0.0])  # w (underside) towards -z_world


def _pivot_poses(rng, n):
    """world_T_tob of a TOB whose tip rests on PIVOT, tilted up to ~35 deg about x and y,
    spun freely about its w axis."""
    tilt = transform_from_x(
        np.column_stack([np.zeros((n, 3)), rng.uniform(-180, 180, n), rng.uniform(-35, 35, (n, 2))])
    )
    rot = DOWN @ tilt
    t = PIVOT - np.einsum("nij,j->ni", rot[:, :3, :3], TRUE_TIP)
    rot[:, :3, 3] = t
    return rot


def _camera_looking_at(world_T_tob, rng):
    """A flange pose that puts the TOB ~600 mm in front of the camera (visual servo)."""
    n = world_T_tob.shape[0]
    camera_T_tob = transform_from_x(
        np.column_stack(
            [
                rng.normal(0, 10, (n, 2)),
                600 + rng.normal(0, 10, n),
                rng.uniform(-180, 180, n),
                rng.normal(0, 8, (n, 2)),
            ]
        )
    )
    world_T_camera = world_T_tob @ invert_transform(camera_T_tob)
    return world_T_camera @ invert_transform(FLANGE_T_CAMERA), camera_T_tob


def test_pivot_recovers_tip_and_pivot_from_noise_free_poses():
    poses = _pivot_poses(np.random.default_rng(1), 30)
    cal = calibrate_tip_pivot(poses)
    np.testing.assert_allclose(cal.tob_t_tip_mm, TRUE_TIP, atol=0.01)
    np.testing.assert_allclose(cal.world_p_pivot_mm, PIVOT, atol=0.01)
    assert np.max(np.abs(cal.tob_t_tip_mm - TRUE_TIP)) < 1e-9
    assert cal.residual_rms_mm < 1e-9
    assert cal.n_samples == 30 and cal.method == "pivot"
    assert cal.residuals_mm.shape == (30, 3)


def test_pivot_from_noisy_psvs_measurements_within_predicted_sigma():
    """End to end: noisy pixels -> eq. (4) -> eq. (7), (8) -> world -> pivot calibration."""
    rng = np.random.default_rng(2)
    params, model = PsvsParams(), TargetModel()
    world_T_tob = _pivot_poses(rng, 60)
    world_T_flange, camera_T_tob_true = _camera_looking_at(world_T_tob, rng)
    measured = []
    for c_T_t in camera_T_tob_true:
        uv_r, uv_l = project(params, transform_points(c_T_t, model.source_positions_mm))
        uv_r = uv_r + rng.normal(0, 0.05, uv_r.shape)
        uv_l = uv_l + rng.normal(0, 0.05, uv_l.shape)
        pts = triangulate(params, uv_r, uv_l)
        measured.append(estimate_camera_T_tob(model, pts[rng.permutation(3)])[0])
    world_T_tob_meas = compose(world_T_flange, FLANGE_T_CAMERA, np.array(measured))
    cal = calibrate_tip_pivot(world_T_tob_meas)
    err = np.abs(cal.tob_t_tip_mm - TRUE_TIP)
    assert np.all(err < 3.0 * cal.tob_t_tip_sigma_mm), (err, cal.tob_t_tip_sigma_mm)
    assert np.all(np.abs(cal.world_p_pivot_mm - PIVOT) < 3.0 * cal.world_p_pivot_sigma_mm)
    assert 0.0 < cal.residual_rms_mm < 5.0
    assert np.all(cal.tob_t_tip_sigma_mm < 1.0)  # and the calibration is actually useful
    # The paper's method on the same data, with P' known, agrees within the same bound.
    paper = calibrate_tip_paper(world_T_flange, FLANGE_T_CAMERA, np.array(measured), PIVOT)
    assert np.all(np.abs(paper.tob_t_tip_mm - TRUE_TIP) < 3.0 * paper.tob_t_tip_sigma_mm + 0.05)


def test_pivot_predicted_sigma_matches_scatter_over_repeats():
    rng = np.random.default_rng(3)
    poses = _pivot_poses(rng, 25)
    errors, sigmas = [], []
    for _ in range(400):
        noisy = poses.copy()
        noisy[:, :3, 3] += rng.normal(0, 0.2, (25, 3))
        cal = calibrate_tip_pivot(noisy)
        errors.append(cal.tob_t_tip_mm - TRUE_TIP)
        sigmas.append(cal.tob_t_tip_sigma_mm)
    ratio = np.std(errors, axis=0) / np.sqrt(np.mean(np.square(sigmas), axis=0))
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio


def test_paper_method_eq10_to_eq13_noise_free():
    rng = np.random.default_rng(4)
    # Eq. (10), (11): P' measured by the PSVS from N robot poses.
    w_T_f = transform_from_x(
        np.column_stack([rng.uniform(200, 600, (12, 3)), rng.uniform(-60, 60, (12, 3))])
    )
    cam_p = transform_points(invert_transform(compose(w_T_f, FLANGE_T_CAMERA)), PIVOT)
    world_p, per_sample = world_point_from_samples(w_T_f, FLANGE_T_CAMERA, cam_p)
    np.testing.assert_allclose(world_p, PIVOT, atol=1e-9)
    np.testing.assert_allclose(per_sample, np.broadcast_to(PIVOT, (12, 3)), atol=1e-9)
    # Eq. (12), (13): the tip in the TOB frame from the recorded states.
    world_T_tob = _pivot_poses(rng, 20)
    world_T_flange, camera_T_tob = _camera_looking_at(world_T_tob, rng)
    cal = calibrate_tip_paper(world_T_flange, FLANGE_T_CAMERA, camera_T_tob, world_p)
    np.testing.assert_allclose(cal.tob_t_tip_mm, TRUE_TIP, atol=1e-9)
    assert cal.residual_rms_mm < 1e-9 and cal.method == "paper"
    # A wrong P' shows up in the residual RMS.
    off = calibrate_tip_paper(world_T_flange, FLANGE_T_CAMERA, camera_T_tob, PIVOT + [2, 0, 0])
    assert off.residual_rms_mm > 0.5


def test_paper_method_noisy_mean_is_within_standard_error():
    rng = np.random.default_rng(5)
    world_T_tob = _pivot_poses(rng, 200)
    world_T_flange, camera_T_tob = _camera_looking_at(world_T_tob, rng)
    camera_T_tob = camera_T_tob.copy()
    camera_T_tob[:, :3, 3] += rng.normal(0, 0.3, (200, 3))
    cal = calibrate_tip_paper(world_T_flange, FLANGE_T_CAMERA, camera_T_tob, PIVOT)
    err = np.abs(cal.tob_t_tip_mm - TRUE_TIP)
    assert np.all(err < 3 * cal.tob_t_tip_sigma_mm)
    np.testing.assert_allclose(cal.tob_t_tip_sigma_mm, 0.3 / np.sqrt(200), rtol=0.2)


def test_pivot_rejects_ill_posed_and_bad_input():
    rng = np.random.default_rng(6)
    # Spinning only about one axis leaves the tip undetermined along that axis.
    spin = transform_from_x(
        np.column_stack([np.zeros((10, 3)), rng.uniform(-180, 180, 10), np.zeros((10, 2))])
    )
    spin[:, :3, 3] = PIVOT - np.einsum("nij,j->ni", spin[:, :3, :3], TRUE_TIP)
    with pytest.raises(GeometryError, match="at least two different axes"):
        calibrate_tip_pivot(spin)
    with pytest.raises(GeometryError, match="at least 3 samples"):
        calibrate_tip_pivot(_pivot_poses(rng, 2))
    bad = _pivot_poses(rng, 5)
    bad[2, :3, :3] *= 2.0
    with pytest.raises(GeometryError, match="not orthonormal"):
        calibrate_tip_pivot(bad)
    with pytest.raises(ValueError, match="need one each"):
        calibrate_tip_paper(_pivot_poses(rng, 4), np.eye(4), _pivot_poses(rng, 3), PIVOT)
