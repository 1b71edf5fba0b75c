"""The perception core: messages in and out, bad images, run-time parameters, the region of
interest, config from TOML, lock-step determinism and replay."""

from __future__ import annotations

import numpy as np
import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from humanpt.geometry import TargetModel, transform_points
from humanpt.perception import PerceptionConfig, PerceptionCore
from humanpt.runtime.config import ConfigError, build, from_dict, to_table
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.registry import config_types, core_class
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, from_vector3, image
from tests.perception.drawing import pose, scene

T = pose([10, -5, 610, 5, 12, -8])
IMG, UV_R, UV_L = scene(T, seed=11)


def _tobs(outputs):
    return [m for t, m in outputs if t == "perception/tob"]


def _events(outputs):
    return [m for t, m in outputs if t == "perception/events"]


def _param(core, t_ns, key, value_json):
    return core.step(
        t_ns, "param", pb.ParamSet(component="perception", key=key, value_json=value_json)
    )


def test_a_measurement_message_in_metres_with_the_capture_stamp():
    core = PerceptionCore(PerceptionConfig())
    outs = core.step(2_000, "camera/image", image(IMG, 1_234_567))
    (m,) = _tobs(outs)
    assert m.header.stamp_ns == 1_234_567 and m.header.frame_id == "camera" and m.header.seq == 0
    assert m.status == pb.TOB_STATUS_FULL and m.visible == 3 and len(m.pairs) == 3
    assert m.method == pb.PERCEPTION_METHOD_WEIGHTED and 0.0 < m.quality <= 1.0
    assert m.processing_s == 0.0  # the core never reads the clock
    assert len(m.centers_px) == 6
    centres = np.array([[c.u, c.v] for c in m.centers_px])
    for k, pair in enumerate(m.pairs):  # ordered A, B, C
        assert np.abs(centres[pair.right] - UV_R[k]).max() < 0.05
        assert np.abs(centres[pair.left] - UV_L[k]).max() < 0.05
        assert pair.residual_px < 0.1
    truth_m = transform_points(T, TargetModel.isosceles().source_positions_mm) / 1000.0
    points = np.array([from_vector3(p) for p in m.points_camera_m])
    assert np.abs(points - truth_m).max() < 2e-4
    camera_T_tob = from_pose(m.camera_T_tob)
    assert np.abs(camera_T_tob[:3, 3] - T[:3, 3] / 1000.0).max() < 2e-4
    assert np.abs(camera_T_tob[:3, :3] - T[:3, :3]).max() < 0.01
    (ev,) = _events(outs)
    assert ev.code == "tob_status" and "full" in ev.text


@pytest.mark.parametrize(
    ("msg", "code"),
    [
        (RawImage(), "bad_image"),  # empty
        (
            RawImage(width=640, height=480, encoding="yuv422", step=1280, data=b"\0" * 614400),
            "bad_image",
        ),
        (
            RawImage(width=640, height=480, encoding="mono8", step=640, data=b"\0" * 1000),
            "bad_image",
        ),
        (image(np.zeros((240, 320), np.uint8), 5), "wrong_size"),
        (image(np.full((480, 640), 255, np.uint8), 5), "saturated"),
        (pb.Event(code="not an image"), "bad_image"),
    ],
)
def test_bad_images_give_lost_and_one_warning_per_run_never_an_exception(msg, code):
    core = PerceptionCore(PerceptionConfig())
    outs = core.step(10, "camera/image", msg)
    assert [m.status for m in _tobs(outs)] == [pb.TOB_STATUS_LOST]
    assert [(e.code, e.severity) for e in _events(outs)][0] == (code, pb.SEVERITY_WARNING)
    outs = core.step(20, "camera/image", msg)  # the same trouble again: no new warning
    assert [m.status for m in _tobs(outs)] == [pb.TOB_STATUS_LOST] and not _events(outs)
    outs = core.step(30, "camera/image", image(IMG, 30))
    assert _tobs(outs)[0].status == pb.TOB_STATUS_FULL
    assert [e.code for e in _events(outs)] == ["image_ok", "tob_status"]
    assert core.counters["bad_images"] == 2


def test_other_encodings_are_measured_too():
    core = PerceptionCore(PerceptionConfig())
    rgb = np.repeat(IMG[:, :, None], 3, axis=2)
    mono16 = IMG.astype(np.uint16) * 257
    for msg in (image(rgb, 1), image(rgb, 2, encoding="bgr8"), image(mono16, 3)):
        (m,) = _tobs(core.step(1, "camera/image", msg))
        assert m.status == pb.TOB_STATUS_FULL


def test_an_unexpected_error_while_measuring_is_an_event_not_an_exception(monkeypatch):
    core = PerceptionCore(PerceptionConfig())

    def boom(*a, **k):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(core.perception, "measure", boom)
    outs = core.step(5, "camera/image", image(IMG, 5))
    assert _tobs(outs)[0].status == pb.TOB_STATUS_LOST
    assert any(e.code == "perception_error" and "kaboom" in e.text for e in _events(outs))


def test_parameters_change_at_run_time_through_param_inputs():
    core = PerceptionCore(PerceptionConfig())
    assert _tobs(core.step(1, "camera/image", image(IMG, 1)))[0].status == pb.TOB_STATUS_FULL
    # method
    outs = _param(core, 2, "method", '"paper"')
    assert _events(outs)[0].code == "param_changed"
    (m,) = _tobs(core.step(3, "camera/image", image(IMG, 3)))
    assert m.method == pb.PERCEPTION_METHOD_PAPER and m.status == pb.TOB_STATUS_FULL
    # threshold above the sources: nothing is found
    _param(core, 4, "threshold", "240")
    assert _tobs(core.step(5, "camera/image", image(IMG, 5)))[0].status == pb.TOB_STATUS_LOST
    _param(core, 6, "threshold", "60")
    _param(core, 7, "method", '"weighted"')
    # a mask over the whole target
    u0, v0 = np.floor(np.minimum(UV_R.min(0), UV_L.min(0))).astype(int) - 10
    u1, v1 = np.ceil(np.maximum(UV_R.max(0), UV_L.max(0))).astype(int) + 10
    _param(core, 8, "mask", f"[[{u0}, {v0}, {u1 - u0}, {v1 - v0}]]")
    assert _tobs(core.step(9, "camera/image", image(IMG, 9)))[0].status == pb.TOB_STATUS_LOST
    _param(core, 10, "mask", "[]")
    assert _tobs(core.step(11, "camera/image", image(IMG, 11)))[0].status == pb.TOB_STATUS_FULL
    # inversion: a negative image is measured only with invert = true
    negative = image(255 - IMG, 12)
    assert _tobs(core.step(12, "camera/image", negative))[0].status == pb.TOB_STATUS_LOST
    _param(core, 13, "invert", "true")
    assert _tobs(core.step(14, "camera/image", negative))[0].status == pb.TOB_STATUS_FULL
    # bad values are rejected with an event, the old value stays
    for key, value in (
        ("threshold", "300"),
        ("method", '"magic"'),
        ("mask", "[[1, 2, 3]]"),
        ("roi_margin_px", "10"),
    ):
        (ev,) = _events(_param(core, 15, key, value))
        assert ev.code == "param_rejected"
    assert core.params() == {
        "method": "weighted",
        "threshold": 60.0,
        "invert": True,
        "mask": [],
        "track_roi": True,
        "check_blobs": True,
        "degraded_policy": "rebuild",
        "degraded_flux_tol": 0.05,
        "degraded_view_tol": 0.05,
        "degraded_shape_tol": 0.15,
        "degraded_noise_k": 5.0,
        "degraded_paper_factor": 3.5,
    }


def test_tracking_searches_a_region_of_interest_and_falls_back_to_the_full_image():
    core = PerceptionCore(PerceptionConfig())
    for k in range(5):
        img, _, _ = scene(pose([10 + k, -5, 610, 5, 12, -8]), seed=k)
        assert _tobs(core.step(k, "camera/image", image(img, k)))[0].status == pb.TOB_STATUS_FULL
    assert core.counters["full_searches"] == 1 and core.counters["roi_hits"] == 4
    # the target jumps out of the region: found again by a full search in the same step
    img, _, _ = scene(pose([-150, 100, 900, 0, 0, 0]), seed=9)
    assert _tobs(core.step(9, "camera/image", image(img, 9)))[0].status == pb.TOB_STATUS_FULL
    assert core.counters["full_searches"] == 2
    _param(core, 10, "track_roi", "false")
    core.step(11, "camera/image", image(img, 11))
    assert core.counters["full_searches"] == 3


def test_config_from_toml_validates_and_round_trips():
    assert core_class("perception") is PerceptionCore
    assert config_types()["perception"] is PerceptionConfig
    cfg = from_dict(
        {
            "perception": {
                "method": "paper",
                "threshold": 80,
                "mask": [[0, 0, 10, 10]],
            }
        },
        "test.toml",
    )
    c = cfg.component("perception", PerceptionConfig)
    assert c.method == "paper" and c.threshold == 80.0 and c.mask == ((0, 0, 10, 10),)
    assert build(PerceptionConfig, to_table(c), source="t", section="perception") == c
    for bad in (
        {"threshold": -1},
        {"method": "best"},
        {"mask": [[0, 0, 0, 5]]},
        {"min_depth_mm": 5000},
        {"paper_cross_px": [8]},
        {"psvs": {"baseline_mm": 95.0}},  # the PSVS is the rig's, not perception's
    ):
        with pytest.raises(ConfigError):
            from_dict({"perception": bad}, "test.toml", config_types())


def _lockstep_run(run_dir=None):
    """Images of a target moving across the view, with a method switch, a mask and a bad
    image on the way."""
    core = PerceptionCore(PerceptionConfig())
    with Lockstep([core], run_dir=run_dir) as ls:
        for k in range(12):
            t = (k + 1) * 33_000_000
            if k == 7:
                msg = image(np.zeros((10, 10), np.uint8), t)
            else:
                img, _, _ = scene(pose([-30 + 6 * k, 4 * k, 600 + 5 * k, 10, 3 * k, 0]), seed=k)
                msg = image(img, t)
            ls.inject(t, "perception", "camera/image", msg)
        ls.set_param(100_000_000, "perception", "method", '"paper"')
        ls.set_param(200_000_000, "perception", "method", '"weighted"')
        ls.set_param(250_000_000, "perception", "mask", "[[0, 0, 50, 50]]")
        ls.run_until(1_000_000_000)
    return ls


def test_lockstep_runs_are_identical_and_replay_exactly(tmp_path):
    a = _lockstep_run(tmp_path)
    b = _lockstep_run()
    assert a.digest() == b.digest()
    tobs = [pb.TobMeasurement.FromString(o.data) for o in a.outputs if o.topic == "perception/tob"]
    assert len(tobs) == 12
    assert [m.status for m in tobs].count(pb.TOB_STATUS_FULL) == 11
    assert {m.method for m in tobs} == {pb.PERCEPTION_METHOD_PAPER, pb.PERCEPTION_METHOD_WEIGHTED}
    result = replay(tmp_path / "perception.mcap")
    assert result.match, result.report()
    assert result.replayed_outputs == result.recorded_outputs > 12


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    width=st.integers(0, 700),
    height=st.integers(0, 500),
    encoding=st.sampled_from(["mono8", "mono16", "rgb8", "bgr8", "yuv422", ""]),
    step_extra=st.integers(-2, 3),
    data_len=st.one_of(st.none(), st.integers(0, 2000)),
)
def test_fuzzed_raw_images_never_raise(width, height, encoding, step_extra, data_len):
    channels = {"mono16": 2, "rgb8": 3, "bgr8": 3}.get(encoding, 1)
    step = max(width * channels + step_extra, 0)
    n = step * height if data_len is None else data_len
    msg = RawImage(
        width=width,
        height=height,
        encoding=encoding,
        step=step,
        data=bytes(i % 5 for i in range(n)),
    )
    outs = PerceptionCore(PerceptionConfig()).step(1, "camera/image", msg)
    (m,) = _tobs(outs)
    assert m.status == pb.TOB_STATUS_LOST


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31),
    method=st.sampled_from(["weighted", "paper"]),
    level=st.integers(0, 255),
)
def test_random_pictures_never_raise(seed, method, level):
    rng = np.random.default_rng(seed)
    img = np.full((480, 640), level, np.uint8)
    for _ in range(int(rng.integers(0, 40))):  # random bright and dark rectangles and spots
        u, v = int(rng.integers(0, 640)), int(rng.integers(0, 480))
        img[v : v + int(rng.integers(1, 60)), u : u + int(rng.integers(1, 60))] = int(
            rng.integers(0, 256)
        )
    img = np.clip(img + rng.normal(0, rng.uniform(0, 30), img.shape), 0, 255).astype(np.uint8)
    core = PerceptionCore(PerceptionConfig(method=method))
    for k in range(2):
        (m,) = _tobs(core.step(k, "camera/image", image(img, k)))
        assert m.status in (pb.TOB_STATUS_FULL, pb.TOB_STATUS_POSITION_ONLY, pb.TOB_STATUS_LOST)
        assert 0.0 <= m.quality <= 1.0 and m.visible == len(m.pairs) == len(m.points_camera_m)


def test_saturated_blobs_are_counted_and_reported_once_per_episode():
    """Sources drawn 3x brighter than full scale clip at 255 over their cores: each blob's
    count of full-scale aperture pixels equals the image's own count of 255-pixels around
    the blob's drawn centre (numpy on the image, independent of the detector); the core
    warns once (``blob_saturated``), counts every such paired blob, and says
    ``blob_saturated_ok`` on the first unsaturated measurement. The unsaturated image of
    the other tests has no such pixel, no event."""
    bright, uv_r, uv_l = scene(T, seed=11, amplitude_dn=(600.0, 560.0))
    core = PerceptionCore(PerceptionConfig())
    blobs = core.perception.measure(bright).blobs
    v, u = np.nonzero(bright == 255)
    for centre in np.vstack([uv_r, uv_l]):
        (k,) = np.flatnonzero(np.hypot(*(blobs.uv_px - centre).T) < 0.5)  # this blob
        expected = int(np.count_nonzero(np.hypot(u - centre[0], v - centre[1]) < 8.0))
        assert expected > 3 and blobs.saturated_px[k] == expected
    assert not core.perception.measure(IMG).blobs.saturated_px.any()

    codes = []
    for k, img in enumerate((bright, bright, IMG, IMG)):
        outs = core.step(k * 1000, "camera/image", image(img, k + 1))
        assert _tobs(outs)[0].status == pb.TOB_STATUS_FULL
        codes.append([e.code for e in _events(outs) if e.code.startswith("blob_saturated")])
    assert codes == [["blob_saturated"], [], ["blob_saturated_ok"], []]
    assert core.counters["saturated_blobs"] == 12  # six paired blobs in each bright image
    # the limit: more than saturated_blob_px pixels at 255
    high = PerceptionCore(PerceptionConfig(saturated_blob_px=int(blobs.saturated_px.max())))
    assert not any(e.code == "blob_saturated" for e in _events(high.step(0, "camera/image", image(bright, 1))))
    assert high.counters["saturated_blobs"] == 0
    with pytest.raises(ValueError, match="saturated_blob_px"):
        PerceptionConfig(saturated_blob_px=-1)
