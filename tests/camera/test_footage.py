"""Footage through the pipeline (issue 35 acceptance: "a video file source runs through
perception live and its recording replays"): complex images rendered by the twin at known
target poses are written to a folder (lossless PNG: the pixels perception sees are the
rendered ones), the live ``camera`` component plays the folder and the live ``perception``
component measures the target in every frame; both recordings replay.

Expected values: the poses the images were rendered at (the renderer's input), and the
measurement perception's core gives on the same images in-process."""

from __future__ import annotations

import hashlib

import cv2
import numpy as np
import pytest

from humanpt.geometry.rig import camera_T_desired
from humanpt.geometry.transforms import make_transform, matrix_from_rotvec
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.core import PerceptionCore
from humanpt.runtime.recording import read
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_image, from_pose, image, image_stamp_ns
from humanpt.sim_camera import Renderer, SimCameraConfig
from tests.conftest import wait_for, write_config, zenoh_client

N = 8


def _truth(i: int) -> np.ndarray:
    """The target's pose in frame i (mm): 3 mm steps along x and 1 deg about y from D."""
    turn = make_transform(matrix_from_rotvec([0.0, np.radians(i - N / 2), 0.0]), np.array([3.0 * i - 12, 2.0, 0.0]))
    return camera_T_desired(600.0) @ turn


@pytest.fixture(scope="module")
def footage(tmp_path_factory):
    folder = tmp_path_factory.mktemp("footage")
    renderer = Renderer(SimCameraConfig(seed=7))
    frames = [renderer.render(_truth(i), frame_index=i) for i in range(N)]
    for i, f in enumerate(frames):
        assert cv2.imwrite(str(folder / f"frame{i}.png"), f)
    return folder, frames


def _pose_error(measured: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    d = np.linalg.inv(truth) @ measured
    angle = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(d[:3, 3])), float(angle)


def test_perception_measures_the_rendered_poses_in_process(footage):
    _, frames = footage
    core = PerceptionCore(PerceptionConfig())
    for i, f in enumerate(frames):
        ((_, m),) = [o for o in core.step(i * 40_000_000, "camera/image", image(f, i * 40_000_000 + 1, "camera",
                                                                                   "mono8")) if o[0] == "perception/tob"]
        assert m.status == pb.TOB_STATUS_FULL, (i, m.status)
        dt, da = _pose_error(from_pose(m.camera_T_tob), _truth(i) * _mm_to_m())
        assert dt < 1e-3 and da < 0.5, (i, dt, da)  # within 1 mm and 0.5 deg at 600 mm


def _mm_to_m() -> np.ndarray:
    s = np.ones((4, 4))
    s[:3, 3] = 1e-3
    return s


@pytest.mark.timeout(180)
def test_a_folder_of_footage_runs_through_live_perception_and_both_recordings_replay(footage, router, procs, tmp_path):
    folder, frames = footage
    port, _ = router
    cfg = write_config(tmp_path / "cell.toml", port,
                       extra=f'[camera]\nsource = "{folder}"\nfps = 25.0\nloop = true\n')
    run_dir = tmp_path / "run"
    seen: list[pb.TobMeasurement] = []
    session = zenoh_client(port)
    try:
        sub = session.declare_subscriber("humanpt/test/perception/tob",
                                         lambda s: seen.append(pb.TobMeasurement.FromString(bytes(s.payload))))
        perception = procs.start("perception", "--config", str(cfg), "--run-dir", str(run_dir), "--duration", "120")
        camera = procs.start("camera", "--config", str(cfg), "--run-dir", str(run_dir), "--duration", "120")
        # every frame measured at least once after perception came up: two loops of the folder
        wait_for(lambda: len(seen) >= 2 * N + 1, 120, "perception/tob from the footage")
        procs.stop(camera)
        procs.stop(perception)
        sub.undeclare()
    finally:
        session.close()
    by_pixels = {hashlib.sha1(f.tobytes()).hexdigest(): i for i, f in enumerate(frames)}
    captured = {}
    for e in read(run_dir / "camera.mcap").inputs:
        if e.topic == "capture":
            msg = e.decode()
            captured[image_stamp_ns(msg)] = by_pixels[hashlib.sha1(from_image(msg).tobytes()).hexdigest()]
    tobs = [e.decode() for e in read(run_dir / "perception.mcap").outputs if e.topic == "perception/tob"]
    assert len(tobs) >= 2 * N
    indices = set()
    for m in tobs:
        i = captured[m.header.stamp_ns]  # every measurement is of a frame the camera played
        indices.add(i)
        assert m.status == pb.TOB_STATUS_FULL, (i, m.status)
        dt, da = _pose_error(from_pose(m.camera_T_tob), _truth(i) * _mm_to_m())
        assert dt < 1e-3 and da < 0.5, (i, dt, da)
    assert indices == set(range(N))
    for name in ("camera", "perception"):
        res = replay(run_dir / f"{name}.mcap")
        assert res.match and res.compared > 0, (name, res.report())
