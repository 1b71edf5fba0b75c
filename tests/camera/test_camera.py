"""The real-camera source, on a video file the test writes: frames stamped at capture come
out as camera/image; bad and stale frames are dropped with events; the live component
records and replays."""

from __future__ import annotations

import itertools
import threading

import cv2
import numpy as np
import pytest

from humanpt.camera import CameraConfig, CameraCore, CaptureAdapter, capture_message, read_frames
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.recording import read
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_image, image_stamp_ns
from tests.conftest import run_cli, write_config

N_FRAMES = 12


def _frame(i: int) -> np.ndarray:
    """A dark 96 x 64 BGR frame with a bright square moving right."""
    f = np.full((64, 96, 3), 20, np.uint8)
    f[20:36, 5 + 5 * i : 21 + 5 * i] = (90, 200, 240)
    return f


@pytest.fixture(scope="module")
def video(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("video") / "moving.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 50.0, (96, 64))
    assert writer.isOpened()
    for i in range(N_FRAMES):
        writer.write(_frame(i))
    writer.release()
    return str(path)


def _clock(start_ns: int = 1_000_000_000, step_ns: int = 20_000_000):
    counter = itertools.count()
    return lambda: start_ns + step_ns * next(counter)


def test_video_file_frames_become_camera_images_stamped_at_capture(video):
    cfg = CameraConfig(source=video)
    frames = list(read_frames(cfg, clock=_clock()))
    assert len(frames) == N_FRAMES
    ls = Lockstep([CameraCore(cfg)], start_ns=0)
    for stamp, frame in frames:
        ls.inject(stamp, "camera", "capture", capture_message(frame, stamp))
    ls.run_until(10**12)
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

    images = [RawImage.FromString(o.data) for o in ls.outputs if o.topic == "camera/image"]
    assert len(images) == N_FRAMES
    assert [image_stamp_ns(m) for m in images] == [s for s, _ in frames]
    for i, m in enumerate(images):
        assert (m.encoding, m.width, m.height, m.frame_id) == ("mono8", 96, 64, "camera")
        grey = cv2.cvtColor(_frame(i), cv2.COLOR_BGR2GRAY)
        assert np.mean(np.abs(from_image(m).astype(int) - grey)) < 4.0  # MJPG is lossy, a little
        cols = np.flatnonzero(from_image(m)[28] > 100)
        assert abs(cols.mean() - (12.5 + 5 * i)) < 1.0  # the square moved as written


def test_colour_is_kept_when_mono_is_off(video):
    cfg = CameraConfig(source=video, mono=False)
    stamp, frame = next(read_frames(cfg, clock=_clock()))
    ((topic, msg),) = CameraCore(cfg).step(stamp, "capture", capture_message(frame, stamp))
    assert (
        topic == "camera/image" and msg.encoding == "bgr8" and from_image(msg).shape == (64, 96, 3)
    )


def test_bad_and_stale_frames_are_dropped_with_an_event():
    core = CameraCore(CameraConfig(source="unused.avi"))
    good = capture_message(np.zeros((4, 6), np.uint8), 100)
    assert core.step(1, "capture", good)[0][0] == "camera/image"
    stale = capture_message(np.zeros((4, 6), np.uint8), 100)
    ((topic, ev),) = core.step(2, "capture", stale)
    assert topic == "camera/events" and ev.code == "stale_frame"
    broken = capture_message(np.zeros((4, 6), np.uint8), 200)
    broken.data = broken.data[:-3]
    ((topic, ev),) = core.step(3, "capture", broken)
    assert ev.code == "bad_frame" and "needs" in ev.text
    assert (
        core.step(4, "capture", capture_message(np.zeros((4, 6), np.uint8), 300))[0][0]
        == "camera/image"
    )


def test_capture_adapter_grabs_the_whole_file_in_a_thread(video):
    got = []
    adapter = CaptureAdapter(CameraConfig(source=video, pace=False), clock=_clock())
    adapter.start(lambda topic, msg: got.append((topic, msg)))
    assert adapter.finished.wait(10.0)
    adapter.close()
    assert [t for t, _ in got] == ["capture"] * N_FRAMES
    stamps = [image_stamp_ns(m) for _, m in got]
    assert stamps == sorted(stamps) and len(set(stamps)) == N_FRAMES
    assert got[0][1].encoding == "bgr8"


def test_a_source_that_does_not_open_is_retried_not_fatal(tmp_path):
    adapter = CaptureAdapter(CameraConfig(source=str(tmp_path / "nope.avi"), reopen_s=0.05))
    adapter.start(lambda topic, msg: None)
    threading.Event().wait(0.3)
    adapter.close()
    assert adapter.errors >= 2 and adapter.frames == 0
    with pytest.raises(ValueError, match="camera.width_px"):
        CameraConfig(width_px=-1)


@pytest.mark.timeout(120)
def test_live_camera_component_publishes_records_and_replays(video, router, tmp_path):
    port, cfg_path = router
    cfg = write_config(tmp_path / "cam.toml", port, extra=f'[camera]\nsource = "{video}"\n')
    run_dir = tmp_path / "run"
    r = run_cli("camera", "--config", str(cfg), "--run-dir", str(run_dir), "--duration", "3")
    assert r.returncode == 0, r.stderr
    rec = read(run_dir / "camera.mcap")
    outs = [e for e in rec.outputs if e.topic == "camera/image"]
    ins = [e for e in rec.inputs if e.topic == "capture"]
    assert len(ins) == N_FRAMES and len(outs) == N_FRAMES
    res = replay(run_dir / "camera.mcap")
    assert res.match and res.compared >= N_FRAMES, res.report()
    # the file ended (no loop) while the component ran on: a camera that stopped
    stalls = [e for e in rec.outputs if e.topic == "camera/events" and e.decode().code == "camera_stalled"]
    assert len(stalls) == 1 and stalls[0].t_ns > outs[-1].t_ns, [e.decode().text for e in stalls]



def _codes(outputs) -> list[str]:
    return [m.code for t, m in outputs if t == "camera/events"]


def test_a_camera_that_stops_gives_camera_stalled_once_and_camera_resumed():
    # stall_s 0.5 s: ticks every 0.1 s; frames at 0.0 .. 0.2 s, then none until 1.5 s
    core = CameraCore(CameraConfig(source="unused.avi", stall_s=0.5))
    assert core.tick_period_ns() == 100_000_000
    frame = lambda t: capture_message(np.zeros((4, 6), np.uint8), t)  # noqa: E731
    ms = 1_000_000
    events = []
    for t in range(0, 1500 * ms, 100 * ms):
        if t <= 200 * ms:
            events += core.step(t, "capture", frame(t + 1))
        events += core.step(t + 1, "tick", pb.Tick())
    # the last frame at 0.2 s: 0.7 s is the first tick more than 0.5 s later (0.5 s after
    # 0.2 s is 0.7 s; 0.7 s + 1 ns > 0.5 s gap): one event, not one per tick after it
    stalled = [m for t, m in events if t == "camera/events"]
    assert [m.code for m in stalled] == ["camera_stalled"]
    assert stalled[0].header.stamp_ns == 700 * ms + 1 and stalled[0].severity == pb.SEVERITY_ERROR
    out = core.step(1500 * ms, "capture", frame(1500 * ms))
    assert _codes(out) == ["camera_resumed"] and out[-1][0] == "camera/image"
    assert _codes(core.step(1600 * ms + 1, "tick", pb.Tick())) == []


def test_no_frame_at_all_is_a_stall_and_a_clock_step_is_not():
    core = CameraCore(CameraConfig(source="unused.avi", stall_s=0.5))
    ms = 1_000_000
    assert _codes(core.step(0, "tick", pb.Tick())) == []
    out = core.step(600 * ms, "tick", pb.Tick())
    assert _codes(out) == ["camera_stalled"] and "no frame yet" in out[0][1].text
    # a healthy camera whose clock is stepped 2 s forward (NTP): the watch moves with it
    core = CameraCore(CameraConfig(source="unused.avi", stall_s=0.5))
    core.step(0, "capture", capture_message(np.zeros((4, 6), np.uint8), 1))
    core.step(1, "clock_step", pb.Event(text=str(2_000_000_000)))
    assert _codes(core.step(2_100 * ms, "tick", pb.Tick())) == []


def test_a_frame_of_another_size_is_dropped_with_an_event():
    core = CameraCore(CameraConfig(source="unused.avi"))
    assert core.step(1, "capture", capture_message(np.zeros((4, 6), np.uint8), 100))[0][0] == "camera/image"
    ((topic, ev),) = core.step(2, "capture", capture_message(np.zeros((8, 6), np.uint8), 200))
    assert ev.code == "frame_size_changed" and "6 x 8 px" in ev.text and "6 x 4 px" in ev.text
    assert core.step(3, "capture", capture_message(np.zeros((4, 6), np.uint8), 300))[0][0] == "camera/image"


# --- an image folder as the source (issue 35 item 2): real footage replayed at camera.fps ---


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Twelve frames as img1.png .. img12.png (natural order differs from the names' sort:
    img10 sorts before img2 as text), one grey .pgm among them, and a damaged file and a
    text file that are not images."""
    path = tmp_path_factory.mktemp("images")
    for i in range(N_FRAMES):
        frame = _frame(i)
        if i == 3:
            cv2.imwrite(str(path / f"img{i + 1}.pgm"), cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
        else:
            cv2.imwrite(str(path / f"img{i + 1}.png"), frame)
    (path / "img12b.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")  # damaged: skipped with an error
    (path / "notes.txt").write_text("not an image")  # not an image suffix: not read
    return path


def test_an_image_folder_plays_in_natural_order_and_skips_a_damaged_file(folder):
    got = list(read_frames(CameraConfig(source=str(folder), fps=25.0), clock=_clock()))
    assert len(got) == N_FRAMES  # the damaged file lost only itself
    # the bright square moves 5 px right per frame: frame i's square starts at column 5 + 5 i
    for i, (_, frame) in enumerate(got):
        grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        cols = np.flatnonzero(grey[28] > 100)
        assert cols[0] == 5 + 5 * i, (i, cols[:3])
    assert got[3][1].ndim == 2 and got[0][1].ndim == 3  # the .pgm is grey, the .png colour
    from humanpt.camera.capture import ImageFolder

    reader = ImageFolder(folder, 25.0)
    while reader.read()[0]:
        pass
    assert [p.name for p in reader.skipped] == ["img12b.png"]


def test_an_image_folder_without_a_frame_rate_or_images_is_refused(folder, tmp_path):
    from humanpt.camera.capture import capture_adapters

    with pytest.raises(OSError, match="is an image folder: set camera.fps"):
        capture_adapters(CameraConfig(source=str(folder)))
    (tmp_path / "empty").mkdir()
    with pytest.raises(OSError, match="holds no image"):
        capture_adapters(CameraConfig(source=str(tmp_path / "empty"), fps=25.0))


@pytest.mark.timeout(120)
def test_live_camera_component_on_an_image_folder_records_and_replays(folder, router, tmp_path):
    port, _ = router
    cfg = write_config(tmp_path / "cam.toml", port, extra=f'[camera]\nsource = "{folder}"\nfps = 200.0\n')
    run_dir = tmp_path / "run"
    r = run_cli("camera", "--config", str(cfg), "--run-dir", str(run_dir), "--duration", "3")
    assert r.returncode == 0, r.stderr
    assert "img12b.png" in r.stderr  # the skipped file is named
    rec = read(run_dir / "camera.mcap")
    outs = [e for e in rec.outputs if e.topic == "camera/image"]
    assert len(outs) == N_FRAMES
    assert {e.decode().encoding for e in outs} == {"mono8"}
    stamps = [image_stamp_ns(e.decode()) for e in outs]
    assert stamps == sorted(stamps) and len(set(stamps)) == N_FRAMES  # (the pacing is a rate: not asserted here)
    res = replay(run_dir / "camera.mcap")
    assert res.match and res.compared >= N_FRAMES, res.report()


# --- a device's settings (issue 35 item 2): asked, read back, what the driver did not take said ---


class _Driver:
    """A V4L2 driver as OpenCV sees it (a device cannot exist here): it takes what it can
    and rounds the frame rate to its own modes; exposure needs manual mode first."""

    def __init__(self):
        self.values = {cv2.CAP_PROP_FRAME_WIDTH: 640.0, cv2.CAP_PROP_FRAME_HEIGHT: 480.0, cv2.CAP_PROP_FPS: 30.0,
                       cv2.CAP_PROP_EXPOSURE: 156.0, cv2.CAP_PROP_GAIN: 0.0, cv2.CAP_PROP_AUTO_EXPOSURE: 3.0}
        self.asked = []

    def set(self, prop, value):
        self.asked.append((prop, value))
        if prop == cv2.CAP_PROP_GAIN:
            return False  # no gain control on this camera
        if prop == cv2.CAP_PROP_FPS:
            value = 30.0 if value > 30 else 15.0  # its two modes
        if prop == cv2.CAP_PROP_EXPOSURE and self.values[cv2.CAP_PROP_AUTO_EXPOSURE] != 1:
            return False
        self.values[prop] = float(value)
        return True

    def get(self, prop):
        return self.values[prop]


def test_a_devices_settings_are_asked_and_what_the_driver_did_not_take_is_said():
    from humanpt.camera.capture import request_settings

    driver = _Driver()
    cfg = CameraConfig(source="/dev/video0", width_px=1280, height_px=720, fps=60, exposure=50, gain=4)
    notes = request_settings(driver, cfg)
    assert cfg.is_device and CameraConfig(source="2").is_device and not CameraConfig(source="a.avi").is_device
    assert driver.values[cv2.CAP_PROP_FRAME_WIDTH] == 1280 and driver.values[cv2.CAP_PROP_EXPOSURE] == 50
    # auto exposure off before the exposure is set
    assert driver.asked.index((cv2.CAP_PROP_AUTO_EXPOSURE, 1)) < driver.asked.index((cv2.CAP_PROP_EXPOSURE, 50))
    assert notes == ["fps 60 asked, the driver gives 30", "gain 4 refused by the driver (it gives 0)"]
    # nothing asked that the config leaves at 0 (the driver's default)
    driver = _Driver()
    assert request_settings(driver, CameraConfig(source="0")) == [] and driver.asked == []
    with pytest.raises(ValueError, match="camera.exposure"):
        CameraConfig(exposure=-1.0)


# --- two cameras, an ordinary stereo pair (issue 35 item 3): frames paired by stamp ---


def test_two_cameras_frames_are_paired_by_stamp_and_the_unpaired_counted():
    # 5 ms tolerance. Left at 0, 40, 80, 120 ms; right at 2, 43, 95 (drifted), 121 ms:
    # pairs (0, 2), (40, 43), (120, 121); left 80 and right 95 are 15 ms apart: both dropped.
    core = CameraCore(CameraConfig(source="0", source_right="1", pair_tolerance_ms=5.0))
    ms = 1_000_000
    left = lambda t: capture_message(np.full((4, 6), 10, np.uint8), t * ms)  # noqa: E731
    right = lambda t: capture_message(np.full((4, 6), 200, np.uint8), t * ms)  # noqa: E731
    out = []
    for t, side in ((0, "L"), (2, "R"), (40, "L"), (43, "R"), (80, "L"), (95, "R"), (120, "L"), (121, "R")):
        out += core.step(t * ms + 1, "capture" if side == "L" else "capture_right", left(t) if side == "L" else right(t))
    images = [m for topic, m in out if topic == "camera/image"]
    assert [image_stamp_ns(m) for m in images] == [1 * ms, 41 * ms + ms // 2, 120 * ms + ms // 2]
    px = from_image(images[0])
    assert px.shape == (4, 12) and (px[:, :6] == 10).all() and (px[:, 6:] == 200).all()  # left | right
    unpaired = [m.text for topic, m in out if topic == "camera/events" and m.code == "unpaired_frame"]
    assert len(unpaired) == 2 and "left camera's frame stamped 80000000" in unpaired[0]
    assert "right camera's frame stamped 95000000" in unpaired[1] and core.unpaired == 2


def test_one_dead_camera_of_a_pair_is_a_stall():
    core = CameraCore(CameraConfig(source="0", source_right="1", stall_s=0.5))
    ms = 1_000_000
    events = []
    for t in range(0, 1000 * ms, 40 * ms):  # the left camera runs, the right one is dead
        events += core.step(t, "capture", capture_message(np.zeros((4, 6), np.uint8), t + 1))
        events += core.step(t + 1, "tick", pb.Tick())
    assert "camera_stalled" in _codes(events) and "no pair" in next(
        m.text for t, m in events if t == "camera/events" and m.code == "camera_stalled")
    assert not [m for t, m in events if t == "camera/image"]


@pytest.mark.timeout(120)
def test_live_camera_pairs_two_folders_and_replays(folder, router, tmp_path):
    port, _ = router
    cfg = write_config(tmp_path / "cam.toml", port,
                       extra=f'[camera]\nsource = "{folder}"\nsource_right = "{folder}"\nfps = 100.0\n'
                             "pair_tolerance_ms = 20.0\n")
    run_dir = tmp_path / "run"
    r = run_cli("camera", "--config", str(cfg), "--run-dir", str(run_dir), "--duration", "3")
    assert r.returncode == 0, r.stderr
    rec = read(run_dir / "camera.mcap")
    assert {e.topic for e in rec.inputs} >= {"capture", "capture_right"}
    outs = [e.decode() for e in rec.outputs if e.topic == "camera/image"]
    # the two "cameras" play the same 12 frames at 100 frames/s from threads started together:
    # each pair is one frame seen twice, side by side
    assert len(outs) >= N_FRAMES - 2
    for m in outs:
        assert (m.width, m.height) == (2 * 96, 64)
    res = replay(run_dir / "camera.mcap")
    assert res.match and res.compared >= len(outs), res.report()
