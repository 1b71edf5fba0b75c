"""Rotated virtual cameras (tilted mirrors) and per-view principal points (issue 16)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry import (
    PinholeCamera,
    PsvsParams,
    parallel_pixels,
    point_covariance_mm2,
    project,
    project_pinhole,
    projection_jacobian,
    triangulate,
    virtual_rotation_from_mirror_tilt_deg,
)
from humanpt.geometry.config import PsvsConfig

ROT_R = (0.03, -0.08, 0.02)  # deg, a few mirror-misalignment-sized rotations
ROT_L = (-0.05, 0.1, -0.04)


def _rotated(**kw) -> PsvsParams:
    return PsvsParams(rotvec_right_deg=ROT_R, rotvec_left_deg=ROT_L, **kw)


@pytest.mark.parametrize("method", ["eq4", "eq2", "lsq"])
@pytest.mark.parametrize(
    "extra",
    [
        {},
        {"u0_left": 323.5, "v0_left": 238.0, "u0_right": 318.0, "skew": 0.4},
        {"dist_coeffs": (-0.2, 0.05, 1e-4, -2e-4, 0.0)},
    ],
)
def test_project_then_triangulate_returns_the_point_with_rotated_cameras(method, extra):
    params = _rotated(**extra)
    rng = np.random.default_rng(16)
    depth = np.array([300.0, 450.0, 645.0, 900.0, 1500.0])
    pts = np.column_stack(
        [rng.uniform(-0.15, 0.15, 5) * depth, rng.uniform(-0.1, 0.1, 5) * depth, depth]
    )
    uv_r, uv_l = project(params, pts)
    np.testing.assert_allclose(triangulate(params, uv_r, uv_l, method=method), pts, atol=1e-7)


def test_identity_rotation_leaves_every_pixel_and_point_unchanged():
    params = PsvsParams(rotvec_left_deg=(0.0, 0.0, 0.0), u0_left=321.0)
    assert params.is_parallel and params.left_camera.is_parallel
    uv = np.array([[100.25, 200.5], [400.0, 30.0]])
    assert parallel_pixels(params.left_camera, uv) is not None
    np.testing.assert_array_equal(parallel_pixels(params.left_camera, uv), uv)
    p = np.array([[10.0, -5.0, 645.0]])
    uv_r, uv_l = project(params, p)
    unrotated = PsvsParams(u0_left=321.0)
    for method in ("eq4", "eq2", "lsq"):
        np.testing.assert_array_equal(
            triangulate(params, uv_r, uv_l, method=method),
            triangulate(unrotated, uv_r, uv_l, method=method),
        )


def test_projection_is_the_rotated_pinhole_by_hand():
    """x_v = R^T (P - O), then eq. (1): the rotation matrix from scipy, not the code's."""
    rotvec = np.radians([0.4, -0.7, 0.25])
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    cam = PinholeCamera(1000.0, 990.0, 321.0, 239.0, (-45.3, 0.0, -44.6), 0.5, rot)
    p = np.array([25.0, -12.0, 600.0])
    x = rot.T @ (p - np.array([-45.3, 0.0, -44.6]))
    expected = [321.0 + (1000.0 * x[0] + 0.5 * x[1]) / x[2], 239.0 + 990.0 * x[1] / x[2]]
    np.testing.assert_allclose(project_pinhole(cam, p), expected, rtol=0, atol=1e-10)


def test_projection_jacobian_of_a_rotated_camera_matches_finite_differences():
    cam = _rotated(skew=1.2).left_camera
    p = np.array([30.0, -20.0, 700.0])
    h = 1e-4
    numeric = np.stack(
        [
            (project_pinhole(cam, p + h * e) - project_pinhole(cam, p - h * e)) / (2 * h)
            for e in np.eye(3)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(projection_jacobian(cam, p), numeric, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize("angle_deg", [0.05, 0.1, -0.3, 2.0])
@pytest.mark.parametrize("depth_mm", [400.0, 645.0, 1200.0])
def test_pan_and_tilt_shift_the_image_by_a_tan_angle(angle_deg, depth_mm):
    """A point on a view's optical axis: a pan (about y) by theta moves it by
    -a_u tan(theta) along u, a tilt (about x) by +a_v tan(theta) along v (hand
    calculation: R_y(theta)^T (0, 0, Z) = Z (-sin, 0, cos))."""
    base = PsvsParams(a_u=1000.0, a_v=980.0)
    left = base.left_camera
    on_axis = left.centre + np.array([0.0, 0.0, depth_mm])
    uv0 = project_pinhole(left, on_axis)
    np.testing.assert_allclose(uv0, [320.0, 240.0], atol=1e-9)
    pan = PsvsParams(a_u=1000.0, a_v=980.0, rotvec_left_deg=(0.0, angle_deg, 0.0)).left_camera
    tilt = PsvsParams(a_u=1000.0, a_v=980.0, rotvec_left_deg=(angle_deg, 0.0, 0.0)).left_camera
    t = math.tan(math.radians(angle_deg))
    np.testing.assert_allclose(project_pinhole(pan, on_axis) - uv0, [-1000.0 * t, 0.0], atol=1e-9)
    np.testing.assert_allclose(project_pinhole(tilt, on_axis) - uv0, [0.0, 980.0 * t], atol=1e-9)


def test_a_mirror_tilt_of_alpha_rotates_the_virtual_camera_by_two_alpha():
    """Reflect the real camera's axes in a 45 deg mirror, tilt the mirror by alpha about an
    axis in its plane, reflect again: the virtual axes turn by 2 alpha about that axis
    (Householder reflections; the relative rotation from scipy)."""

    def reflection(normal):
        n = np.asarray(normal, float) / np.linalg.norm(normal)
        return np.eye(3) - 2.0 * np.outer(n, n)

    normal = np.array([1.0, 0.0, -1.0]) / math.sqrt(2.0)
    for axis, alpha in (((0.0, 1.0, 0.0), 0.05), ((1.0, 0.0, 1.0), -0.2), ((0.0, 1.0, 0.0), 1.5)):
        a = np.asarray(axis) / np.linalg.norm(axis)
        assert abs(a @ normal) < 1e-12  # the tilt axis lies in the mirror
        tilt = Rotation.from_rotvec(np.radians(alpha) * a).as_matrix()
        nominal = reflection(normal)
        tilted = reflection(tilt @ normal)
        relative = Rotation.from_matrix(tilted @ nominal.T)  # a proper rotation
        np.testing.assert_allclose(
            np.degrees(relative.as_rotvec()),
            virtual_rotation_from_mirror_tilt_deg(alpha, axis),
            atol=1e-10,
        )
    np.testing.assert_allclose(virtual_rotation_from_mirror_tilt_deg(0.05), [0.0, 0.1, 0.0])


@pytest.mark.parametrize("depth_mm", [450.0, 645.0, 900.0])
def test_unmodelled_pan_of_one_view_biases_depth_by_the_disparity_error(depth_mm):
    """The world's left virtual camera panned by 0.1 deg, triangulated with the nominal
    (parallel) model: the left view shifts by du = -a_u tan(0.1 deg) = -1.745 px, the
    disparity D = a_u (b + m)/(z + b/2) shrinks by |du| and the depth grows by
    (z + b/2) |du| / (D - |du|) (hand calculation from eq. (4), the l term neglected;
    z = 645 mm, b = 90 mm, a_u = 1000 px: +9.3 mm). 2 % for the point's 3.7 deg off the
    left axis and l."""
    world = PsvsParams(rotvec_left_deg=(0.0, 0.1, 0.0))
    nominal = PsvsParams()
    p = np.array([0.0, 0.0, depth_mm])
    uv_r, uv_l = project(world, p)
    measured = triangulate(nominal, uv_r, uv_l)
    du = 1000.0 * math.tan(math.radians(0.1))
    depth = depth_mm + 45.0
    disparity = 1000.0 * (90.0 + nominal.m_mm) / depth
    expected = depth * du / (disparity - du)
    assert measured[2] - depth_mm == pytest.approx(expected, rel=0.02)
    assert expected > 0


def test_point_covariance_of_rotated_cameras_matches_monte_carlo():
    """The error model runs the same projection and triangulation: its covariance agrees
    with the sample covariance of noisy observations (4000 samples: ~5 % on a sigma)."""
    params = _rotated(dist_coeffs=(-0.1, 0.0, 0.0, 0.0, 0.0))
    p = np.array([20.0, -15.0, 645.0])
    sigma = 0.05
    cov = point_covariance_mm2(params, p, sigma)
    uv_r, uv_l = project(params, p)
    rng = np.random.default_rng([16, 2])
    noise = rng.standard_normal((4000, 4)) * sigma
    pts = triangulate(params, uv_r + noise[:, :2], uv_l + noise[:, 2:])
    np.testing.assert_allclose(np.sqrt(np.diag(np.cov(pts.T))), np.sqrt(np.diag(cov)), rtol=0.06)


def test_rejects_a_non_rotation_and_a_large_misalignment():
    with pytest.raises(ValueError, match="camera_R_virtual"):
        PinholeCamera(1000.0, 1000.0, 320.0, 240.0, (0, 0, 0), 0.0, np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="camera_R_virtual"):
        PinholeCamera(1000.0, 1000.0, 320.0, 240.0, (0, 0, 0), 0.0, 1.01 * np.eye(3))
    with pytest.raises(ValueError, match="rotvec_left_deg"):
        PsvsParams(rotvec_left_deg=(0.0, 45.0, 0.0))
    with pytest.raises(ValueError, match="rotvec_right_deg"):
        PsvsParams(rotvec_right_deg=(0.0, math.nan, 0.0))


def test_config_offsets_and_rotations_reach_the_cameras():
    cfg = PsvsConfig(
        du0_left_px=0.5, dv0_right_px=-0.25, rotvec_left_deg=(0.0, 0.05, 0.0)
    )
    p = cfg.params()
    assert (p.left_camera.u0, p.left_camera.v0) == (320.5, 240.0)
    assert (p.right_camera.u0, p.right_camera.v0) == (320.0, 239.75)
    np.testing.assert_allclose(
        p.left_camera.rotation, Rotation.from_rotvec([0.0, math.radians(0.05), 0.0]).as_matrix()
    )
    assert p.right_camera.is_parallel and not p.is_parallel
    # the defaults are the paper's PSVS, field for field
    assert PsvsConfig().params() == PsvsParams()


def test_config_splitter_thickness_gives_m_and_l_of_eq5_eq6():
    """The paper: d = 1 mm, 45 deg, n = 1.5 -> m = 0.329, l = 0.378 mm; both scale with d."""
    p = PsvsConfig(splitter_thickness_mm=1.1).params()
    assert (round(p.m_mm / 1.1, 3), round(p.l_mm / 1.1, 3)) == (0.329, 0.378)
    assert PsvsConfig(splitter_thickness_mm=1.0).params() == PsvsParams()
    with pytest.raises(ValueError, match="splitter_thickness_mm"):
        PsvsConfig(splitter_thickness_mm=1.1, m_mm=0.5)
