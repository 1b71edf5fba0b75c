"""``humanpt bench`` (no sub-verb): the figures that matter, measured now (the CLI prints
them as one table).

* perception: images/s of the default method's core step on 640x480 twin images, one core;
* lock-step: the closed loop on virtual time, in x real time (with and without recording);
* a live run of the whole system (:func:`humanpt.twin.live.run_live`, as ``humanpt demo``
  runs it: every component a process over Zenoh):
  image-to-command latency (capture stamp to the controller's first command using it) and
  where it goes, hop by hop (:func:`latency_chain`),
  ALTER cycles answered on time (a command of that cycle within the gateway's deadline);
* replay of that run's recordings, in x real time;
* MCAP write throughput with the default compression.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def perception_rate(n: int = 300) -> float:
    """Images/s of the default method's core step on 640x480 twin images, cv2 on one thread."""
    import cv2

    from humanpt.perception import PerceptionConfig, PerceptionCore
    from humanpt.schemas.convert import image
    from humanpt.sim_camera import Renderer
    from humanpt.testing.perception_eval import random_cases

    cv2.setNumThreads(1)
    cases = random_cases(16, seed=1)
    renderer = Renderer(cases[0].sim)
    msgs = [image(renderer.render(c.camera_T_tob, frame_index=c.frame_index), (k + 1) * 33_000_000)
            for k, c in enumerate(cases)]
    core = PerceptionCore(PerceptionConfig())
    for k in range(20):
        core.step(k, "camera/image", msgs[(k // 4) % len(msgs)])
    t0 = time.perf_counter()
    for k in range(n):
        core.step(k, "camera/image", msgs[(k // 4) % len(msgs)])
    return n / (time.perf_counter() - t0)


@dataclass(frozen=True)
class LockstepSpeed:
    """The closed loop on the lock-step twin: ``speed`` x real time (wall), ``cores_alone``
    x real time had the loop's thread done nothing but the cores' steps (the baseline the
    scheduler, codecs and recorders are measured against), ``cpu_s`` where the CPU went
    (:func:`humanpt.twin.run.run`'s ``account``) and ``twin_s``."""

    speed: float
    cores_alone: float
    cpu_s: dict[str, float]
    twin_s: float

    def share_rows(self) -> list[tuple[str, str]]:
        """(part, "x.x % (y.yy ms per twin-second)"), largest first: each core's step, then
        decode, encode, record, schedule and the other threads (the recorders' writers)."""
        total = sum(self.cpu_s.values())
        rows = sorted(self.cpu_s.items(), key=lambda kv: -kv[1])
        return [(k, f"{100 * v / total:4.1f} % ({1e3 * v / self.twin_s:.1f} ms per twin-second)") for k, v in rows]


def lockstep_speed(seconds: float, record: bool) -> LockstepSpeed:
    """The closed loop on the lock-step twin (arc, the simulated Puma), ``seconds`` of twin
    time, every core recorded or not (:func:`humanpt.twin.run.run`), its CPU accounted."""
    from humanpt.runtime.lockstep import Lockstep
    from humanpt.twin.run import SystemConfig, run

    with tempfile.TemporaryDirectory() as d:
        # As humanpt demo --lockstep runs it (no output digest), without keeping outputs.
        res = run(SystemConfig.for_scenario("arc", 0), robot="puma", duration_s=seconds,
                  run_dir=d if record else None, keep_outputs=False, account=True)
    parts = {*Lockstep.PARTS, "other threads"}
    in_cores = sum(v for k, v in res.cpu_s.items() if k not in parts)
    return LockstepSpeed(res.speed, res.twin_s / max(in_cores, 1e-9), dict(res.cpu_s), res.twin_s)


def latency_and_cycles(run_dir: Path, deadline_ms: float = 6.0) -> dict:
    """From a live run's recordings: image-to-command latencies (ms) and ALTER cycles on time."""
    from humanpt.runtime.recording import iter_entries
    from humanpt.schemas import humanpt_pb2 as pb

    lat = []
    seen = set()
    for e in iter_entries(run_dir / "controller.mcap"):
        if e.direction == "out" and e.topic == "controller/command":
            cmd = pb.FlangeCommand.FromString(e.data)
            m = cmd.measurement_stamp_ns
            if m and m not in seen:  # the first command that uses this image
                seen.add(m)
                lat.append((e.t_ns - m) / 1e6)
    commands: dict[int, int] = {}
    states: list[tuple[int, int, int]] = []
    for e in iter_entries(run_dir / "robot_gateway.mcap"):
        if e.direction == "in" and e.topic == "controller/command":
            c = pb.FlangeCommand.FromString(e.data).cycle
            commands.setdefault(c, e.t_ns)
        elif e.direction == "out" and e.topic == "robot_gateway/robot_state":
            st = pb.RobotState.FromString(e.data)
            states.append((st.cycle, e.t_ns, st.missed_cycles))
    # Judge the cycles after the servo started commanding (the first command).
    first = min(commands) if commands else None
    judged = [(c, t) for c, t, _ in states if first is not None and c >= first]
    on_time = sum(1 for c, t in judged if c in commands and commands[c] - t <= deadline_ms * 1e6)
    return {"latency_ms": np.array(lat), "cycles": len(judged), "on_time": on_time}


# Where an image's time goes on its way to a command (issue 37 item 3), hop by hop, from the
# recordings: each process records an input at the time it took it off the bus, so the time
# from one process's receipt to the next one's is the first one's work plus one bus hop.
CHAIN = (
    ("capture -> perception has the image", "the camera's read-out (twin: render), encode, one bus hop"),
    ("perception -> pose filter has the measurement", "perception's work, one bus hop"),
    ("pose filter -> controller has the estimate", "the wait for the robot's pose at the image (the next "
     "robot state after it), the filter's work, one bus hop"),
    ("controller -> its command out", "the wait for the robot cycle the command answers, the servo law"),
    ("command out -> gateway has it", "one bus hop"),
)


def latency_chain(run_dir: Path) -> dict[str, np.ndarray]:
    """Per image of a live run (its capture stamp S), the time in ms of each hop of
    :data:`CHAIN`, from the recordings of perception, pose_filter, controller and
    robot_gateway (one machine, one clock): S to perception's receipt of the image; to the
    pose filter's receipt of its measurement; to the controller's receipt of the first
    estimate made from it; to the first command built on it (``measurement_stamp_ns``); to
    the gateway's receipt of that command.  Only the images that went all the way; the
    hops of one image add up to its image-to-gateway time.  Empty arrays when none did."""
    from humanpt.runtime.recording import iter_entries

    def first_by(file: str, direction: str, topic: str, stamp) -> dict[int, int]:
        out: dict[int, int] = {}
        path = run_dir / file
        if not path.exists():
            return out
        for e in iter_entries(path):
            if e.direction == direction and e.topic == topic:
                s = stamp(e.decode())
                if s and s not in out:
                    out[s] = e.t_ns
        return out

    seen = [
        first_by("perception.mcap", "in", "camera/image", lambda m: m.timestamp.ToNanoseconds()),
        first_by("pose_filter.mcap", "in", "perception/tob", lambda m: m.header.stamp_ns),
        first_by("controller.mcap", "in", "pose_filter/tob_state", lambda m: m.measurement_stamp_ns),
        first_by("controller.mcap", "out", "controller/command", lambda m: m.measurement_stamp_ns),
        first_by("robot_gateway.mcap", "in", "controller/command", lambda m: m.measurement_stamp_ns),
    ]
    stamps = sorted(set.intersection(*(set(d) for d in seen))) if all(seen) else []
    t = np.array([[s] + [d[s] for d in seen] for s in stamps], dtype=np.int64).reshape(-1, 1 + len(seen))
    hops = np.diff(t, axis=1) / 1e6
    return {name: hops[:, i] for i, (name, _) in enumerate(CHAIN)}


def chain_rows(chain: dict[str, np.ndarray]) -> list[list[str]]:
    """:func:`latency_chain` as table rows: hop, p50 ms, p99 ms, share of the p50 total,
    what it is."""
    total = sum(float(np.median(v)) for v in chain.values() if len(v)) or 1.0
    rows = []
    for name, what in CHAIN:
        v = chain.get(name, np.array([]))
        if not len(v):
            rows.append([name, "-", "-", "-", what])
            continue
        p50 = float(np.median(v))
        rows.append([name, f"{p50:.2f}", f"{np.percentile(v, 99):.2f}", f"{100 * p50 / total:.0f} %", what])
    return rows


@dataclass
class BridgeCost:
    """Image-to-command latencies (ms) of live runs without and with the Foxglove bridge
    (:func:`bridge_cost`), each pooled over its rounds."""

    without_ms: np.ndarray
    with_ms: np.ndarray
    rounds: int
    seconds: float

    def rows(self) -> list[list[str]]:
        """Table rows: condition, images, p50, p99 (ms), each against the run without."""
        base = (float(np.median(self.without_ms)), float(np.percentile(self.without_ms, 99)))
        out = []
        for name, v in (("without the bridge", self.without_ms), ("with the bridge", self.with_ms)):
            p50, p99 = float(np.median(v)), float(np.percentile(v, 99))
            out.append([name, str(len(v)), f"{p50:.2f}", f"{p50 / base[0]:.3f}", f"{p99:.2f}", f"{p99 / base[1]:.3f}"])
        return out


def bridge_cost(seconds: float = 20.0, rounds: int = 2, scenario: str = "arc",
                say: Callable[[str], None] | None = None) -> BridgeCost:
    """What the Foxglove bridge costs the live loop (issue 36): the demo's live run of
    ``scenario`` (:func:`humanpt.twin.live.run_live`) for ``seconds``, without the bridge then
    with it, ``rounds`` times alternated (so a change of the machine's load falls on both);
    the image-to-command latencies of each condition pooled.  The bridge takes every bus
    topic at its configured rates whether or not a browser is connected; a connected
    browser's WebSocket sending is not in these runs.  RuntimeError when a run fails."""
    from humanpt.twin.live import run_live
    from humanpt.twin.run import SystemConfig

    got: dict[bool, list[np.ndarray]] = {False: [], True: []}
    for r in range(rounds):
        for with_bridge in (False, True):
            if say:
                say(f"round {r + 1}/{rounds}: {seconds:g} s live, {'with' if with_bridge else 'without'} the bridge")
            with tempfile.TemporaryDirectory() as d:
                run_dir = Path(d)
                live = run_live(SystemConfig.for_scenario(scenario, 0), run_dir, duration_s=seconds,
                                bridge=with_bridge)
                if live.failed:
                    raise RuntimeError("; ".join(live.failed) + "\n" + (run_dir / "processes.log").read_text()[-2000:])
                got[with_bridge].append(latency_and_cycles(run_dir)["latency_ms"])
    return BridgeCost(np.concatenate(got[False]), np.concatenate(got[True]), rounds, seconds)


@dataclass
class Figure:
    """One figure of the table: its name, value and a note (a target, a sample size)."""

    name: str
    value: str
    note: str = ""


def measure_all(live_seconds: float, lockstep_seconds: float, scenario: str,
                on_figure: Callable[[Figure], None] | None = None) -> tuple[list[Figure], float, str]:
    """Every figure, in order: (figures, wall seconds of the live part, what went wrong in
    the live run or ''). ``on_figure`` is called as each is measured."""
    figures: list[Figure] = []

    def show(name, value, note=""):
        figures.append(Figure(name, value, note))
        if on_figure is not None:
            on_figure(figures[-1])

    failure = ""
    show("perception, default method (core step, 640x480, one core)", f"{perception_rate():.0f} images/s",
         "target >= 500")
    for record, name in ((False, "lock-step closed loop, no recording"),
                         (True, "lock-step closed loop, recorded (humanpt demo --lockstep)")):
        ls = lockstep_speed(lockstep_seconds, record)
        show(name, f"{ls.speed:.1f}x real time",
             f"{ls.speed / ls.cores_alone:.2f} of the cores alone ({ls.cores_alone:.1f}x real time)")
        if record:  # where the recorded loop's CPU goes
            for part, share in ls.share_rows():
                show(f"  {part}", share)
    with tempfile.TemporaryDirectory() as d:
        from humanpt.twin.live import run_live
        from humanpt.twin.run import SystemConfig

        run_dir = Path(d) / "live"
        run_dir.mkdir()
        t0 = time.perf_counter()
        # As humanpt demo --scenario SCENARIO --duration LIVE_SECONDS runs it.
        live = run_live(SystemConfig.for_scenario(scenario, 0), run_dir, duration_s=live_seconds)
        if live.failed:
            failure = "; ".join(live.failed) + "\n" + (run_dir / "processes.log").read_text()[-2000:]
            show("live demo", "FAILED", live.failed[0])
        else:
            res = latency_and_cycles(run_dir)
            lat = res["latency_ms"]
            if len(lat):
                show("image-to-command latency through Zenoh, p50", f"{np.percentile(lat, 50):.2f} ms",
                     f"(n = {len(lat)})")
                show("image-to-command latency through Zenoh, p99", f"{np.percentile(lat, 99):.2f} ms",
                     "target <= 10 ms")
            chain = latency_chain(run_dir)
            for name, p50, p99, share, _what in chain_rows(chain):
                show(f"  {name}", f"{p50} ms" if p50 != "-" else p50, f"p99 {p99} ms, {share} of the median chain")
            show(f"ALTER cycles answered on time ({live_seconds:g} s live demo)",
                 f"{res['on_time']} / {res['cycles']}", "target: all")
            from humanpt.runtime.replay import replay

            t1 = time.perf_counter()
            ok = all(replay(f).match for f in sorted(run_dir.glob("*.mcap")))
            dt = time.perf_counter() - t1
            show("replay of every component of that run", f"{live_seconds / dt:.1f}x real time",
                 "outputs identical" if ok else "MISMATCH")
        wall = time.perf_counter() - t0
    from humanpt.bench.measure import synthetic_image, write_rates
    from humanpt.schemas.convert import image

    imgs = [image(synthetic_image(seed=s), s) for s in range(8)]
    (mbps, rate, _), raw = write_rates(lambda n: imgs[n % len(imgs)], 1.0)
    show("MCAP write, 640x480 images, zstd", f"{mbps:.0f} MB/s",
         f"({rate:.0f} images/s; {mbps / raw[0]:.2f}x the raw mcap Writer, {raw[0]:.0f} MB/s)")
    return figures, wall, failure
