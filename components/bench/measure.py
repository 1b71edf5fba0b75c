"""What ``humanpt bench runtime|render|perception`` measure (the CLI prints the tables).
Nothing here is asserted."""

from __future__ import annotations

import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.runtime.bus import free_tcp_port
from humanpt.runtime.config import RuntimeConfig


def percentile_ms(samples_ns: list[int], q: float) -> float:
    return float(np.percentile(np.asarray(samples_ns, dtype=float), q)) / 1e6


def synthetic_image(seed: int = 0, width: int = 640, height: int = 480) -> np.ndarray:
    """A dark frame with six bright discs and sensor noise, like a PSVS complex image."""
    rng = np.random.default_rng(seed)
    img = rng.normal(12, 2.0, (height, width))
    yy, xx = np.mgrid[0:height, 0:width]
    for u, v in rng.uniform((40, 40), (width - 40, height - 40), size=(6, 2)):
        img[(xx - u) ** 2 + (yy - v) ** 2 <= 36] = 230
    return np.clip(img, 0, 255).astype(np.uint8)


def round_trips(payload: bytes, n: int, port: int) -> list[int]:
    """Round-trip times (ns) of ``payload`` client A -> router -> client B -> router -> A."""
    import zenoh

    from humanpt.runtime.bus import zenoh_config

    rt = RuntimeConfig(connect=(f"tcp/127.0.0.1:{port}",), listen=(f"tcp/127.0.0.1:{port}",))
    router_conf = zenoh_config(rt, mode="router", listen=rt.listen, connect=())
    rtts: list[int] = []
    got = threading.Event()
    with zenoh.open(router_conf), zenoh.open(zenoh_config(rt)) as a, zenoh.open(zenoh_config(rt)) as b:
        pong_pub = b.declare_publisher("bench/pong")
        b_sub = b.declare_subscriber("bench/ping", lambda s: pong_pub.put(s.payload.to_bytes()))
        a_sub = a.declare_subscriber("bench/pong", lambda s: got.set())
        ping_pub = a.declare_publisher("bench/ping")
        time.sleep(0.3)  # let declarations reach the router
        for i in range(n + 10):
            got.clear()
            t0 = time.perf_counter_ns()
            ping_pub.put(payload)
            if not got.wait(2.0):
                continue
            if i >= 10:  # warm-up
                rtts.append(time.perf_counter_ns() - t0)
        a_sub.undeclare()
        b_sub.undeclare()
    return rtts


def mcap_throughput(msg_factory, seconds: float, compression: str = "zstd") -> tuple[float, float, int]:
    """(payload MB/s, messages/s, file bytes) writing messages for ``seconds`` with the Recorder."""
    from humanpt.runtime.recording import OUT, Recorder

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "bench.mcap"
        rec = Recorder(path, {"component": "bench"}, compression=compression)
        n = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            msg = msg_factory(n)
            rec.write(OUT, n * 1_000_000, "camera/image" if hasattr(msg, "encoding") else "ponger/pong", msg)
            n += 1
        rec.close()
        dt = time.perf_counter() - t0
        return rec.bytes_written / dt / 1e6, n / dt, path.stat().st_size


@dataclass
class RoundTrip:
    """Round trips of one payload through the router (ms); empty when nothing came back."""

    label: str
    p50_ms: float | None
    p99_ms: float | None
    n: int


@dataclass
class Throughput:
    """MCAP writing with the Recorder: payload MB/s, messages/s, file bytes / payload bytes."""

    label: str
    mb_s: float
    msg_s: float
    file_over_payload: float | None


def measure_runtime(n: int, seconds: float,
                    progress: Callable[[str], None] | None = None) -> tuple[list[RoundTrip], list[Throughput]]:
    """``n`` round trips each of a 200-byte message and a 640x480 image through a router on
    loopback (router and both clients in this process); MCAP write throughput for
    ``seconds`` each of images and of 200-byte events (zstd). ``progress(label)`` after
    each round-trip case."""
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import header, image

    trips = []
    small = bytes(range(200))
    img = synthetic_image()
    img_payload = image(img, 0).SerializeToString()
    for label, payload in (("200-byte message", small), (f"640x480 mono8 image ({len(img_payload)} B)", img_payload)):
        rtts = round_trips(payload, n, free_tcp_port())
        if not rtts:
            trips.append(RoundTrip(label, None, None, 0))
            continue
        trips.append(RoundTrip(label, percentile_ms(rtts, 50), percentile_ms(rtts, 99), len(rtts)))
        if progress is not None:
            progress(label)
    imgs = [image(synthetic_image(seed=s), s) for s in range(8)]
    mbps, rate, size = mcap_throughput(lambda k: imgs[k % len(imgs)], seconds)
    writes = [Throughput("images (zstd)", mbps, rate, size / max(1, rate * seconds * len(img_payload)))]
    ev = pb.Event(header=header(1, 2, "world"), severity=2, source="bench", code="x", text="y" * 150)
    mbps, rate, size = mcap_throughput(lambda k: ev, seconds)
    writes.append(Throughput("200-byte events (zstd)", mbps, rate, None))
    return trips, writes


@dataclass
class RenderBench:
    """Seconds per frame of the simulated PSVS camera, per stage and for its core step."""

    frames: int
    width_px: int
    height_px: int
    blur_sigma_px: float
    render_s: float  # the renderer alone, per frame
    stages_s: dict[str, float]  # per frame
    core_step_s: float  # the sim_camera core: truth in, image message out, per frame


def measure_render(frames: int) -> RenderBench:
    """The simulated PSVS camera at its default settings, ``frames`` frames per case."""
    from humanpt.geometry import camera_T_desired
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import header, pose
    from humanpt.sim_camera import Renderer, SimCameraConfig, SimCameraCore

    n = max(1, frames)
    cfg = SimCameraConfig()
    renderer = Renderer(cfg)
    camera_T_tob = camera_T_desired(600.0)
    for i in range(10):  # warm-up
        renderer.render(camera_T_tob, frame_index=i)
    stages = {"project": 0.0, "coverage + blur": 0.0, "sensor (noise, 8 bit)": 0.0}
    shape = (cfg.psvs.image_height_px, cfg.psvs.image_width_px)
    t_all = time.perf_counter()
    for i in range(n):
        t0 = time.perf_counter()
        blobs = renderer.blobs(renderer.discs(camera_T_tob))
        t1 = time.perf_counter()
        idx, signal = renderer.signal_pixels(blobs)  # the stages render() runs
        t2 = time.perf_counter()
        renderer.expose_pixels(idx, signal, i, shape)
        t3 = time.perf_counter()
        stages["project"] += t1 - t0
        stages["coverage + blur"] += t2 - t1
        stages["sensor (noise, 8 bit)"] += t3 - t2
    total = time.perf_counter() - t_all
    # The whole core: truth in, image message out (what the lock-step world runs).
    core = SimCameraCore(cfg)
    flange = np.eye(4)
    tob = cfg.flange_T_camera @ camera_T_tob  # world = flange frame here
    for topic, field, a_T_b in (("sim_robot/truth", "world_T_flange", flange), ("operator/truth", "world_T_tob", tob)):
        m = a_T_b.copy()
        m[:3, 3] /= 1000.0
        msg = pb.Truth(header=header(0))
        getattr(msg, field).CopyFrom(pose(m))
        core.step(0, topic, msg)
    period = cfg.tick_period_ns
    t0 = time.perf_counter()
    for i in range(n):
        core.step((i + 1) * period, "tick", pb.Tick(header=header((i + 1) * period), period_ns=period))
    core_total = time.perf_counter() - t0
    return RenderBench(n, cfg.psvs.image_width_px, cfg.psvs.image_height_px, cfg.blur_sigma_px, total / n,
                       {k: t / n for k, t in stages.items()}, core_total / n)


def pin_one_cpu() -> str:
    """Run this process (and OpenCV) on one CPU: '' or a note for the table's title."""
    import os

    import cv2

    cv2.setNumThreads(1)
    if hasattr(os, "sched_setaffinity"):
        try:
            os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
            return ", pinned to one CPU"
        except OSError:
            pass
    return ""


def measure_perception(n_images: int) -> list[tuple[str, str, float, float, float]]:
    """Each perception method on 640x480 twin images (random poses): rows of (method,
    case, images/s, p50 ms, p99 ms), ``n_images`` per case."""

    from humanpt.perception import Perception, PerceptionConfig, PerceptionCore
    from humanpt.schemas.convert import image
    from humanpt.sim_camera import Renderer
    from humanpt.testing.perception_eval import random_cases

    n = max(1, n_images)
    cases = random_cases(16, seed=1)
    renderer = Renderer(cases[0].sim)
    images = [renderer.render(c.camera_T_tob, frame_index=c.frame_index) for c in cases]
    messages = [image(img, (k + 1) * 33_000_000) for k, img in enumerate(images)]

    def timed(fn) -> tuple[float, float, float]:
        for k in range(min(20, n)):  # warm-up
            fn(k)
        t = np.empty(n)
        for k in range(n):
            t0 = time.perf_counter_ns()
            fn(k)
            t[k] = time.perf_counter_ns() - t0
        return 1e9 * n / t.sum(), float(np.percentile(t, 50)) / 1e6, float(np.percentile(t, 99)) / 1e6

    rows = []
    m = len(images)
    for method in ("weighted", "paper"):
        p = Perception(PerceptionConfig(method=method))
        rois = []
        for img in images:
            r = p.measure(img)
            rois.append(p.roi_around(r.blobs.uv_px, r.blobs.size_px))
        rows.append((method, "search: whole image", *timed(lambda k, p=p: p.measure(images[k % m]))))
        rows.append((method, "tracking: region of interest",
                     *timed(lambda k, p=p, rois=rois: p.measure(images[k % m], rois[k % m]))))
        # the whole core step on a sequence (decode, checks, ROI tracking, message); each
        # image repeated 4 times so that the tracking region holds
        core = PerceptionCore(PerceptionConfig(method=method))
        rows.append((method, "core step (decode ... message)",
                     *timed(lambda k, core=core: core.step(k, "camera/image", messages[(k // 4) % m]))))
    return rows


def perception_accuracy(images: int, seed: int) -> dict:
    """Both methods' accuracy on twin images with ground truth: {set name: evaluation},
    ``images`` per set (a quarter of it at each end of the working range)."""
    from humanpt.testing.perception_eval import SETS, cases_for, evaluate, range_cases

    results = {name: evaluate(cases_for(name, images, seed)) for name in SETS if name != "range"}
    for z in (250.0, 350.0, 1200.0, 1800.0):  # the ends of the working range, one row each
        results[f"z={z:.0f}mm"] = evaluate(range_cases(images // 4, seed, (z,)))
    return results
