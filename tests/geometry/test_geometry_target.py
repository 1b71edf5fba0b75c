"""Target model and frame: eq. (7)-(9), labelling, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.geometry import (
    GeometryError,
    TargetModel,
    estimate_camera_T_tob,
    invert_transform,
    isosceles_source_positions_mm,
    label_sources,
    tip_pose,
    tob_frame_from_points,
    tob_T_tip_on_w_axis,
    transform_from_x,
    transform_points,
)

from .geometry_strategies import finite, target_models, tob_poses


def _assert_proper_frame(a_T_b):
    rot = a_T_b[:3, :3]
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(np.cross(rot[:, 0], rot[:, 1]), rot[:, 2], atol=1e-12)
    np.testing.assert_array_equal(a_T_b[3], [0.0, 0.0, 0.0, 1.0])


# --------------------------------------------------------------------- eq. (7), (8)


@settings(deadline=None, max_examples=100)
@given(
    pts=st.lists(finite(-500.0, 500.0), min_size=9, max_size=9).map(
        lambda v: np.array(v).reshape(3, 3)
    )
)
def test_frame_is_orthonormal_right_handed_and_follows_eq7(pts):
    a, b, c = pts
    g = pts.mean(axis=0)
    ra, rb = a - g, b - g
    sine = np.linalg.norm(np.cross(ra, rb)) / max(np.linalg.norm(ra) * np.linalg.norm(rb), 1e-300)
    if np.linalg.norm(ra) < 1.0 or np.linalg.norm(rb) < 1.0 or sine < 1e-3:
        if sine < 1e-6:
            with pytest.raises(GeometryError, match="collinear|coincide"):
                tob_frame_from_points(a, b, c)
        return  # nearly degenerate: the frame exists but is numerically meaningless
    t = tob_frame_from_points(a, b, c)
    _assert_proper_frame(t)
    np.testing.assert_allclose(t[:3, 3], g, atol=1e-12)  # G is the mean
    w_expected = np.cross(rb, ra)
    np.testing.assert_allclose(t[:3, 2], w_expected / np.linalg.norm(w_expected), atol=1e-9)
    np.testing.assert_allclose(t[:3, 0], -ra / np.linalg.norm(ra), atol=1e-9)  # u = -R_a
    # A on the negative u axis, B on the v > 0 side, all three in the plane w = 0.
    local = transform_points(invert_transform(t), pts)
    np.testing.assert_allclose(local[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(local[0, 1], 0.0, atol=1e-9)
    assert local[0, 0] < 0 and local[1, 1] > 0


def test_frame_is_vectorised():
    rng = np.random.default_rng(5)
    poses = transform_from_x(
        np.column_stack([rng.uniform(-100, 100, (8, 3)), rng.uniform(-170, 170, (8, 3))])
    )
    model = TargetModel()
    pts = transform_points(poses[:, None], model.source_positions_mm)  # (8, 3, 3)
    frames = tob_frame_from_points(pts[:, 0], pts[:, 1], pts[:, 2])
    np.testing.assert_allclose(frames, poses, atol=1e-12)


def test_collinear_and_coincident_points_raise():
    with pytest.raises(GeometryError, match="collinear"):
        tob_frame_from_points([0, 0, 500], [10, 0, 500], [25, 0, 500])
    with pytest.raises(GeometryError, match="coincide"):
        tob_frame_from_points([1, 2, 500], [1, 2, 500], [1, 2, 500])


# --------------------------------------------------------------------- target model


def test_default_model_geometry():
    m = TargetModel()
    np.testing.assert_allclose(m.sides_mm, [40.0, 30.0, 40.0], atol=1e-12)
    np.testing.assert_allclose(m.source_positions_mm.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(m.tob_T_tip, tob_T_tip_on_w_axis(60.0))
    assert m.has_driver and m.source_diameter_mm == 5.0
    assert m == TargetModel.isosceles()
    hash(m)


def test_model_validation_messages():
    with pytest.raises(ValueError, match="equilateral"):
        TargetModel.isosceles(leg_mm=40.0, base_mm=40.0)
    with pytest.raises(ValueError, match="2x the tolerance"):
        TargetModel.isosceles(leg_mm=40.0, base_mm=36.0, side_tolerance_mm=3.0)
    with pytest.raises(ValueError, match="own eq. \\(7\\) frame"):
        pts = isosceles_source_positions_mm(40.0, 30.0) + [1.0, 0.0, 0.0]
        TargetModel(*map(tuple, pts))
    with pytest.raises(ValueError, match="source diameter"):
        TargetModel.isosceles(leg_mm=40.0, base_mm=30.0, source_diameter_mm=35.0)
    with pytest.raises(ValueError, match="no isosceles triangle"):
        TargetModel.isosceles(leg_mm=10.0, base_mm=30.0)
    with pytest.raises(ValueError, match="side_tolerance_mm"):
        TargetModel(side_tolerance_mm=0.0)
    with pytest.raises(ValueError, match="tob_t_tip_mm"):
        TargetModel(tob_t_tip_mm=(0.0, np.nan, 1.0))


def test_model_from_measured_positions_and_without_driver():
    pose = transform_from_x([100.0, -20.0, 30.0, 35.0, -20.0, 70.0])
    ref = TargetModel.isosceles(leg_mm=45.0, base_mm=28.0, driver_length_mm=72.0)
    world_pts = transform_points(pose, ref.source_positions_mm)
    world_tip = transform_points(pose, ref.tob_t_tip_mm)
    built = TargetModel.from_source_positions(*world_pts, world_p_tip_mm=world_tip)
    np.testing.assert_allclose(built.source_positions_mm, ref.source_positions_mm, atol=1e-9)
    np.testing.assert_allclose(built.tob_t_tip_mm, ref.tob_t_tip_mm, atol=1e-9)
    bare = TargetModel.isosceles(driver_length_mm=None)
    assert not bare.has_driver
    with pytest.raises(GeometryError, match="no driver"):
        _ = bare.tob_T_tip
    assert bare.with_tip((1.0, 2.0, 3.0)).tob_t_tip_mm == (1.0, 2.0, 3.0)


# --------------------------------------------------------------------- labelling


@settings(deadline=None, max_examples=80)
@given(model=target_models(), pose=tob_poses(), perm=st.permutations([0, 1, 2]))
def test_labelling_recovers_the_pose_for_any_input_order(model, pose, perm):
    camera_pts = transform_points(pose, model.source_positions_mm)
    shuffled = camera_pts[list(perm)]
    camera_T_tob, lab = estimate_camera_T_tob(model, shuffled)
    np.testing.assert_allclose(camera_T_tob, pose, atol=1e-9)
    np.testing.assert_allclose(lab.camera_p_abc_mm, camera_pts, atol=1e-12)
    assert [perm[i] for i in lab.order] == [0, 1, 2]
    assert lab.side_error_mm < 1e-9
    _assert_proper_frame(camera_T_tob)
    # w points away from the camera (into the underside) ...
    assert np.dot(camera_T_tob[:3, 2], camera_T_tob[:3, 3]) > 0
    # ... so the driver tip is farther from the camera than G.
    tip = tip_pose(camera_T_tob, model.tob_T_tip)[:3, 3]
    assert np.linalg.norm(tip) > np.linalg.norm(camera_T_tob[:3, 3])


def test_labelling_tolerates_noise_within_tolerance():
    model = TargetModel()
    rng = np.random.default_rng(9)
    pose = transform_from_x([20.0, -10.0, 650.0, 120.0, 15.0, -10.0])
    for _ in range(50):
        pts = transform_points(pose, model.source_positions_mm) + rng.normal(0, 0.4, (3, 3))
        order = rng.permutation(3)
        lab = label_sources(model, pts[order])
        assert [int(order[i]) for i in lab.order] == [0, 1, 2]
        assert lab.side_error_mm <= model.side_tolerance_mm


def test_wrong_triangle_raises_with_sides_in_message():
    model = TargetModel()
    other = TargetModel.isosceles(leg_mm=50.0, base_mm=30.0)
    pts = other.source_positions_mm + [0.0, 0.0, 600.0]
    with pytest.raises(GeometryError, match=r"does not match the target.*tolerance 3.0 mm"):
        label_sources(model, pts)
    # The same points pass with a loose enough tolerance.
    assert label_sources(model, pts, side_tolerance_mm=10.5).order == (0, 1, 2)


def test_degenerate_sources_raise():
    model = TargetModel()
    with pytest.raises(GeometryError, match="collinear"):
        label_sources(model, [[0, 0, 600], [20, 0, 600], [40, 0, 600]])
    with pytest.raises(GeometryError, match="coincide"):
        label_sources(model, [[0, 0, 600], [0, 0, 600], [30, 10, 600]])
    edge_on = model.source_positions_mm[:, [2, 1, 0]] + [0.0, 0.0, 600.0]  # plane x = const
    edge_on[:, 0] = 0.0
    edge_on[:, 2] = model.source_positions_mm[:, 0] + 600.0
    with pytest.raises(GeometryError, match="edge-on"):
        label_sources(model, edge_on)
    with pytest.raises(ValueError, match="exactly three"):
        label_sources(model, np.zeros((4, 3)))


def test_tip_on_w_axis_eq9():
    pose = transform_from_x([10.0, 20.0, 700.0, 30.0, 10.0, -5.0])
    tip = tip_pose(pose, tob_T_tip_on_w_axis(55.0))
    np.testing.assert_allclose(tip[:3, :3], pose[:3, :3])  # tob_R_tip = I
    np.testing.assert_allclose(tip[:3, 3], pose[:3, 3] + 55.0 * pose[:3, 2], atol=1e-12)
    assert np.linalg.norm(tip[:3, 3] - pose[:3, 3]) == pytest.approx(55.0)
