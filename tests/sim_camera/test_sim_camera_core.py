"""The sim_camera core: truths in, images out stamped with the capture time, rendered only
once the truth is known on both sides of the exposure; bad input is an event; the timing
errors of the world (stamp offset, jitter, frame drops) are seeded and off by default."""

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
from humanpt.geometry.frames import SAMPLE_HOLD_HOLD, SAMPLE_HOLD_REFUSE
from humanpt.geometry.transforms import interpolate_transform
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import (
    from_image,
    from_pose,
    header,
    image_stamp_ns,
    pose,
)
from humanpt.sim_camera import Renderer, SimCameraConfig, SimCameraCore, truth_poses


def _truth(t_ns: int, field: str, a_T_b_mm: np.ndarray) -> pb.Truth:
    m = np.array(a_T_b_mm, dtype=float)
    m[:3, 3] /= 1000.0
    msg = pb.Truth(header=header(t_ns, 0, "world"))
    getattr(msg, field).CopyFrom(pose(m))
    return msg


def _tick(t_ns: int) -> pb.Tick:
    return pb.Tick(header=header(t_ns), period_ns=33_333_333)


def test_pose_track_is_linear_and_geodesic_holds_before_and_never_extrapolates():
    a = transform_from_x(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    b = transform_from_x(np.array([10.0, -20.0, 30.0, 40.0, 0.0, 0.0]))
    track = truth_poses()
    track.add(0, a)
    track.add(100, b)
    mid = track.at(50, SAMPLE_HOLD_REFUSE)
    np.testing.assert_allclose(x_from_transform(mid), [5.0, -10.0, 15.0, 20.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_array_equal(track.at(-30, SAMPLE_HOLD_REFUSE), a)  # before the first sample: it stood there
    np.testing.assert_array_equal(track.at(100, SAMPLE_HOLD_REFUSE), b)
    assert track.at(101, SAMPLE_HOLD_REFUSE) is None and not track.covers(101) and track.covers(100)
    np.testing.assert_array_equal(track.at(150, SAMPLE_HOLD_HOLD), b)
    track.add(100, a)  # a repeat: the newer value wins
    np.testing.assert_array_equal(track.at(100, SAMPLE_HOLD_REFUSE), a)
    track.add(40, b)  # an earlier stamp: a restarted source, the stream starts again
    assert len(track) == 1 and track.last_ns == 40


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
    # The flange's truth ends at 0: the capture at 50 ms waits for it (no extrapolation).
    assert core.step(50_000_000, "tick", _tick(50_000_000)) == []
    outs = core.step(60_000_000, "sim_robot/truth", _truth(60_000_000, "world_T_flange", flange))
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
    core.step(1_010_000_000, "tick", _tick(1_010_000_000))
    outs = core.step(1_028_000_000, "sim_robot/truth", _truth(1_028_000_000, "world_T_flange", np.eye(4)))
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
    core.step(10, "tick", _tick(10))
    assert core.step(10, "sim_robot/truth", _truth(2_000_000, "world_T_flange", np.eye(4)))[0][0] == "camera/image"


def test_exposure_is_a_live_parameter():
    core = SimCameraCore(SimCameraConfig(noise=False))
    flange = np.eye(4)
    core.step(0, "sim_robot/truth", _truth(0, "world_T_flange", flange))
    core.step(0, "sim_robot/truth", _truth(10_000_000, "world_T_flange", flange))
    core.step(
        0,
        "operator/truth",
        _truth(0, "world_T_tob", DEFAULT_FLANGE_T_CAMERA_MM @ camera_T_desired(600.0)),
    )
    core.step(
        0,
        "operator/truth",
        _truth(10_000_000, "world_T_tob", DEFAULT_FLANGE_T_CAMERA_MM @ camera_T_desired(600.0)),
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


def test_pose_track_turns_at_a_constant_rate_between_samples():
    """Between two stamped truths the pose moves on the constant-velocity screw: here a
    turn about the world z axis, so the angle and the translation are linear in time (by
    hand); beyond the last stamp it is unknown (None), before the first it holds."""

    def pose_at(angle_rad: float, x_mm: float) -> np.ndarray:
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        return np.array([[c, -s, 0, x_mm], [s, c, 0, 0], [0, 0, 1, 500.0], [0, 0, 0, 1.0]])

    track = truth_poses()
    track.add(0, pose_at(0.2, 10.0))
    track.add(100_000_000, pose_at(0.5, 40.0))  # 0.3 rad and 30 mm in 100 ms
    track.add(200_000_000, pose_at(0.5, 40.0))  # then still
    for t_ms, expected in ((-5, (0.2, 10.0)), (0, (0.2, 10.0)), (25, (0.275, 17.5)),
                           (100, (0.5, 40.0)), (150, (0.5, 40.0))):
        np.testing.assert_allclose(track.at(t_ms * 1_000_000, SAMPLE_HOLD_REFUSE), pose_at(*expected), atol=1e-12)
    assert track.at(200_000_001, SAMPLE_HOLD_REFUSE) is None
    track.forget_before(150_000_000)  # keeps what times >= 150 ms need
    np.testing.assert_allclose(track.at(150_000_000, SAMPLE_HOLD_REFUSE), pose_at(0.5, 40.0), atol=1e-12)
    assert len(track) == 2


def _feed(core, t_ns, flange=None):
    flange = np.eye(4) if flange is None else flange
    return core.step(t_ns, "sim_robot/truth", _truth(t_ns, "world_T_flange", flange))


def test_a_capture_waits_for_the_end_of_its_exposure_and_keeps_its_stamp():
    """Exposure 2 ms centred on the tick at 50 ms: a flange truth at 50.9 ms does not cover
    its end (51 ms), one at 51 ms does; the image then carries the capture stamp 50 ms."""
    core = SimCameraCore(SimCameraConfig(exposure_ms=2.0))
    _feed(core, 0)
    assert core.step(50_000_000, "tick", _tick(50_000_000)) == []
    assert _feed(core, 50_900_000) == []
    outs = _feed(core, 51_000_000)
    assert [t for t, _ in outs] == ["camera/image", "sim_camera/truth"]
    assert image_stamp_ns(outs[0][1]) == 50_000_000 and outs[1][1].header.stamp_ns == 50_000_000


def test_truth_that_never_comes_drops_the_capture_with_an_event_and_the_queue_stays_bounded():
    core = SimCameraCore(SimCameraConfig(max_truth_wait_ms=100.0))
    _feed(core, 0)
    events = []
    for i in range(1, 301):  # 10 s of ticks, the robot's truth stopped at 0
        outs = core.step(i * 33_333_333, "tick", _tick(i * 33_333_333))
        assert all(t == "sim_camera/events" for t, _ in outs)
        events += [m for _, m in outs]
        assert len(core.pending) <= 4  # 100 ms of waiting at 30 frames/s (+ the new one)
    assert {e.code for e in events} == {"truth_late"}
    assert len(events) == 3  # the 1st, 10th and 100th drop, not one per frame
    assert "100 ms" in events[0].text
    # Still waiting: the captures within 100 ms + half the exposure of the last tick (4).
    assert len(core.pending) == 4 and core.counts["truth_late"] == 300 - 4


def _timing_core(**kw):
    core = SimCameraCore(SimCameraConfig(noise=False, **kw))
    stamps, n = [], 2000
    for i in range(n):
        t = i * 10_000_000
        core.step(t, "tick", _tick(t))
        outs = _feed(core, t + 5_000_000)
        stamps += [(t, image_stamp_ns(m)) for topic, m in outs if topic == "camera/image"]
        assert [m.header.stamp_ns for topic, m in outs if topic == "sim_camera/truth"] in ([], [t])
    return stamps, n


def test_timing_errors_are_off_by_default():
    stamps, n = _timing_core()
    assert len(stamps) == n and all(a == b for a, b in stamps)


def test_stamp_offset_and_jitter_shift_the_image_stamp_only():
    """An offset of 3 ms and a jitter of 0.5 ms SD: the stamps' error has mean 3 ms and SD
    0.5 ms (within 4 standard errors over 2000 frames); the truth stays at the capture."""
    stamps, n = _timing_core(stamp_offset_ms=3.0, stamp_jitter_ms=0.5)
    err_ms = np.array([(s - t) / 1e6 for t, s in stamps])
    assert len(err_ms) == n
    assert abs(err_ms.mean() - 3.0) < 4 * 0.5 / np.sqrt(n)
    assert abs(err_ms.std(ddof=1) - 0.5) < 4 * 0.5 / np.sqrt(2 * (n - 1))
    again, _ = _timing_core(stamp_offset_ms=3.0, stamp_jitter_ms=0.5)
    assert again == stamps  # seeded per frame
    exact, _ = _timing_core(stamp_offset_ms=-2.5)
    assert exact[0] == (0, 0)  # a stamp never goes below 0
    assert all(s - t == -2_500_000 for t, s in exact[1:])


def test_frames_are_dropped_with_the_given_probability():
    stamps, n = _timing_core(frame_drop_probability=0.1)
    kept = len(stamps)
    # Binomial(2000, 0.9): SD = sqrt(2000 * 0.9 * 0.1) = 13.4 frames
    assert abs(kept - 0.9 * n) < 4 * np.sqrt(n * 0.9 * 0.1)
    assert [t for t, _ in stamps] == sorted({t for t, _ in stamps})  # the rest on time


def test_the_image_is_rendered_from_the_truth_interpolated_at_its_stamp_while_accelerating():
    """A flange that accelerates (x = a t^2 / 2 sampled every 28 ms, turning faster and
    faster): the pose each image was rendered from equals the robot's truth interpolated
    (linear, geodesic) between the samples around the capture stamp - to 1e-9 mm - and is
    never what the last two samples before the capture extrapolate to."""
    core = SimCameraCore(SimCameraConfig(noise=False))
    accel_mm_s2 = 2000.0

    def flange_at(t_s: float) -> np.ndarray:
        return transform_from_x(np.array([0.5 * accel_mm_s2 * t_s**2, 0.0, 0.0, 30.0 * t_s**2, 0.0, 0.0]))

    samples, rendered = [], []
    cam_t, cycle_t = 0, 0
    while cycle_t <= 1_000_000_000:
        while cam_t <= cycle_t:  # ticks before the next robot sample at equal times first
            core.step(cam_t, "tick", _tick(cam_t))
            cam_t += 33_333_333
        samples.append((cycle_t, flange_at(cycle_t / 1e9)))
        for topic, m in _feed(core, cycle_t, samples[-1][1]):
            if topic == "sim_camera/truth":
                T = from_pose(m.world_T_flange)
                T[:3, 3] *= 1000
                rendered.append((m.header.stamp_ns, T))
        cycle_t += 28_000_000
    assert len(rendered) >= 29
    stamps = [t for t, _ in samples]
    moved_off = 0
    for stamp, T in rendered:
        i = int(np.searchsorted(stamps, stamp, side="right"))  # first sample after the stamp
        i = min(i, len(stamps) - 1)
        (t0, T0), (t1, T1) = samples[i - 1], samples[i]
        expected = T1 if stamp == t1 else interpolate_transform(T0, T1, (stamp - t0) / (t1 - t0))
        np.testing.assert_allclose(T[:3, 3], expected[:3, 3], atol=1e-9)
        np.testing.assert_allclose(T[:3, :3], expected[:3, :3], atol=1e-12)
        if i >= 2 and stamp > t0:
            (tp, Tp) = samples[i - 2]
            extrapolated = interpolate_transform(Tp, T0, (stamp - tp) / (t0 - tp))
            moved_off += np.linalg.norm(extrapolated[:3, 3] - T[:3, 3]) > 1e-3
    assert moved_off >= 20  # the test can tell an extrapolation from the truth


def test_motion_blur_hands_the_renderer_the_poses_at_the_start_and_end_of_the_exposure():
    """With ``motion_blur`` the core renders the exposure from the poses at its start and
    end (the renderer integrates between them)."""
    cfg = SimCameraConfig(noise=False, exposure_ms=20.0, motion_blur=True)
    core = SimCameraCore(cfg)
    flange0 = np.eye(4)
    flange1 = transform_from_x(np.array([20.0, 0, 0, 0, 0, 0]))  # 20 mm in 100 ms
    tob = DEFAULT_FLANGE_T_CAMERA_MM @ camera_T_desired(600.0)
    core.step(0, "operator/truth", _truth(0, "world_T_tob", tob))
    core.step(0, "operator/truth", _truth(100_000_000, "world_T_tob", tob))
    _feed(core, 0, flange0)
    core.step(50_000_000, "tick", _tick(50_000_000))
    outs = _feed(core, 100_000_000, flange1)
    # The exposure runs 40..60 ms: the flange from x = 8 to 12 mm (by hand).
    start = transform_from_x(np.array([8.0, 0, 0, 0, 0, 0])) @ DEFAULT_FLANGE_T_CAMERA_MM
    end = transform_from_x(np.array([12.0, 0, 0, 0, 0, 0])) @ DEFAULT_FLANGE_T_CAMERA_MM
    direct = Renderer(cfg).render(np.linalg.inv(start) @ tob, start, 0, np.linalg.inv(end) @ tob, end)
    np.testing.assert_array_equal(from_image(outs[0][1]), direct)
    truth = from_pose(outs[1][1].world_T_flange)
    np.testing.assert_allclose(truth[:3, 3] * 1000, [10.0, 0, 0], atol=1e-9)  # mid-exposure


def _covered_image(cover_fraction, cover_angle_rad):
    """The image of the target at D with the operator's truth carrying a cover."""
    core = SimCameraCore(SimCameraConfig(noise=False))
    flange = np.eye(4)
    tob = flange @ DEFAULT_FLANGE_T_CAMERA_MM @ camera_T_desired(600.0)
    core.step(0, "sim_robot/truth", _truth(0, "world_T_flange", flange))
    msg = _truth(0, "world_T_tob", tob)
    msg.cover_fraction.extend(cover_fraction)
    msg.cover_angle_rad.extend(cover_angle_rad)
    assert core.step(0, "operator/truth", msg) == []
    core.step(10_000_000, "tick", _tick(10_000_000))
    core.step(20_000_000, "operator/truth", _truth(20_000_000, "world_T_tob", tob))  # the cover ends
    outs = core.step(20_000_000, "sim_robot/truth", _truth(20_000_000, "world_T_flange", flange))
    assert outs[0][0] == "camera/image" and list(outs[1][1].cover_fraction) == list(cover_fraction)
    core.step(40_000_000, "tick", _tick(40_000_000))
    core.step(50_000_000, "operator/truth", _truth(50_000_000, "world_T_tob", tob))
    later = core.step(50_000_000, "sim_robot/truth", _truth(50_000_000, "world_T_flange", flange))
    return from_image(outs[0][1]), from_image(later[0][1]), np.linalg.inv(DEFAULT_FLANGE_T_CAMERA_MM) @ tob


@pytest.mark.parametrize("source, fraction, angle_deg", [(1, 1.0, 0.0), (0, 0.3, 90.0)])
def test_the_operators_cover_renders_as_the_configured_occlusion_for_its_time(source, fraction, angle_deg):
    cover = [0.0, 0.0, 0.0]
    cover[source] = fraction
    angles = [0.0, 0.0, 0.0]
    angles[source] = np.radians(angle_deg)
    covered, after, camera_T_tob = _covered_image(cover, angles)
    # The same scene with the static occlusion of the config (sim_camera's own, older path).
    static = SimCameraConfig(noise=False, occluded_sources=(source,), occlusion_fraction=fraction,
                             occlusion_angle_deg=angle_deg)
    np.testing.assert_array_equal(covered, Renderer(static).render(camera_T_tob, DEFAULT_FLANGE_T_CAMERA_MM, 0))
    # Once the truth's cover is gone, the uncovered target again.
    plain = Renderer(SimCameraConfig(noise=False)).render(camera_T_tob, DEFAULT_FLANGE_T_CAMERA_MM, 0)
    np.testing.assert_array_equal(after, plain)
    assert not np.array_equal(covered, plain)


def test_a_bad_cover_is_an_event_and_the_pose_is_still_used():
    core = SimCameraCore(SimCameraConfig(noise=False))
    msg = _truth(0, "world_T_tob", np.eye(4))
    msg.cover_fraction.extend([0.0, 1.5, 0.0])
    msg.cover_angle_rad.extend([0.0, 0.0, 0.0])
    outs = core.step(0, "operator/truth", msg)
    assert outs[0][1].code == "bad_truth" and "3 fractions in [0, 1]" in outs[0][1].text
    assert not core.covers
