"""First-order stereo error model against Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.geometry import (
    PsvsParams,
    TargetModel,
    monte_carlo_pose_x,
    point_covariance_mm2,
    point_sigma_mm,
    pose_covariance,
    pose_sigma,
    project,
    transform_from_x,
    triangulate,
    wrap_angle_deg,
    x_from_transform,
)

N_MC = 20000


def _assert_cov_agrees(mc_samples, truth, cov_model, angle_cols=()):
    d = mc_samples - truth
    for c in angle_cols:
        d[:, c] = wrap_angle_deg(d[:, c])
    cov_mc = np.cov(d, rowvar=False)
    sd_model = np.sqrt(np.diag(cov_model))
    ratio = np.sqrt(np.diag(cov_mc)) / sd_model
    assert np.all(np.abs(ratio - 1.0) < 0.10), ratio
    # Correlations agree too (off-diagonals scaled by the standard deviations).
    scale = np.outer(sd_model, sd_model)
    assert np.max(np.abs(cov_mc - cov_model) / scale) < 0.10
    return ratio


@pytest.mark.parametrize("method", ["eq4", "lsq"])
@pytest.mark.parametrize(
    "params",
    [PsvsParams(), PsvsParams(skew=1.5, dist_coeffs=(-0.2, 0.05, 1e-3, -5e-4, 0.0))],
    ids=["ideal", "distorted"],
)
def test_point_sigma_agrees_with_monte_carlo(params, method):
    rng = np.random.default_rng(21)
    point = np.array([35.0, -20.0, 650.0])
    sigma_px = 0.1
    uv_r, uv_l = project(params, point)
    noisy_r = uv_r + rng.normal(0, sigma_px, (N_MC, 2))
    noisy_l = uv_l + rng.normal(0, sigma_px, (N_MC, 2))
    samples = triangulate(params, noisy_r, noisy_l, method=method)
    _assert_cov_agrees(samples, point, point_covariance_mm2(params, point, sigma_px, method))


def test_point_sigma_scales_and_depth_dominates():
    p = PsvsParams()
    s1 = point_sigma_mm(p, [0.0, 0.0, 600.0], 0.1)
    s2 = point_sigma_mm(p, [0.0, 0.0, 600.0], 0.2)
    np.testing.assert_allclose(s2, 2 * s1, rtol=1e-6)
    assert s1[2] > 5 * s1[0]
    # Stereo depth: sigma_z ~ (z + b/2)^2 / (a_u (b + m)) * sqrt(2) sigma_px for c = 0.
    expected = (600 + 45) ** 2 / (1000 * (90 + p.m_mm)) * np.sqrt(2) * 0.1
    assert s1[2] == pytest.approx(expected, rel=0.02)
    far = point_sigma_mm(p, [0.0, 0.0, 1200.0], 0.1)
    assert far[2] == pytest.approx(s1[2] * ((1200 + 45) / 645) ** 2, rel=0.02)


@pytest.mark.parametrize(
    "x_tob, frame",
    [
        ([10.0, -15.0, 600.0, 20.0, 10.0, -8.0], "camera"),
        ([-30.0, 25.0, 700.0, 179.99, -15.0, 12.0], "camera"),  # yaw across +-180
        ([0.0, 0.0, 600.0, -70.0, 5.0, 5.0], "world"),
        ([5.0, 5.0, 550.0, 45.0, 0.0, 20.0], "tip"),
    ],
)
def test_pose_sigma_agrees_with_monte_carlo(x_tob, frame):
    params = PsvsParams(dist_coeffs=(-0.1, 0.02, 0.0, 0.0, 0.0))
    model = TargetModel()
    camera_T_tob = transform_from_x(x_tob)
    a_T_camera = None
    tob_T_frame = None
    if frame == "world":
        a_T_camera = transform_from_x([236.0, 1248.0, 685.0, -2.6, 179.1, -4.5])
    if frame == "tip":
        tob_T_frame = model.tob_T_tip
    sigma_px = 0.05
    cov = pose_covariance(params, model, camera_T_tob, sigma_px, "eq4", a_T_camera, tob_T_frame)
    rng = np.random.default_rng(22)
    samples = monte_carlo_pose_x(
        params, model, camera_T_tob, sigma_px, N_MC, rng, "eq4", a_T_camera, tob_T_frame
    )
    a = np.eye(4) if a_T_camera is None else a_T_camera
    f = np.eye(4) if tob_T_frame is None else tob_T_frame
    truth = x_from_transform(a @ camera_T_tob @ f)
    _assert_cov_agrees(samples, truth, cov, angle_cols=(3, 4, 5))
    np.testing.assert_allclose(
        pose_sigma(params, model, camera_T_tob, sigma_px, "eq4", a_T_camera, tob_T_frame),
        np.sqrt(np.diag(cov)),
    )


def test_bigger_target_is_more_precise_in_angle():
    params = PsvsParams()
    pose = transform_from_x([0.0, 0.0, 600.0, 10.0, 5.0, 5.0])
    small = pose_sigma(params, TargetModel.isosceles(40.0, 30.0), pose, 0.05)
    big = pose_sigma(params, TargetModel.isosceles(80.0, 60.0), pose, 0.05)
    assert np.all(big[3:] < 0.6 * small[3:])
    np.testing.assert_allclose(big[:3], small[:3], rtol=0.35)  # G's precision ~ unchanged


def test_sigma_validation():
    with pytest.raises(ValueError, match="sigma_px"):
        point_sigma_mm(PsvsParams(), [0.0, 0.0, 600.0], -0.1)
    with pytest.raises(ValueError):
        point_sigma_mm(PsvsParams(), [0.0, 0.0, 600.0], [0.1, 0.1, 0.1])
