"""``humanpt bench ...``: benchmarks that print a table.  Nothing here is asserted."""

from __future__ import annotations

import tempfile
import threading
import time
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


def bench_runtime(args) -> int:
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import header, image

    print("humanpt bench runtime (loopback, router and both clients in one process; medians of noisy "
          "shared machines: compare ratios)", flush=True)
    rows = []
    small = bytes(range(200))
    img = synthetic_image()
    img_payload = image(img, 0).SerializeToString()
    for label, payload in (("200-byte message", small), (f"640x480 mono8 image ({len(img_payload)} B)", img_payload)):
        rtts = round_trips(payload, args.n, free_tcp_port())
        if not rtts:
            rows.append((f"round trip, {label}", "no replies", "", ""))
            continue
        rows.append((f"round trip, {label}", f"{percentile_ms(rtts, 50):.3f} ms", f"{percentile_ms(rtts, 99):.3f} ms",
                     f"n={len(rtts)}"))
        print(f"  measured {label}", flush=True)
    imgs = [image(synthetic_image(seed=s), s) for s in range(8)]
    mbps, rate, size = mcap_throughput(lambda n: imgs[n % len(imgs)], args.seconds)
    rows.append(("MCAP write, images (zstd)", f"{mbps:.1f} MB/s", f"{rate:.0f} msg/s",
                 f"file/payload {size / max(1, rate * args.seconds * len(img_payload)):.2f}"))
    ev = pb.Event(header=header(1, 2, "world"), severity=2, source="bench", code="x", text="y" * 150)
    mbps, rate, size = mcap_throughput(lambda n: ev, args.seconds)
    rows.append(("MCAP write, 200-byte events (zstd)", f"{mbps:.1f} MB/s", f"{rate:.0f} msg/s", ""))
    w = max(len(r[0]) for r in rows)
    print(f"\n{'case':{w}s}  {'p50 / rate':>12s}  {'p99 / msgs':>12s}  note")
    for r in rows:
        print(f"{r[0]:{w}s}  {r[1]:>12s}  {r[2]:>12s}  {r[3]}")
    return 0


def bench_render(args) -> int:
    """Frames per second of the simulated PSVS camera at its default settings."""
    from humanpt.geometry import camera_T_desired
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import header, pose
    from humanpt.sim_camera import Renderer, SimCameraConfig, SimCameraCore

    n = max(1, args.frames)
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
    print(f"humanpt bench render: {cfg.psvs.image_width_px}x{cfg.psvs.image_height_px}, 3 sources x 2 views at "
          f"600 mm, blur {cfg.blur_sigma_px} px, shot + read noise; {n} frames per case")
    print(f"\n{'case':34s} {'frames/s':>10s} {'ms/frame':>10s}")
    print(f"{'render (renderer alone)':34s} {n / total:10.0f} {1e3 * total / n:10.3f}")
    for name, t in stages.items():
        print(f"{'  ' + name:34s} {'':>10s} {1e3 * t / n:10.3f}")
    print(f"{'sim_camera core step (+ message)':34s} {n / core_total:10.0f} {1e3 * core_total / n:10.3f}")
    return 0


def bench_perception(args) -> int:
    """Images per second of each perception method on 640x480 twin images, on one core; and
    (unless ``--no-accuracy``) both methods' accuracy on twin images with ground truth."""
    import os

    import cv2

    from humanpt.perception import Perception, PerceptionConfig, PerceptionCore
    from humanpt.schemas.convert import image
    from humanpt.sim_camera import Renderer
    from humanpt.testing.perception_eval import (
        SETS,
        cases_for,
        evaluate,
        format_table,
        random_cases,
        range_cases,
    )

    cv2.setNumThreads(1)
    pinned = ""
    if hasattr(os, "sched_setaffinity"):
        try:
            os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
            pinned = ", pinned to one CPU"
        except OSError:
            pass
    n = max(1, args.images)
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
    print(f"humanpt bench perception: 640x480 twin images (random poses, 450-900 mm, default noise), "
          f"{n} per case, cv2 threads 1{pinned}")
    print(f"\n{'method':9s} {'case':32s} {'images/s':>9s} {'p50 ms':>8s} {'p99 ms':>8s}")
    for method, case, rate, p50, p99 in rows:
        print(f"{method:9s} {case:32s} {rate:9.0f} {p50:8.3f} {p99:8.3f}")
    if not args.no_accuracy:
        print(f"\naccuracy on twin images with ground truth ({args.accuracy_images} per set, seed {args.seed}; "
              "bound: geometry error model at the measured centre RMS):\n")
        results = {name: evaluate(cases_for(name, args.accuracy_images, args.seed)) for name in SETS if name != "range"}
        for z in (250.0, 350.0, 1200.0, 1800.0):  # the ends of the working range, one row each
            results[f"z={z:.0f}mm"] = evaluate(range_cases(args.accuracy_images // 4, args.seed, (z,)))
        print(format_table(results))
    return 0


def bench_alter(args) -> int:
    """alter_gateway <-> sim_robot over a real pty (see ``humanpt.bench.alter``)."""
    from humanpt.bench.alter import bench_alter as run

    periods = tuple(float(p) for p in args.periods.split(",") if p.strip())
    run(args.duration, periods, args.search_seconds, "zenoh" if args.zenoh else "threads")
    return 0
