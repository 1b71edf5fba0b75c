"""The sim_camera core: truths in, images out at the capture time; bad input is an event."""

from __future__ import annotations

import numpy as np
import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.geometry import (
    DEFAULT_FLANGE_T_CAMERA_MM,
    camera_T_desired,
    transform_from_x,
    x_from_transform,
)
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import (
    from_image,
    from_pose,
    header,
    image_stamp_ns,
    pose,
)
from humanpt.sim_camera import Renderer, SimCameraConfig, SimCameraCore, interpolate_pose


def _truth(t_ns: int, field: str, a_T_b_mm: np.ndarray) -> pb.Truth:
    m = np.array(a_T_b_mm, dtype=float)
    m[:3, 3] /= 1000.0
    msg = pb.Truth(header=header(t_ns, 0, "world"))
    getattr(msg, field).CopyFrom(pose(m))
    return msg


def _tick(t_ns: int) -> pb.Tick:
    return pb.Tick(header=header(t_ns), period_ns=33_333_333)


def test_interpolate_pose_is_linear_and_geodesic_and_caps_extrapolation():
    a = transform_from_x(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    b = transform_from_x(np.array([10.0, -20.0, 30.0, 40.0, 0.0, 0.0]))
    mid = interpolate_pose(50, 0, a, 100, b, 0)
    np.testing.assert_allclose(x_from_transform(mid), [5.0, -10.0, 15.0, 20.0, 0.0, 0.0], atol=1e-9)
    ahead = interpolate_pose(150, 0, a, 100, b, 20)  # only 20 ns of extrapolation allowed
    np.testing.assert_allclose(
        x_from_transform(ahead), [12.0, -24.0, 36.0, 48.0, 0.0, 0.0], atol=1e-9
    )


def test_core_renders_at_the_tick_time_from_interpolated_truth():
    cfg = SimCameraConfig(seed=3)
    core = SimCameraCore(cfg)
    flange = np.eye(4)
    world_T_camera = flange @ DEFAULT_FLANGE_T_CAMERA_MM
    tob_a = world_T_camera @ camera_T_desired(600.0)
    tob_b = (
        world_T_camera @ camera_T_desired(600.0) @ transform_from_x(np.array([20.0, 0, 0, 0, 0, 0]))
    )
    assert core.step(0, "sim_robot/truth", _truth(0, "world_T_flange", flange)) == []
    core.step(0, "operator/truth", _truth(0, "world_T_tob", tob_a))
    core.step(100_000_000, "operator/truth", _truth(100_000_000, "world_T_tob", tob_b))
    outs = core.step(50_000_000, "tick", _tick(50_000_000))
    assert [t for t, _ in outs] == ["camera/image", "sim_camera/truth"]
    img_msg, truth = outs[0][1], outs[1][1]
    assert isinstance(img_msg, RawImage)
    assert (img_msg.encoding, img_msg.width, img_msg.height, img_msg.frame_id) == (
        "mono8",
        640,
        480,
        "camera",
    )
    assert image_stamp_ns(img_msg) == 50_000_000 and truth.header.stamp_ns == 50_000_000
    world_T_tob = from_pose(truth.world_T_tob)
    world_T_tob[:3, 3] *= 1000
    expected = (
        world_T_camera @ camera_T_desired(600.0) @ transform_from_x(np.array([10.0, 0, 0, 0, 0, 0]))
    )
    np.testing.assert_allclose(world_T_tob, expected, atol=1e-9)
    # The image is exactly the renderer's for that pose and frame 0.
    direct = Renderer(cfg).render(np.linalg.inv(world_T_camera) @ expected, world_T_camera, 0)
    np.testing.assert_array_equal(from_image(img_msg), direct)


def test_without_a_flange_pose_there_is_no_image_and_it_says_so_once():
    core = SimCameraCore(SimCameraConfig())
    outs = []
    for i in range(30):
        outs += core.step(i * 33_333_333, "tick", _tick(i * 33_333_333))
    assert [o[1].code for o in outs] == ["waiting_for_truth"]
    # A flange but no target: frames of background only.
    core.step(1_000_000_000, "sim_robot/truth", _truth(1_000_000_000, "world_T_flange", np.eye(4)))
    outs = core.step(1_010_000_000, "tick", _tick(1_010_000_000))
    img = from_image(outs[0][1])
    assert img.max() < 25 and not outs[1][1].HasField("world_T_tob")


def test_bad_truth_is_an_event_and_the_core_lives_on():
    core = SimCameraCore(SimCameraConfig())
    nan_truth = pb.Truth(header=header(5))
    nan_truth.world_T_flange.translation.x = float("nan")
    outs = core.step(5, "sim_robot/truth", nan_truth)
    assert outs[0][0] == "sim_camera/events" and outs[0][1].code == "bad_input"  # every core's input check
    outs = core.step(6, "operator/truth", pb.Truth(header=header(6)))  # world_T_tob missing
    assert outs[0][1].code == "bad_truth" and "world_T_tob is not set" in outs[0][1].text
    core.step(7, "sim_robot/truth", _truth(7, "world_T_flange", np.eye(4)))
    assert core.step(10, "tick", _tick(10))[0][0] == "camera/image"


def test_exposure_is_a_live_parameter():
    core = SimCameraCore(SimCameraConfig(noise=False))
    flange = np.eye(4)
    core.step(0, "sim_robot/truth", _truth(0, "world_T_flange", flange))
    core.step(
        0,
        "operator/truth",
        _truth(0, "world_T_tob", DEFAULT_FLANGE_T_CAMERA_MM @ camera_T_desired(600.0)),
    )
    before = from_image(core.step(1, "tick", _tick(1))[0][1]).max()
    ev = core.step(
        2,
        "param",
        pb.ParamSet(header=header(2), component="sim_camera", key="exposure_ms", value_json="0.5"),
    )
    assert ev[0][1].code == "param_changed"
    after = from_image(core.step(3, "tick", _tick(3))[0][1]).max()
    assert after == pytest.approx(4 + 5 + (before - 14) / 2, abs=1.5)
    bad = core.step(
        4,
        "param",
        pb.ParamSet(header=header(4), component="sim_camera", key="exposure_ms", value_json="-1"),
    )
    assert bad[0][1].code == "param_rejected"


def test_interpolated_pose_turns_at_a_constant_rate_and_extrapolates_a_little():
    """Between two stamped truths the pose moves on the constant-velocity screw: here a
    turn about the world z axis, so the angle and the translation are linear in time (by
    hand), and beyond the last stamp it goes on for max_extra_ns, then holds."""

    def pose_at(angle_rad: float, x_mm: float) -> np.ndarray:
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        return np.array([[c, -s, 0, x_mm], [s, c, 0, 0], [0, 0, 1, 500.0], [0, 0, 0, 1.0]])

    p0, p1 = pose_at(0.2, 10.0), pose_at(0.5, 40.0)  # 0.3 rad and 30 mm in 100 ms
    for t_ms, expected in ((0, (0.2, 10.0)), (25, (0.275, 17.5)), (100, (0.5, 40.0)),
                           (120, (0.56, 46.0)), (500, (0.65, 55.0))):
        got = interpolate_pose(t_ms * 1_000_000, 0, p0, 100_000_000, p1, 50_000_000)
        np.testing.assert_allclose(got, pose_at(*expected), atol=1e-12)
