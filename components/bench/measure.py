"""What ``humanpt bench runtime|render|perception`` measure (the CLI prints the tables).
Nothing here is asserted."""

from __future__ import annotations

import inspect
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


def raw_mcap_throughput(msg_factory, seconds: float, compression: str = "zstd") -> tuple[float, float, int]:
    """The baseline of :func:`mcap_throughput`: what a user would write instead, mcap's own
    ``Writer`` (one schema, one channel, each message serialized and added), same chunk
    size and compression: (payload MB/s, messages/s, file bytes)."""
    from mcap.writer import CompressionType, Writer

    from humanpt.runtime.recording import Recorder

    chunk_size = inspect.signature(Recorder).parameters["chunk_size"].default  # the Recorder's default
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "raw.mcap"
        with open(path, "wb") as f:
            w = Writer(f, chunk_size=chunk_size, compression=comp)
            w.start(profile="", library="bench")
            first = msg_factory(0)
            schema = w.register_schema(first.DESCRIPTOR.full_name, "protobuf", b"")
            channel = w.register_channel("bench", "protobuf", schema)
            n, payload = 0, 0
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                data = msg_factory(n).SerializeToString()
                w.add_message(channel, log_time=n * 1_000_000, data=data, publish_time=n * 1_000_000)
                payload += len(data)
                n += 1
            w.finish()
            dt = time.perf_counter() - t0
        return payload / dt / 1e6, n / dt, path.stat().st_size


def write_rates(msg_factory, seconds: float, rounds: int = 2) -> tuple[tuple[float, float, int], tuple[float, float, int]]:
    """(humanpt's Recorder, the raw mcap Writer): each the best of ``rounds`` runs of
    ``seconds``, interleaved (the machine's load moves both alike)."""
    ours, raw = [], []
    for _ in range(rounds):
        ours.append(mcap_throughput(msg_factory, seconds))
        raw.append(raw_mcap_throughput(msg_factory, seconds))
    return max(ours), max(raw)


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
    baseline_mb_s: float | None = None  # the raw mcap Writer's, same messages, same run


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
    (mbps, rate, size), raw = write_rates(lambda k: imgs[k % len(imgs)], seconds)
    writes = [Throughput("images (zstd)", mbps, rate, size / max(1, rate * seconds * len(img_payload)), raw[0])]
    ev = pb.Event(header=header(1, 2, "world"), severity=2, source="bench", code="x", text="y" * 150)
    (mbps, rate, size), raw = write_rates(lambda k: ev, seconds)
    writes.append(Throughput("200-byte events (zstd)", mbps, rate, None, raw[0]))
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


# -- perception: humanpt against its baselines, measured interleaved ------------------------

PERCEPTION_SIZES = ((640, 480), (1920, 1200))
NAIVE = "naive OpenCV pipeline"
FLOOR = "memory floor: one read"
STAGE = "  tracking stage: "  # the tracking step's parts (no ratio: a share of tracking)


def naive_blob_centres(gray: np.ndarray, threshold: float = 60.0, count: int = 6) -> list[tuple[float, float]]:
    """The baseline a user would write instead of humanpt's perception: threshold the whole
    frame, ``cv2.connectedComponentsWithStats``, intensity-weighted centroids (u, v) of the
    ``count`` largest blobs (no background, no checks, no pairing)."""
    import cv2

    _, binary = cv2.threshold(gray, threshold, 255, cv2.THRESH_BINARY)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    out = []
    for i in np.argsort(stats[1:, cv2.CC_STAT_AREA])[::-1][:count] + 1:
        x, y, w, h = stats[i, :4]
        win = gray[y : y + h, x : x + w].astype(np.float64) * (labels[y : y + h, x : x + w] == i)
        total = win.sum()
        ys, xs = np.mgrid[y : y + h, x : x + w]
        out.append((float((win * xs).sum() / total), float((win * ys).sum() / total)))
    return out


def memory_floor(gray: np.ndarray) -> int:
    """The least any per-image work can cost: one read of every pixel (``np.max``, SIMD)."""
    return int(gray.max())


def tracking_sequence(width: int = 640, height: int = 480, n: int = 32, seed: int = 1):
    """(rig, images): ``n`` twin images of a slowly moving target (0.4 mm, 0.1 deg per image
    from a random pose at 450-900 mm; default noise), played forward then backward by the
    callers, so that a region of interest always holds. Another size than 640x480: the same
    optics (a_u = 1000 px) on a larger sensor, principal point at its centre."""
    import dataclasses

    from humanpt.geometry import transform_from_x, x_from_transform
    from humanpt.geometry.rig import Rig
    from humanpt.sim_camera import Renderer
    from humanpt.testing.perception_eval import random_cases

    case = random_cases(1, seed=seed)[0]
    psvs = dataclasses.replace(case.sim.psvs, image_width_px=width, image_height_px=height,
                               u0=width / 2.0, v0=height / 2.0)
    renderer = Renderer(dataclasses.replace(case.sim, psvs=psvs))
    x0 = x_from_transform(case.camera_T_tob)
    step = np.array([0.4, 0.3, 0.4, 0.1, 0.1, 0.1])
    images = [renderer.render(transform_from_x(x0 + k * step), frame_index=k) for k in range(n)]
    return Rig(psvs=psvs), images


def interleaved(cases: dict[str, Callable[[int], object]], n: int, rounds: int = 8,
                warmup: int = 20) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per case the ``n`` (CPU, wall) times (ns) of ``fn(k)``, k = 0 .. n-1, measured in
    ``rounds`` alternating blocks (case 1, case 2, ..., case 1, ...) so that a change of
    the machine's load hits every case alike; ``warmup`` untimed calls of each first. CPU =
    this thread's CPU time (``time.thread_time_ns``, less the clock's own cost): what the
    work costs, without the time other processes took the core away (on a shared machine
    that is most of the wall time of a millisecond call)."""
    for fn in cases.values():
        for k in range(min(warmup, n)):
            fn(k)
    cpu_clock, wall_clock = time.thread_time_ns, time.perf_counter_ns
    own = np.median([-(cpu_clock() - cpu_clock()) for _ in range(200)])  # the clock's cost
    times = {name: (np.empty(n), np.empty(n)) for name in cases}
    bounds = np.linspace(0, n, max(1, min(rounds, n)) + 1).astype(int)
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        for name, fn in cases.items():
            cpu, wall = times[name]
            for k in range(a, b):
                w0 = wall_clock()
                c0 = cpu_clock()
                fn(k)
                cpu[k] = cpu_clock() - c0
                wall[k] = wall_clock() - w0
    for cpu, _ in times.values():
        np.maximum(cpu - own, 1.0, out=cpu)
    return times


@dataclass(frozen=True)
class PerceptionRow:
    """One case: ``rate`` images/s = 1 / the median CPU time per image, ``cpu_ms`` that
    median, wall time p50 and p99 (ms), and ``ratio`` = its baseline's median CPU time /
    its own (> 1: faster than the baseline; None for a baseline)."""

    size: str
    method: str
    case: str
    rate: float
    cpu_ms: float
    p50_ms: float
    p99_ms: float
    baseline: str | None = None
    ratio: float | None = None


def perception_cases(rig, images, method: str = "weighted", baselines: bool = True,
                     stages: bool = False) -> dict[str, Callable[[int], object]]:
    """The timed cases on one image sequence (played forward, then backward): the
    baselines, the whole-image search, tracking (the windows around the blobs predicted
    from the previous image's measurement) and the core step (decode, checks, tracking or
    search, message) on a sequence of messages; with ``stages`` the tracking step's parts
    too (where its time goes: windows and detection, correspondence, blob checks)."""
    from humanpt.perception import Perception, PerceptionConfig, PerceptionCore
    from humanpt.perception.checks import check_sources
    from humanpt.perception.correspondence import FULL
    from humanpt.schemas.convert import image

    cfg = PerceptionConfig(method=method)
    p = Perception(cfg, rig)
    order = list(range(len(images))) + list(range(len(images) - 1, 0, -1))
    seq = [images[i] for i in order]
    m = len(seq)
    anchors = []
    for k in range(m):  # the previous image's FULL measurement predicts this one's blobs
        r = p.measure(seq[k - 1])
        if r.paired.status != FULL:
            raise RuntimeError(f"bench image {order[k - 1]} is not measured FULL ({r.paired.status})")
        used = r.paired.pairs.ravel()
        anchors.append((r.blobs.uv_px[used], r.blobs.size_px[used]))
    messages = [image(img, (k + 1) * 33_000_000) for k, img in enumerate(seq)]
    core = PerceptionCore(cfg, rig)
    cases: dict[str, Callable[[int], object]] = {}
    if baselines:
        cases[NAIVE] = lambda k: naive_blob_centres(seq[k % m], cfg.threshold)
        cases[FLOOR] = lambda k: memory_floor(seq[k % m])
    cases["search: whole image"] = lambda k: p.measure(seq[k % m])
    cases["tracking: windows around the blobs"] = lambda k: p.track(seq[k % m], *anchors[k % m])
    cases["core step (decode ... message)"] = lambda k: core.step(k, "camera/image", messages[k % m])
    if stages:  # the tracking step's parts, each on the previous part's output of that image
        found = [p.track_detect(seq[k], *anchors[k])[0] for k in range(m)]
        matches = [p.match(b) for b in found]
        cases[f"{STAGE}windows + detection"] = lambda k: p.track_detect(seq[k % m], *anchors[k % m])
        cases[f"{STAGE}correspondence"] = lambda k: p.match(found[k % m])
        cases[f"{STAGE}blob checks"] = lambda k: check_sources(found[k % m], matches[k % m], p.params, p.model,
                                                                p.check_settings)
    return cases


def measure_perception(n_images: int, sizes=PERCEPTION_SIZES, paper: bool = True,
                       rounds: int = 8) -> list[PerceptionRow]:
    """humanpt's perception and its baselines (:func:`naive_blob_centres`,
    :func:`memory_floor`) on twin image sequences (:func:`tracking_sequence`) of each size,
    ``n_images`` per case, every case of one size interleaved (:func:`interleaved`), rates
    and ratios from the median CPU time per image.
    Ratios: tracking to the whole-image search, every other humanpt case to the naive
    pipeline; the paper method's (640x480 only) to the same naive pipeline; the tracking
    step's stages (the first size only) have none."""
    n = max(1, n_images)
    rows: list[PerceptionRow] = []
    for width, height in sizes:
        rig, images = tracking_sequence(width, height)
        first = (width, height) == tuple(sizes[0])
        cases = {("weighted", name): fn for name, fn in perception_cases(rig, images, stages=first).items()}
        if paper and first:
            cases.update({("paper", name): fn for name, fn in perception_cases(rig, images, "paper", False).items()})
        times = interleaved({f"{m}|{c}": fn for (m, c), fn in cases.items()}, n, rounds)
        med = {key: float(np.median(cpu)) for key, (cpu, _) in times.items()}
        for (method, case), (key, (_, wall)) in zip(cases, times.items(), strict=True):
            base = None if case in (NAIVE, FLOOR) or case.startswith(STAGE) else (
                "search: whole image" if case.startswith("tracking") else NAIVE)
            base_key = f"{method}|{base}" if base != NAIVE else f"weighted|{NAIVE}"
            rows.append(PerceptionRow(
                f"{width}x{height}", "-" if case in (NAIVE, FLOOR) else method, case, 1e9 / med[key], med[key] / 1e6,
                float(np.percentile(wall, 50)) / 1e6, float(np.percentile(wall, 99)) / 1e6, base,
                None if base is None else med[base_key] / med[key]))
    return rows


def perception_accuracy(images: int, seed: int) -> dict:
    """Both methods' accuracy on twin images with ground truth: {set name: evaluation},
    ``images`` per set (a quarter of it at each end of the working range)."""
    from humanpt.testing.perception_eval import SETS, cases_for, evaluate, range_cases

    results = {name: evaluate(cases_for(name, images, seed)) for name in SETS if name != "range"}
    for z in (250.0, 350.0, 1200.0, 1800.0):  # the ends of the working range, one row each
        results[f"z={z:.0f}mm"] = evaluate(range_cases(images // 4, seed, (z,)))
    return results
