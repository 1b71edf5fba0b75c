"""PSVS model: eq. (1)-(6), forward model and the three triangulators."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings

from humanpt.geometry import (
    GeometryError,
    PinholeCamera,
    PsvsParams,
    in_image,
    intrinsic_matrix,
    project,
    project_pinhole,
    projection_jacobian,
    psvs_m_l_mm,
    refraction_angle_deg,
    triangulate,
    triangulate_eq2,
    triangulate_eq4,
    triangulate_lsq,
    virtual_camera_centres_mm,
)

from .geometry_strategies import psvs_params, scene_points

# --------------------------------------------------------------------- eq. (5), (6), (3), (1)


def test_paper_m_and_l_for_1mm_45deg_n15():
    m, l = psvs_m_l_mm(thickness_mm=1.0, omega1_deg=45.0, n_glass=1.5, n_air=1.0)
    assert round(m, 3) == 0.329
    assert round(l, 3) == 0.378


def test_m_l_scale_with_thickness_and_vanish_without_plate():
    m1, l1 = psvs_m_l_mm(1.0)
    m2, l2 = psvs_m_l_mm(2.5)
    assert m2 == pytest.approx(2.5 * m1, rel=1e-12)
    assert l2 == pytest.approx(2.5 * l1, rel=1e-12)
    assert psvs_m_l_mm(0.0) == (0.0, 0.0)


def test_refraction_angle_follows_snell():
    theta_r = refraction_angle_deg(45.0, n_glass=1.5, n_air=1.0)
    assert math.sin(math.radians(theta_r)) * 1.5 == pytest.approx(math.sin(math.radians(45.0)))
    # No refraction when the indices match: theta_r = theta_i = 90 - omega1.
    assert refraction_angle_deg(30.0, 1.0, 1.0) == pytest.approx(60.0)


def test_refraction_rejects_impossible_geometry():
    with pytest.raises(ValueError, match="omega1"):
        psvs_m_l_mm(1.0, omega1_deg=95.0)
    with pytest.raises(ValueError, match="total internal reflection"):
        refraction_angle_deg(10.0, n_glass=1.0, n_air=1.5)
    with pytest.raises(ValueError, match="thickness"):
        psvs_m_l_mm(-1.0)


def test_eq3_virtual_camera_centres():
    right, left = virtual_camera_centres_mm(90.0, 0.329, 0.378)
    np.testing.assert_allclose(right, [45.0, 0.0, -45.0])
    np.testing.assert_allclose(left, [-45.329, 0.0, -44.622])
    params = PsvsParams(baseline_mm=90.0, m_mm=0.329, l_mm=0.378)
    np.testing.assert_allclose(params.right_camera.centre, right)
    np.testing.assert_allclose(params.left_camera.centre, left)


def test_eq1_intrinsic_matrix_with_skew():
    k = intrinsic_matrix(1000.0, 990.0, 320.0, 240.0, skew=2.5)
    np.testing.assert_array_equal(k, [[1000.0, 2.5, 320.0], [0.0, 990.0, 240.0], [0.0, 0.0, 1.0]])
    cam = PinholeCamera(1000.0, 990.0, 320.0, 240.0, (0.0, 0.0, 0.0), skew=2.5)
    p = np.array([30.0, -20.0, 500.0])
    homog = k @ p
    np.testing.assert_allclose(project_pinhole(cam, p), homog[:2] / homog[2], rtol=0, atol=1e-12)


# --------------------------------------------------------------------- PsvsParams


def test_default_params_match_the_brief():
    p = PsvsParams()
    assert p.image_size_px == (640, 480)
    assert (p.a_u, p.a_v, p.u0, p.v0, p.skew, p.baseline_mm) == (1000, 1000, 320, 240, 0, 90)
    assert (round(p.m_mm, 3), round(p.l_mm, 3)) == (0.329, 0.378)
    assert p.dist_coeffs == (0.0,) * 5
    assert (p.right_camera.u0, p.right_camera.v0) == (320, 240)
    assert (p.left_camera.u0, p.left_camera.v0) == (320, 240)
    assert p == PsvsParams.from_mirror()
    hash(p)  # frozen and hashable


def test_replace_moves_shared_image_centre_but_keeps_overrides():
    p = dataclasses.replace(PsvsParams(u0_left=322.0), u0=330.0, a_u=1200.0)
    assert p.right_camera.u0 == 330.0 and p.left_camera.u0 == 322.0
    assert p.right_camera.a_u == p.left_camera.a_u == 1200.0
    np.testing.assert_allclose(p.real_camera_matrix[0], [1200.0, 0.0, 330.0])


def test_in_image():
    p = PsvsParams()
    uv = np.array([[0.0, 0.0], [639.4, 479.4], [-1.0, 10.0], [100.0, 480.0], [5.0, 5.0]])
    np.testing.assert_array_equal(in_image(p, uv), [True, True, False, False, True])
    np.testing.assert_array_equal(in_image(p, uv, margin_px=10.0), [False] * 5)


def test_from_mirror_sets_m_l_and_keeps_other_fields():
    p = PsvsParams.from_mirror(thickness_mm=2.0, a_u=1200.0, baseline_mm=60.0)
    m, l = psvs_m_l_mm(2.0)
    assert (p.m_mm, p.l_mm, p.a_u, p.baseline_mm) == (m, l, 1200.0, 60.0)
    with pytest.raises(ValueError, match="computes m_mm"):
        PsvsParams.from_mirror(m_mm=0.1)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"a_u": 0.0}, "a_u must be > 0"),
        ({"a_v": -5.0}, "a_v must be > 0"),
        ({"baseline_mm": 0.0}, "baseline_mm must be > 0"),
        ({"u0": float("nan")}, "u0 must be finite"),
        ({"skew": float("inf")}, "skew must be finite"),
        ({"image_size_px": (640,)}, "image_size_px"),
        ({"image_size_px": (640.5, 480)}, "image_size_px"),
        ({"image_size_px": (0, 480)}, "image_size_px"),
        ({"dist_coeffs": (0.1, 0.2, 0.3)}, "distortion coefficients"),
        ({"m_mm": 60.0}, "m_mm"),
        ({"a_u": "fast"}, "a_u must be a number"),
    ],
)
def test_params_validation_messages(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PsvsParams(**kwargs)


def test_four_distortion_coefficients_are_padded():
    assert PsvsParams(dist_coeffs=(0.1, 0.0, 0.0, 0.0)).dist_coeffs == (0.1, 0, 0, 0, 0)


# --------------------------------------------------------------------- eq. (4) as printed


def _eq4_literal(p: PsvsParams, ur, vr, ul, vl):
    """Eq. (4) typed from the paper, line by line (c = 0)."""
    a_u, a_v, b, m, l = p.a_u, p.a_v, p.baseline_mm, p.m_mm, p.l_mm
    u0_r, v0_r, u0_l, v0_l = p.right_camera.u0, p.right_camera.v0, p.u0_left, p.v0_left
    z = (a_u * (b + m) + l * (ul - u0_l)) / ((ul - u0_l) - (ur - u0_r)) - b / 2
    x_r = 1 / a_u * (z + b / 2) * (ur - u0_r) + b / 2
    x_l = 1 / a_u * (z + b / 2 - l) * (ul - u0_l) - b / 2 - m
    y_r = 1 / a_v * (z + b / 2) * (vr - v0_r)
    y_l = 1 / a_v * (z + b / 2 - l) * (vl - v0_l)
    return z, x_r, x_l, y_r, y_l


def test_eq4_matches_the_printed_formulas():
    p = PsvsParams(u0_left=322.0, v0_left=238.5)
    rng = np.random.default_rng(4)
    ur, vr = rng.uniform(50, 300, 20), rng.uniform(50, 400, 20)
    ul, vl = ur + rng.uniform(80, 200, 20), vr + rng.normal(0, 0.5, 20)  # noisy pairs
    got = triangulate_eq4(p, np.stack([ur, vr], -1), np.stack([ul, vl], -1))
    z, x_r, x_l, y_r, y_l = _eq4_literal(p, ur, vr, ul, vl)
    np.testing.assert_allclose(got[:, 2], z, rtol=0, atol=1e-9)
    np.testing.assert_allclose(x_r, x_l, rtol=0, atol=1e-9)  # the two x equations agree
    np.testing.assert_allclose(got[:, 0], x_r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[:, 1], 0.5 * (y_r + y_l), rtol=0, atol=1e-9)


def test_eq4_point_on_axis_of_default_psvs():
    p = PsvsParams()
    point = np.array([0.0, 0.0, 600.0])
    uv_r, uv_l = project(p, point)
    # Right camera at x = +b/2 sees the axis point left of centre, the left one right of it.
    assert uv_r[0] < p.u0 < uv_l[0]
    assert uv_r[1] == pytest.approx(p.v0) and uv_l[1] == pytest.approx(p.v0)
    np.testing.assert_allclose(triangulate_eq4(p, uv_r, uv_l), point, rtol=0, atol=1e-9)


# --------------------------------------------------------------------- round trips


@settings(deadline=None, max_examples=60)
@given(params=psvs_params(), point=scene_points())
def test_forward_then_triangulate_returns_the_point(params, point):
    uv_r, uv_l = project(params, point)
    for method in ("eq4", "eq2", "lsq"):
        back = triangulate(params, uv_r, uv_l, method=method)
        np.testing.assert_allclose(back, point, rtol=0, atol=1e-9, err_msg=method)


@settings(deadline=None, max_examples=40)
@given(params=psvs_params(distortion=False), point=scene_points())
def test_eq2_with_eq3_centres_equals_eq4(params, point):
    rng = np.random.default_rng(0)
    uv_r, uv_l = project(params, point)
    uv_r = uv_r + rng.normal(0, 0.3, 2)  # off the exact projections: formulas, not luck
    uv_l = uv_l + rng.normal(0, 0.3, 2)
    a = triangulate_eq4(params, uv_r, uv_l)
    b = triangulate_eq2(params.right_camera, params.left_camera, uv_r, uv_l)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-8)


def test_eq2_ordinary_stereo_rig_with_different_cameras():
    right = PinholeCamera(1210.0, 1190.0, 330.0, 236.0, (60.0, 2.0, 5.0), skew=1.0)
    left = PinholeCamera(1180.0, 1175.0, 312.0, 248.0, (-60.0, -1.0, -3.0))
    rng = np.random.default_rng(7)
    pts = np.column_stack(
        [rng.uniform(-200, 200, 50), rng.uniform(-150, 150, 50), rng.uniform(400, 1500, 50)]
    )
    uv_r, uv_l = project_pinhole(right, pts), project_pinhole(left, pts)
    np.testing.assert_allclose(triangulate_eq2(right, left, uv_r, uv_l), pts, atol=1e-9, rtol=0)
    np.testing.assert_allclose(triangulate_lsq(right, left, uv_r, uv_l), pts, atol=1e-9, rtol=0)


def test_lsq_minimises_the_reprojection_error():
    p = PsvsParams()
    rng = np.random.default_rng(11)
    pts = np.column_stack(
        [rng.uniform(-100, 100, 200), rng.uniform(-80, 80, 200), rng.uniform(400, 1000, 200)]
    )
    uv_r, uv_l = project(p, pts)
    uv_r = uv_r + rng.normal(0, 0.5, uv_r.shape)
    uv_l = uv_l + rng.normal(0, 0.5, uv_l.shape)

    def sse(x):
        r, l = project(p, x)
        return np.sum((r - uv_r) ** 2 + (l - uv_l) ** 2, axis=-1)

    lsq = triangulate_lsq(p.right_camera, p.left_camera, uv_r, uv_l)
    eq4 = triangulate_eq4(p, uv_r, uv_l)
    assert np.all(sse(lsq) <= sse(eq4) + 1e-9)
    assert np.mean(sse(lsq)) < np.mean(sse(eq4))
    # Gradient of the SSE vanishes at the least-squares point (first-order optimality).
    jac = np.concatenate(
        [projection_jacobian(p.right_camera, lsq), projection_jacobian(p.left_camera, lsq)], -2
    )
    r, l = project(p, lsq)
    resid = np.concatenate([r - uv_r, l - uv_l], -1)
    grad = np.einsum("nij,ni->nj", jac, resid)
    assert np.max(np.abs(grad)) < 1e-8


def test_projection_jacobian_matches_finite_differences():
    cam = PsvsParams(skew=1.5).left_camera
    point = np.array([40.0, -30.0, 700.0])
    h = 1e-4
    numeric = np.stack(
        [
            (project_pinhole(cam, point + h * e) - project_pinhole(cam, point - h * e)) / (2 * h)
            for e in np.eye(3)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(projection_jacobian(cam, point), numeric, rtol=1e-7, atol=1e-10)


def test_batches_broadcast():
    p = PsvsParams(dist_coeffs=(-0.05, 0.01, 0.0, 0.0, 0.0))
    pts = np.random.default_rng(2).uniform([-50, -50, 500], [50, 50, 800], (4, 3, 3))
    uv_r, uv_l = project(p, pts)
    assert uv_r.shape == (4, 3, 2) and uv_l.shape == (4, 3, 2)
    for method in ("eq4", "eq2", "lsq"):
        np.testing.assert_allclose(triangulate(p, uv_r, uv_l, method), pts, atol=1e-9, rtol=0)


# --------------------------------------------------------------------- degenerate input


def test_zero_disparity_raises():
    p = PsvsParams()
    with pytest.raises(GeometryError, match="zero disparity"):
        triangulate_eq4(p, [300.0, 240.0], [300.0, 240.0])
    with pytest.raises(GeometryError, match="zero disparity"):
        triangulate_eq2(p.right_camera, p.left_camera, [300.0, 240.0], [300.0, 240.0])


def test_swapped_pair_raises_behind_camera():
    p = PsvsParams()
    uv_r, uv_l = project(p, [0.0, 0.0, 600.0])
    for method in ("eq4", "eq2", "lsq"):
        with pytest.raises(GeometryError, match="behind a virtual camera"):
            triangulate(p, uv_l, uv_r, method=method)


def test_point_behind_camera_cannot_be_projected():
    with pytest.raises(GeometryError, match="not in front"):
        project(PsvsParams(), [0.0, 0.0, -100.0])


def test_unknown_method_and_bad_shapes():
    p = PsvsParams()
    with pytest.raises(ValueError, match="method"):
        triangulate(p, [1.0, 2.0], [3.0, 4.0], method="dlt")
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        triangulate_eq4(p, [1.0, 2.0, 3.0], [3.0, 4.0])
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        project(p, [1.0, 2.0])
