"""Perception on an ordinary stereo pair (issue 35 item 3): the target's three sources
drawn into each camera's image where OpenCV's projectPoints puts them (each camera's own
intrinsics and distortion; the left camera 90 mm to the left, turned 2 deg towards the
right one), and measured back. Expected: the pose the sources were drawn at (its
accuracy bound: a few hundredths of a px of centroid error at 600 mm with a 90 mm
baseline is well under 0.5 mm and 0.5 deg)."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.geometry.rig import Rig, Stereo, StereoCamera
from humanpt.geometry.target import TargetModel
from humanpt.geometry.transforms import (
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    transform_points,
)
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.stereo import StereoPerception, _project

STEREO = Stereo(
    left=StereoCamera(a_u=1010.0, a_v=1008.0, u0=322.0, v0=238.0, dist_coeffs=(-0.08, 0.05, 0.0, 0.0, 0.0)),
    right=StereoCamera(a_u=995.0, a_v=996.0, u0=317.0, v0=243.0, dist_coeffs=(-0.05, 0.02, 0.0, 0.0, 0.0)),
    right_T_left_x=(-90.0, 0.5, 1.0, 0.0, -2.0, 0.3))
RIG = Rig(kind="stereo", stereo=STEREO)


def _image(cam: StereoCamera, cam_T_right: np.ndarray, p_mm: np.ndarray, model: TargetModel,
           rng: np.random.Generator) -> np.ndarray:
    """Dark noisy image with each source a Gaussian spot of its projected size."""
    h, w = STEREO.image_height_px, STEREO.image_width_px
    img = rng.normal(12.0, 1.5, (h, w))
    uv = _project(cam, cam_T_right, p_mm)
    depth = transform_points(cam_T_right, p_mm)[:, 2]
    v, u = np.mgrid[0:h, 0:w]
    for (uc, vc), z in zip(uv, depth, strict=True):
        sigma = 0.35 * cam.a_u * model.source_diameter_mm / z
        img += 200.0 * np.exp(-((u - uc) ** 2 + (v - vc) ** 2) / (2 * sigma**2))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _pair(right_T_tob: np.ndarray, seed: int = 0):
    model = RIG.target_model()
    p_mm = transform_points(right_T_tob, model.source_positions_mm)
    rng = np.random.default_rng(seed)
    left_T_right = invert_transform(STEREO.right_T_left_mm())
    return (_image(STEREO.left, left_T_right, p_mm, model, rng), _image(STEREO.right, np.eye(4), p_mm, model, rng))


@pytest.mark.parametrize("x_mm, turn_deg", [((0, 0, 600), (0, 0, 0)), ((-30, -30, 520), (15, -10, 30)),
                                            ((-60, 25, 750), (-20, 12, -80))])
def test_the_target_is_measured_where_it_was_drawn(x_mm, turn_deg):
    truth = make_transform(matrix_from_rotvec(np.radians(turn_deg)), np.array(x_mm, float))
    m = StereoPerception(PerceptionConfig(), RIG).measure(*_pair(truth))
    assert m.status == "full", m.why
    d = invert_transform(truth) @ m.camera_T_tob_mm
    angle = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)))
    assert np.linalg.norm(d[:3, 3]) < 0.5 and angle < 0.5, (np.linalg.norm(d[:3, 3]), angle)
    assert m.reprojection_px < 0.3 and m.side_error_mm < 0.5


def test_a_source_missing_in_one_image_is_lost_with_the_reason():
    truth = make_transform(np.eye(3), np.array([0.0, 0.0, 600.0]))
    left, right = _pair(truth)
    right[:, :] = right.min()  # the right camera sees nothing
    m = StereoPerception(PerceptionConfig(), RIG).measure(left, right)
    assert m.status == "lost" and "0 in the right" in m.why
    with pytest.raises(ValueError, match="give 640 x 480 px"):
        StereoPerception(PerceptionConfig(), RIG).measure(left[:400], right)


def test_the_component_measures_a_side_by_side_pair_and_publishes_it_as_the_psvss():
    from humanpt.perception.core import PerceptionCore
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import from_pose, image

    truth = make_transform(matrix_from_rotvec(np.radians((10, -5, 20))), np.array([-20.0, 10.0, 620.0]))
    left, right = _pair(truth)
    core = PerceptionCore(PerceptionConfig(), RIG)
    outs = core.step(1, "camera/image", image(np.hstack([left, right]), 1000, "camera", "mono8"))
    (m,) = [msg for topic, msg in outs if topic == "perception/tob"]
    assert m.status == pb.TOB_STATUS_FULL and m.visible == 3 and m.header.stamp_ns == 1000
    measured = from_pose(m.camera_T_tob)
    measured[:3, 3] *= 1e3
    assert np.linalg.norm(measured[:3, 3] - truth[:3, 3]) < 0.5
    # the pairs index the centres: the right camera's are in the image's right half
    for pair in m.pairs:
        assert m.centers_px[pair.right].u >= STEREO.image_width_px > m.centers_px[pair.left].u
    # a lone camera's image (not side by side) is refused by its size, the target lost
    outs = core.step(2, "camera/image", image(left, 2000, "camera", "mono8"))
    codes = [msg.code for topic, msg in outs if topic == "perception/events"]
    (lost_m,) = [msg for topic, msg in outs if topic == "perception/tob"]
    assert "wrong_size" in codes and lost_m.status == pb.TOB_STATUS_LOST


def test_clutter_does_not_blow_up_the_correspondence():
    # 15 extra bright spots in each image (24 blobs would once mean 2024 x 12144 trios): the
    # target is still found, and the pairs tried are bounded (MAX_PAIRS)
    truth = make_transform(np.eye(3), np.array([10.0, -5.0, 600.0]))
    left, right = _pair(truth)
    rng = np.random.default_rng(3)
    v, u = np.mgrid[0:480, 0:640]
    for img in (left, right):
        for uc, vc in zip(rng.uniform(20, 620, 15), rng.uniform(20, 120, 15), strict=True):  # above the target
            img[:] = np.maximum(img, np.clip(180 * np.exp(-((u - uc) ** 2 + (v - vc) ** 2) / 8.0), 0, 255)
                                .astype(np.uint8))
    m = StereoPerception(PerceptionConfig(), RIG).measure(left, right)
    assert m.status == "full", m.why
    assert np.linalg.norm(m.camera_T_tob_mm[:3, 3] - truth[:3, 3]) < 0.5
