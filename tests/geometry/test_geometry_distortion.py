"""Lens distortion: numpy OpenCV model, checked against cv2."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.geometry import (
    GeometryError,
    PsvsParams,
    distort_normalised,
    distort_pixels,
    normalise_pixels,
    pixels_from_normalised,
    undistort_normalised,
    undistort_pixels,
)

from .geometry_strategies import finite

K = np.array([[1000.0, 0.0, 320.0], [0.0, 1010.0, 240.0], [0.0, 0.0, 1.0]])
D = np.array([-0.21, 0.08, 0.0012, -0.0008, -0.01])


def _grid():
    u, v = np.meshgrid(np.linspace(0, 639, 17), np.linspace(0, 479, 13))
    return np.stack([u.ravel(), v.ravel()], -1)


def test_distortion_matches_cv2_project_points():
    rng = np.random.default_rng(3)
    pts = np.column_stack(
        [rng.uniform(-0.35, 0.35, 300), rng.uniform(-0.3, 0.3, 300), np.ones(300)]
    ) * rng.uniform(300, 1500, (300, 1))
    cv_uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, D)
    ideal = (K @ (pts / pts[:, 2:]).T).T[:, :2]
    np.testing.assert_allclose(distort_pixels(ideal, K, D), cv_uv[:, 0, :], rtol=0, atol=1e-9)


def test_undistortion_matches_cv2_undistort_points_iter():
    observed = _grid()
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    src = observed.reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4 names the iterated form so
        cv_ideal = cv2.undistortPointsIter(src, K, D, None, K, criteria)
    else:  # OpenCV 5: undistortPoints takes the criteria
        cv_ideal = cv2.undistortPoints(src, K, D, R=None, P=K, criteria=criteria)
    np.testing.assert_allclose(
        undistort_pixels(observed, K, D), cv_ideal[:, 0, :], rtol=0, atol=1e-6
    )


def test_undistort_then_distort_over_the_whole_image():
    observed = _grid()
    ideal = undistort_pixels(observed, K, D)
    assert np.max(np.abs(ideal - observed)) > 1.0  # the distortion is not negligible here
    np.testing.assert_allclose(distort_pixels(ideal, K, D), observed, rtol=0, atol=1e-9)


@settings(deadline=None, max_examples=80)
@given(
    x=finite(-0.6, 0.6),
    y=finite(-0.45, 0.45),
    k1=finite(-0.15, 0.15),
    k2=finite(-0.03, 0.03),
    p1=finite(-1e-3, 1e-3),
    p2=finite(-1e-3, 1e-3),
    k3=finite(-0.01, 0.01),
)
def test_distort_undistort_round_trip(x, y, k1, k2, p1, p2, k3):
    d = (k1, k2, p1, p2, k3)
    xy = np.array([x, y])
    np.testing.assert_allclose(
        undistort_normalised(distort_normalised(xy, d), d), xy, rtol=0, atol=1e-12
    )


@settings(deadline=None, max_examples=40)
@given(
    u=finite(0.0, 640.0),
    v=finite(0.0, 480.0),
    skew=finite(-3.0, 3.0),
    k1=st.sampled_from([-0.2, 0.1]),
)
def test_pixel_round_trip_with_skew(u, v, skew, k1):
    k = np.array([[1000.0, skew, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]])
    d = (k1, 0.01, 5e-4, -5e-4, 0.0)
    uv = np.array([u, v])
    np.testing.assert_allclose(pixels_from_normalised(normalise_pixels(uv, k), k), uv, atol=1e-9)
    np.testing.assert_allclose(undistort_pixels(distort_pixels(uv, k, d), k, d), uv, atol=1e-9)


def test_no_distortion_is_identity():
    uv = _grid()
    np.testing.assert_array_equal(distort_pixels(uv, K, None), uv)
    np.testing.assert_array_equal(undistort_pixels(uv, K, np.zeros(5)), uv)
    assert not PsvsParams().has_distortion


def test_non_invertible_region_raises():
    # A strong barrel distortion folds back beyond r ~ 1: no ideal point maps there.
    with pytest.raises(GeometryError, match="invertible"):
        undistort_normalised(np.array([2.0, 0.0]), (-0.5, 0.0, 0.0, 0.0, 0.0))


def test_bad_coefficients():
    with pytest.raises(ValueError, match="k1, k2, p1, p2"):
        distort_normalised(np.zeros(2), (0.1, 0.2))
    with pytest.raises(ValueError, match="finite"):
        distort_normalised(np.zeros(2), (np.nan, 0, 0, 0, 0))
