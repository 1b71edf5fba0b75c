"""The GenICam camera source (issue 35 item 2) against a real GenTL producer: genicam's
``viky.cti``, a simulated device producer (three cameras VikyTL_DEV_red/green/blue, 400 x 400
px RGBa8 by default, Mono8 on request; Width 100..800, AcquisitionFrameRate 1..200 per its
node map; its buffers carry no timestamp), driven by harvesters as a real camera's producer
is. Frames, settings, errors, a stall and a size change mid-run, the live component on a
real router and its recording replaying.

Expected values: viky's node map (its ranges, its pixel formats), hand-made pixels and
hand-computed clock offsets for the pure parts."""

from __future__ import annotations

import itertools
import os
import sys
import threading

import genicam  # (the producer ships in its wheel)
import harvesters.core  # noqa: F401  (the [genicam] extra is in [test]: a broken install fails, not skips)
import numpy as np
import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.camera import CameraConfig, CameraCore, CaptureAdapter
from humanpt.camera.capture import capture_adapters, capture_message, open_capture, read_frames
from humanpt.camera.genicam import DeviceClockMap, device_time_ns, frame_from_buffer
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.live import LiveShell
from humanpt.runtime.recording import read
from humanpt.runtime.replay import replay
from humanpt.schemas.convert import from_image, image_stamp_ns
from tests.conftest import wait_for, write_config, zenoh_client

VIKY = os.path.join(os.path.dirname(genicam.__file__), "viky.cti")


def _source(device: str = "") -> str:
    return f"genicam:{VIKY}" + (f"#{device}" if device else "")


# --- the pure parts: pixels and the camera's clock ---


def test_pixel_formats_become_opencv_frames_and_others_are_refused_by_name():
    rgba = np.array([10, 20, 30, 255, 200, 100, 0, 255], np.uint8)  # two pixels, 2 x 1
    bgr = frame_from_buffer(rgba, 2, 1, "RGBa8")
    assert bgr.shape == (1, 2, 3) and bgr.tolist() == [[[30, 20, 10], [0, 100, 200]]]
    bgra = np.array([30, 20, 10, 255, 0, 100, 200, 255], np.uint8)
    assert frame_from_buffer(bgra, 2, 1, "BGRa8").tolist() == bgr.tolist()
    assert frame_from_buffer(np.array([10, 20, 30, 200, 100, 0], np.uint8), 2, 1, "RGB8").tolist() == bgr.tolist()
    assert frame_from_buffer(np.array([30, 20, 10, 0, 100, 200], np.uint8), 2, 1, "BGR8").tolist() == bgr.tolist()
    mono = frame_from_buffer(np.arange(6, dtype=np.uint8), 3, 2, "Mono8")
    assert mono.shape == (2, 3) and mono.tolist() == [[0, 1, 2], [3, 4, 5]]
    with pytest.raises(OSError, match="pixel format 'BayerRG8'"):
        frame_from_buffer(np.zeros(6, np.uint8), 3, 2, "BayerRG8")
    with pytest.raises(ValueError, match="needs 24"):
        frame_from_buffer(np.zeros(20, np.uint8), 3, 2, "RGBa8")
    # the core turns the BGR frame to mono8 as it does OpenCV's: 0.299 R + 0.587 G + 0.114 B
    ((_, msg),) = CameraCore(CameraConfig(source=_source())).step(1, "capture", capture_message(bgr, 5))
    # (118.5 for the second: OpenCV's fixed point rounds it either way; 1 grey level)
    assert msg.encoding == "mono8"
    np.testing.assert_allclose(from_image(msg)[0], [0.299 * 10 + 0.587 * 20 + 0.114 * 30, 0.299 * 200 + 0.587 * 100],
                               atol=1.0)


def test_a_cameras_clock_is_mapped_by_its_quickest_transfer_and_follows_a_reset():
    ms = 1_000_000
    m = DeviceClockMap(window_ns=100 * ms)
    # device times 0, 33, 66 ms arriving 5, 3, 9 ms later at host 1000 ms + ...: the offset is
    # the smallest (host - device) so far: 1005, then 1003 ms
    assert m.to_shared(0, 1005 * ms) == 1005 * ms
    assert m.to_shared(33 * ms, 1036 * ms) == 1036 * ms  # 33 + 1003
    assert m.to_shared(66 * ms, 1075 * ms) == 1069 * ms  # 66 + 1003: the 6 ms of jitter gone
    # 200 ms later the window (100 ms) no longer holds 1003: the newest frames' 1008
    assert m.to_shared(266 * ms, 1274 * ms) == 1274 * ms
    # the camera's clock restarts (a reopen): the map starts again
    assert m.to_shared(1 * ms, 1500 * ms) == 1500 * ms

    class TicksOnly:  # a producer that gives ticks and a 125 MHz tick frequency, not ns
        module = type("Module", (), {"timestamp": 250_000_000})()
        timestamp_frequency = 125_000_000

        @property
        def timestamp_ns(self):
            raise RuntimeError("not available")

    assert device_time_ns(TicksOnly()) == 2_000_000_000


def test_a_setting_is_asked_as_the_nearest_value_the_camera_can_take():
    from types import SimpleNamespace

    from humanpt.camera.genicam import _snap

    width = SimpleNamespace(min=16, max=1928, inc=16)  # an IInteger: steps of 16 from 16
    assert _snap(width, 1003) == 1008  # 16 + 62 x 16 (61.7 steps)
    assert _snap(width, 5000) == 1920  # the top step, not 1928 (off the steps)
    assert _snap(width, 4) == 16
    rate = SimpleNamespace(min=1.0, max=200.0, inc=0.0, has_inc=lambda: False)  # an IFloat without steps
    assert _snap(rate, 37.3) == 37.3 and _snap(rate, 500.0) == 200.0


# --- against viky.cti ---


def test_a_genicam_camera_gives_mono8_frames_with_increasing_stamps():
    cfg = CameraConfig(source=_source("VikyTL_DEV_red"))
    frames = list(read_frames(cfg, max_frames=4))
    assert len(frames) == 4
    core = CameraCore(cfg)
    images = []
    for stamp, frame in frames:
        assert frame.shape == (400, 400, 3)  # RGBa8 as BGR
        images += [m for t, m in core.step(stamp, "capture", capture_message(frame, stamp)) if t == "camera/image"]
    assert [(m.encoding, m.width, m.height) for m in images] == [("mono8", 400, 400)] * 4
    stamps = [image_stamp_ns(m) for m in images]
    assert all(b > a for a, b in itertools.pairwise(stamps)), stamps


def test_settings_are_asked_through_the_node_map_and_read_back():
    cfg = CameraConfig(source=_source("1"), width_px=322, height_px=50, fps=500.0, exposure=1000.0, gain=2.0,
                       pixel_format="Mono8")
    cap = open_capture(cfg)
    try:
        node_map = cap.acquirer.remote_device.node_map
        assert (node_map.Width.value, node_map.Height.value, node_map.PixelFormat.value) == (322, 100, "Mono8")
        assert node_map.AcquisitionFrameRate.value == 200.0  # viky's maximum
        assert cap.notes == ["height_px 50 asked, the camera gives 100",  # viky's minimum
                             "fps 500 asked, the camera gives 200",
                             "exposure 1000: the camera has no ExposureTime node (not set)",
                             "gain 2: the camera has no Gain node (not set)"]
        ok, frame = cap.read()
        assert ok and frame.shape == (100, 322) and frame.dtype == np.uint8
        assert cap.shared_stamp_ns(123) == 123  # no timestamp in viky's buffers: the fetch's return
    finally:
        cap.release()


def test_two_cameras_of_one_producer_stream_together():
    """A stereo pair on one producer (source and source_right): the producer is loaded once
    in the process (a second load of viky.cti sees no camera) and shared; released with the
    last camera and loaded again for the next."""
    left = open_capture(CameraConfig(source=_source("VikyTL_DEV_red")))
    try:
        right = open_capture(CameraConfig(source=_source("VikyTL_DEV_blue")))
        try:
            assert left.producer is right.producer and left.producer.users == 2
            for cap in (left, right, left, right):
                ok, frame = cap.read()
                assert ok and frame.shape == (400, 400, 3)
        finally:
            right.release()
        with pytest.raises(OSError, match="genicam VikyTL_DEV_red: does not open .*already in use"):
            open_capture(CameraConfig(source=_source("VikyTL_DEV_red")))  # one program per camera
        assert left.read()[0] and left.producer.users == 1
    finally:
        left.release()
    again = open_capture(CameraConfig(source=_source("VikyTL_DEV_red")))
    try:
        assert again.read()[0] and again.producer.users == 1
    finally:
        again.release()


def test_a_missing_producer_library_or_camera_is_a_clear_error_and_a_camera_not_found_is_retried(
        tmp_path, monkeypatch):
    with pytest.raises(OSError, match="no GenTL producer file .*nope.cti"):
        capture_adapters(CameraConfig(source=f"genicam:{tmp_path / 'nope.cti'}"))
    with pytest.raises(ValueError, match="names no GenTL producer"):
        CameraConfig(source="genicam:#1")
    with pytest.raises(ValueError, match="pixel_format is asked of a GenICam camera only"):
        CameraConfig(source="0", pixel_format="Mono8")
    with pytest.raises(ValueError, match="'Bayer8' is not one of Mono8"):
        CameraConfig(source=_source(), pixel_format="Bayer8")
    (tmp_path / "bad.cti").write_bytes(b"not a GenTL producer")
    with pytest.raises(OSError, match="bad.cti: no camera found"):
        open_capture(CameraConfig(source=f"genicam:{tmp_path / 'bad.cti'}"))
    with pytest.raises(OSError, match="no camera 'VikyTL_DEV_pink'.*it sees: VikyTL_DEV_red \\(serial 0\\), "
                                      "VikyTL_DEV_green \\(serial 1\\), VikyTL_DEV_blue \\(serial 2\\)"):
        open_capture(CameraConfig(source=_source("VikyTL_DEV_pink")))
    # the component lives on and tries again every reopen_s (a camera may be plugged in later)
    adapter = CaptureAdapter(CameraConfig(source=_source("VikyTL_DEV_pink"), reopen_s=0.05))
    adapter.start(lambda topic, msg: None)
    try:
        wait_for(lambda: adapter.errors >= 2, 30, "two attempts to open the camera")
    finally:
        adapter.close()
    assert adapter.frames == 0
    # without the extra installed: which one to install
    monkeypatch.setitem(sys.modules, "harvesters.core", None)
    with pytest.raises(OSError, match=r'pip install "humanpt\[genicam\]"'):
        capture_adapters(CameraConfig(source=_source()))


# --- live: the adapter in a live shell on a real router; the `humanpt camera` process ---


@pytest.mark.timeout(180)
def test_a_stall_and_a_size_change_mid_run_give_events_and_the_run_replays(router, tmp_path):
    """viky's acquisition stopped under the adapter (the device stops delivering: fetches
    time out): camera_stalled; its Width changed while it streams: frame_size_changed, those
    frames dropped; its first size back: camera_resumed. Nothing crashes; the run replays."""
    port, _ = router
    cfg = CameraConfig(source=_source("VikyTL_DEV_green"), fps=50.0, stall_s=0.3, reopen_s=60.0)
    core = CameraCore(cfg)
    adapter = CaptureAdapter(cfg)
    shell = LiveShell(core, RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",), listen=()),
                      run_dir=tmp_path / "run", adapters=[adapter])
    worker = threading.Thread(target=shell.run, daemon=True)
    worker.start()
    try:
        assert shell.ready.wait(60)
        wait_for(lambda: core.frames >= 3, 60, "three frames published")
        node_map = adapter.capture.acquirer.remote_device.node_map
        node_map.AcquisitionStop.execute()
        wait_for(lambda: core.stalled, 60, "camera_stalled")
        node_map.Width.value = 320
        node_map.AcquisitionStart.execute()
        wait_for(lambda: core.dropped >= 2, 60, "frames of the new size dropped")
        node_map.Width.value = 400
        wait_for(lambda: not core.stalled, 60, "camera_resumed")
    finally:
        shell.stop.set()
        worker.join(30)
    assert not worker.is_alive() and adapter.errors == 0
    rec = read(tmp_path / "run" / "camera.mcap")
    events = [(e.t_ns, e.decode()) for e in rec.outputs if e.topic == "camera/events"]
    codes = [m.code for _, m in events]
    # (a loaded machine may also pause the capture thread for stall_s before the stop: a
    # stall and a resume of their own, earlier; the stop's stall is the last before the new size)
    changed = codes.index("frame_size_changed")
    stalled = max(i for i, code in enumerate(codes[:changed]) if code == "camera_stalled")
    assert "camera_resumed" not in codes[stalled:changed] and "camera_resumed" in codes[changed:], codes
    stall_t = events[stalled][0]
    last_image_t = max(e.t_ns for e in rec.outputs if e.topic == "camera/image" and e.t_ns < stall_t)
    assert stall_t - last_image_t > 0.3e9  # no frame for stall_s before it
    assert "320 x 400 px" in events[changed][1].text
    images = [RawImage.FromString(e.data) for e in rec.outputs if e.topic == "camera/image"]
    assert {(m.width, m.height, m.encoding) for m in images} == {(400, 400, "mono8")}
    res = replay(tmp_path / "run" / "camera.mcap")
    assert res.match and res.compared >= len(images), res.report()


@pytest.mark.timeout(180)
def test_the_live_camera_component_publishes_a_genicam_camera_and_its_recording_replays(router, procs, tmp_path):
    port, _ = router
    cfg = write_config(tmp_path / "cam.toml", port,
                       extra=f'[camera]\nsource = "{_source("VikyTL_DEV_blue")}"\nfps = 50.0\npixel_format = "Mono8"\n')
    run_dir = tmp_path / "run"
    seen: list[RawImage] = []
    session = zenoh_client(port)
    try:
        sub = session.declare_subscriber("humanpt/test/camera/image",
                                         lambda s: seen.append(RawImage.FromString(bytes(s.payload))))
        camera = procs.start("camera", "--config", str(cfg), "--run-dir", str(run_dir), "--duration", "120")
        wait_for(lambda: len(seen) >= 5, 120, "five camera/image on the router")
        said = procs.stop(camera)
        sub.undeclare()
    finally:
        session.close()
    assert camera.returncode == 0, said
    assert {(m.width, m.height, m.encoding) for m in seen} == {(400, 400, "mono8")}
    stamps = [image_stamp_ns(m) for m in seen]
    assert all(b > a for a, b in itertools.pairwise(stamps))
    res = replay(run_dir / "camera.mcap")
    assert res.match and res.compared >= 5, res.report()
