"""Each image recorded once (issue 20 item 5): a consumer's image inputs are references to
the producer's recording, replay puts the pixels back and stays exact; ``[record] images``
keeps one image in N (or none) and replay says which inputs it then lacks."""

from __future__ import annotations

import shutil
from collections import Counter

import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.perception.core import PerceptionCore
from humanpt.runtime.config import ConfigError, RecordConfig, from_dict
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.recording import (
    FULL,
    OMITTED,
    REFERENCE,
    SAME_AS_INPUT,
    RecordingError,
    iter_entries,
    merge_entries,
)
from humanpt.runtime.replay import EXIT_MATCH, EXIT_NOTHING_COMPARED, replay
from humanpt.twin.system import build_system

pytestmark = pytest.mark.timeout(120)
DURATION_S = 2.0
FPS = 30.0  # SimCameraConfig's default frame rate (an independent count of the images)
IMAGE = RawImage.DESCRIPTOR.full_name


def _images(path):
    """(direction, topic, payload, (stamp ns, frame_id), pixel bytes) of every image recorded."""
    out = []
    for e in iter_entries(path):
        if e.schema == IMAGE:
            m = RawImage.FromString(e.data)
            out.append((e.direction, e.topic, e.payload,
                        (m.timestamp.seconds * 10**9 + m.timestamp.nanos, m.frame_id), len(m.data)))
    return out


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One lock-step run of the closed loop on the twin, recorded with the default [record]."""
    d = tmp_path_factory.mktemp("run")
    w = build_system("arc", seed=3, run_dir=d, keep_outputs=False, digest=False)
    w.run_for(DURATION_S)
    w.close()
    return d


def test_each_image_is_recorded_once(run):
    pixels: Counter = Counter()  # image identity -> copies with pixels across the run
    for f in sorted(run.glob("*.mcap")):
        for _, _, _, ident, n in _images(f):
            if n:
                pixels[ident] += 1
    produced = [i for i in _images(run / "sim_camera.mcap") if i[0] == "out"]
    # ~30 fps for 2 s (the first image leaves once the robot's truth beyond it exists)
    assert FPS * DURATION_S - 3 <= len(produced) <= FPS * DURATION_S + 1, len(produced)
    assert len({p[3] for p in produced}) == len(produced)  # stamp + frame_id names one image
    assert set(pixels) == {p[3] for p in produced}
    assert set(pixels.values()) == {1}, Counter(pixels.values())  # once each, not twice
    inputs = [i for i in _images(run / "perception.mcap") if i[0] == "in"]
    assert len(inputs) == len(produced) and {i[2] for i in inputs} == {REFERENCE}
    assert all(i[4] == 0 for i in inputs)  # no pixels in perception's recording
    # The run's size: one copy of ~60 frames of 640x480 at ~1.4 bits per pixel, not two.
    sizes = {f.stem: f.stat().st_size for f in run.glob("*.mcap")}
    assert sizes["perception"] < sizes["sim_camera"] / 20, sizes
    # runs merge / view read each image once, with its pixels
    merged = [e for _, _, e in merge_entries(sorted(run.glob("*.mcap")), [], lambda e: e.schema == IMAGE)]
    assert len(merged) == len(produced) and all(e.payload == FULL for e in merged)


def test_replay_of_perception_puts_the_pixels_back_and_matches(run):
    res = replay(run / "perception.mcap")
    assert res.match and res.missing is None, res.report()
    assert res.compared >= FPS * DURATION_S - 3  # a measurement per image
    assert replay(run / "sim_camera.mcap").match


def test_a_missing_producer_recording_is_named(run, tmp_path):
    shutil.copy(run / "perception.mcap", tmp_path)
    with pytest.raises(RecordingError, match=r"sim_camera\.mcap is missing"):
        replay(tmp_path / "perception.mcap")


def test_a_truncated_producer_recording_replays_up_to_the_first_missing_image(run, tmp_path):
    shutil.copy(run / "perception.mcap", tmp_path)
    data = (run / "sim_camera.mcap").read_bytes()
    (tmp_path / "sim_camera.mcap").write_bytes(data[: len(data) // 2])
    res = replay(tmp_path / "perception.mcap")
    assert res.missing is not None and "camera/image" in res.missing and "not in sim_camera.mcap" in res.missing
    assert res.exit_code == EXIT_MATCH and 0 < res.compared < FPS * DURATION_S - 3, res.report()
    assert "inputs missing" in res.report()


def test_every_n_keeps_one_image_in_n_and_replay_says_what_is_missing(run, tmp_path):
    """The producer keeps one image in 3 (its own replay still matches, without pixels
    where none were kept); perception alone in a run keeps what the policy keeps."""
    w = build_system("arc", seed=3, keep_outputs=False, digest=False)
    with Lockstep(w.lockstep.cores, run_dir=tmp_path, record=RecordConfig(images="every 3"),
                  keep_outputs=False, digest=False) as ls:
        ls.run_until(int(1.0e9))
    cam = [i for i in _images(tmp_path / "sim_camera.mcap") if i[0] == "out"]
    assert [i[2] for i in cam[:6]] == [FULL, OMITTED, OMITTED, FULL, OMITTED, OMITTED]
    assert all((i[4] > 0) == (i[2] == FULL) for i in cam)
    assert replay(tmp_path / "sim_camera.mcap").match
    res = replay(tmp_path / "perception.mcap")
    assert res.missing is not None and "every 3" in res.missing, res.report()
    assert f"{len(cam) - len(cam[::3])} of" in res.missing  # the two images of every three not kept

    # perception with no recorded producer keeps the pixels itself (as the policy says)
    frames = [RawImage.FromString(e.data) for e in iter_entries(run / "sim_camera.mcap")
              if e.topic == "camera/image" and e.direction == "out"][:12]
    for policy, expect in (("all", EXIT_MATCH), ("none", EXIT_NOTHING_COMPARED)):
        d = tmp_path / policy
        twin_perception = next(c for c in w.lockstep.cores if c.name == "perception")
        core = PerceptionCore.create(twin_perception.config, twin_perception.rig)
        with Lockstep([core], run_dir=d, record=RecordConfig(images=policy)) as solo:
            for k, m in enumerate(frames):
                solo.inject(k * 33_000_000, "perception", "camera/image", m)
            solo.run_until(10**9)
        res = replay(d / "perception.mcap")
        assert res.exit_code == expect, res.report()


@pytest.mark.parametrize("value, ok", [
    ("all", 1), ("none", 0), ("every 1", 1), ("every  7", 7), ("every 0", None), ("every -2", None),
    ("evry 3", None), ("every 3.5", None), ("some", None), (3, None), ("every 100001", None)])
def test_images_policy_parsing(value, ok):
    doc = {"record": {"images": value}}
    if ok is None:
        with pytest.raises(ConfigError, match=r"cell\.toml: \[record\]"):
            from_dict(doc, "cell.toml")
    else:
        assert from_dict(doc, "cell.toml").record.keep_every == ok


def test_record_section_keys_are_checked():
    with pytest.raises(ConfigError, match=r"\[record\] unknown key 'imagez'"):
        from_dict({"record": {"imagez": "all"}}, "cell.toml")
    with pytest.raises(ConfigError, match=r"\[record\] image_inputs"):
        from_dict({"record": {"image_inputs": "copy"}}, "cell.toml")
    assert from_dict({}, "cell.toml").record == RecordConfig()


def test_an_output_copying_its_input_image_is_recorded_once(run, tmp_path):
    """viz forwards each image it takes (show:camera.image); the real camera passes a mono8
    capture on unchanged: the copy is recorded SAME_AS_INPUT, and both replay exactly."""
    from humanpt.camera import CameraConfig, CameraCore
    from humanpt.runtime.registry import core_class

    w = build_system("arc", seed=3, keep_outputs=False, digest=False)
    twin_perception = next(c for c in w.lockstep.cores if c.name == "perception")
    viz_cls = core_class("viz")
    viz = viz_cls.create(viz_cls.default_config(), twin_perception.rig)
    with Lockstep([*w.lockstep.cores, viz], run_dir=tmp_path / "viz", keep_outputs=False, digest=False) as ls:
        ls.run_until(int(0.5e9))
    got = Counter((i[0], i[1], i[2], i[4] > 0) for i in _images(tmp_path / "viz" / "viz.mcap"))
    assert set(got) == {("in", "camera/image", REFERENCE, False), ("out", "show:camera.image", SAME_AS_INPUT, False)}
    assert replay(tmp_path / "viz" / "viz.mcap").match

    frames = [RawImage.FromString(e.data) for e in iter_entries(run / "sim_camera.mcap")
              if e.topic == "camera/image" and e.direction == "out"][:5]
    with Lockstep([CameraCore(CameraConfig())], run_dir=tmp_path / "cam") as ls:
        for m in frames:  # a mono8 camera: what it captures is what it publishes
            ls.inject(m.timestamp.seconds * 10**9 + m.timestamp.nanos, "camera", "capture", m)
        ls.run_until(frames[-1].timestamp.seconds * 10**9 + frames[-1].timestamp.nanos + 1)  # (no stall)
    got = Counter((i[0], i[1], i[2], i[4] > 0) for i in _images(tmp_path / "cam" / "camera.mcap"))
    assert got == {("in", "capture", FULL, True): 5, ("out", "camera/image", SAME_AS_INPUT, False): 5}
    res = replay(tmp_path / "cam" / "camera.mcap")
    assert res.match and res.compared == 5, res.report()


def test_live_rule_counts_a_producer_recording_being_written(tmp_path):
    """live_producers: a producer's recording in the run directory, written to lately (not a
    stale file of an earlier run), and never the asking component itself."""
    import os
    import time

    from humanpt.runtime.recording import live_producers

    producers = live_producers(tmp_path, fresh_s=10.0)
    assert producers("camera/image", "perception") == ()
    (tmp_path / "camera.mcap").write_bytes(b"x")
    old = time.time() - 60
    os.utime(tmp_path / "camera.mcap", (old, old))
    assert producers("camera/image", "perception") == ()  # stale: an earlier run's
    (tmp_path / "camera.1.mcap").write_bytes(b"x")  # the camera restarted into this run
    assert producers("camera/image", "perception") == ("camera",)
    assert producers("camera/image", "camera") == ()
    assert producers("perception/tob", "pose_filter") == ()  # not an image topic


def test_live_perception_records_references_to_the_live_camera(tmp_path, router, procs):
    """Two live components on a real router, one run directory: perception's image inputs
    are references to camera.mcap, and its replay is exact."""
    import cv2
    import numpy as np

    from tests.conftest import write_config

    video = tmp_path / "dots.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (160, 120))
    for i in range(10):
        f = np.full((120, 160, 3), 12, np.uint8)
        cv2.circle(f, (40 + 4 * i, 60), 3, (255, 255, 255), -1)
        writer.write(f)
    writer.release()
    port, _ = router
    cfg = write_config(tmp_path / "live.toml", port, extra=f'[camera]\nsource = "{video}"\nloop = true\n')
    run_dir = tmp_path / "run"
    common = ("--config", str(cfg), "--run-dir", str(run_dir), "--duration", "4")
    perception = procs.start("perception", *common)
    camera = procs.start("camera", *common)
    for p in (camera, perception):
        p.wait(timeout=30)  # --duration ends each
        out = procs.stop(p)
        assert p.returncode == 0, out
    refs = [i for i in _images(run_dir / "perception.mcap") if i[0] == "in"]
    assert refs and {i[2] for i in refs} == {REFERENCE} and all(i[4] == 0 for i in refs)
    res = replay(run_dir / "perception.mcap")
    assert res.match and res.compared >= len(refs), res.report()


def test_a_reference_resolves_only_to_the_one_image_it_names(tmp_path):
    """Two different producer images with one stamp and frame_id: refused as ambiguous; an
    image of that identity but another size: not taken for it."""
    import numpy as np

    from humanpt.runtime.recording import ImagePolicy, Recorder, read, resolve_images
    from humanpt.schemas.convert import image

    a, b = np.zeros((4, 6), np.uint8), np.full((4, 6), 9, np.uint8)
    policy = ImagePolicy("perception", producers=lambda topic, me: ("camera",))
    for name, produced in (("twice", (a, b)), ("resized", (np.zeros((2, 3), np.uint8),))):
        d = tmp_path / name
        with Recorder(d / "camera.mcap", {"component": "camera"}) as cam:
            for px in produced:
                cam.write("out", 0, "camera/image", image(px, 5_000, "camera"))
        with Recorder(d / "perception.mcap", {"component": "perception"}, images=policy) as per:
            per.write("in", 1, "camera/image", image(a, 5_000, "camera"))
        rec = read(d / "perception.mcap")
        assert rec.entries[0].payload == REFERENCE
        if name == "twice":
            with pytest.raises(RecordingError, match="ambiguous"):
                resolve_images(rec)
        else:
            left = resolve_images(rec)
            assert len(left) == 1 and "another size" in left[0].missing
