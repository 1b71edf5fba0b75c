"""``humanpt demo``: the whole system on the digital twin, and its accuracy against ground truth.

Live (default): the router, sim_robot behind a pty, alter_gateway, operator, sim_camera,
perception, pose_filter and controller (and viz with ``--viewer``) as separate processes
over Zenoh.  ``--lockstep``: the same cores in one process on virtual time.  Either way
every component records its MCAP in the run directory, the path is written as CSV, and an
accuracy table against ground truth is printed.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.geometry.transforms import (
    invert_transform,
    transform_from_x,
    x_from_transform,
)
from humanpt.runtime.config import to_table

LIVE_COMPONENTS = ("sim_robot", "alter_gateway", "sim_camera", "perception", "pose_filter", "controller")


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to TOML")


def parse_overrides(items: list[str] | None) -> dict[str, dict]:
    """``--set SECTION.KEY=VALUE`` items -> {section: {key: value}}; VALUE is a TOML value
    (a bare word that is not TOML is taken as a string); ``SECTION.SUB.KEY`` nests a table
    (e.g. ``sim_camera.psvs.image_width_px=320``)."""
    import tomllib

    out: dict[str, dict] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        parts = key.strip().split(".")
        if not sep or len(parts) < 2 or not all(parts):
            raise SystemExit(f"humanpt demo: --set {item!r}: expected SECTION.KEY=VALUE, e.g. sim_camera.fps=15")
        try:
            value = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw
        table = out.setdefault(parts[0], {})
        for p in parts[1:-1]:
            table = table.setdefault(p, {})
        table[parts[-1]] = value
    return out


def write_toml(path: Path, sections: dict[str, dict]) -> None:
    lines = ["# written by humanpt demo: the configuration of this run", ""]
    for name, table in sections.items():
        lines.append(f"[{name}]")
        for k, v in table.items():
            if v is None or (isinstance(v, (list, tuple)) and v and isinstance(v[0], dict)):
                continue
            if isinstance(v, dict):
                continue
            lines.append(f"{k} = {_toml_value(v)}")
        lines.append("")
        for k, v in table.items():
            if isinstance(v, dict):  # a nested config table, e.g. [sim_camera.psvs]
                lines.append(f"[{name}.{k}]")
                lines += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items() if vv is not None]
                lines.append("")
    path.write_text("\n".join(lines))


def report(src, ctl: ControllerConfig, run_dir: Path, wall_s: float, sim_s: float, mode: str,
           stop_ns: int | None = None) -> str:
    """The accuracy table against ground truth (:func:`humanpt.twin.run.accuracy`), and
    where things are. Warnings stamped after ``stop_ns`` (the processes being stopped: e.g.
    the gateway seeing the controller go) are counted apart."""
    from humanpt.twin import evaluate
    from humanpt.twin.run import accuracy

    acc = accuracy(src, ctl, stop_ns)
    if mode == "live":
        lines = [f"humanpt demo (live): {sim_s:.1f} s of scenario, {wall_s:.1f} s of wall time with start-up", ""]
    else:
        lines = [f"humanpt demo ({mode}): {sim_s:.1f} s of twin time in {wall_s:.1f} s of wall time "
                 f"({sim_s / max(wall_s, 1e-9):.1f}x real time)", ""]
    lines.append(evaluate.format_stats(f"recorded path of {acc.which} against ground truth", acc.path))
    if len(acc.servo_mm):
        lines += ["", f"servo error |G - D| while the target moved: mean {acc.servo_mm.mean():.3f} mm, "
                  f"max {acc.servo_mm.max():.3f} mm; angle mean {acc.servo_deg.mean():.3f} deg, "
                  f"max {acc.servo_deg.max():.3f} deg"]
    if acc.warnings:
        lines += ["", f"{len(acc.warnings)} warnings/errors, e.g.: "
                  + "; ".join(f"{e.source}: {e.code}" for e in acc.warnings[:5])]
    else:
        lines += ["", "no warnings or errors during the run"]
    if acc.stopping:
        lines.append(f"(while stopping: {len(acc.stopping)}, e.g. "
                     + "; ".join(f"{e.source}: {e.code}" for e in acc.stopping[:3]) + ")")
    paths = sorted((run_dir / "paths").glob("*.csv"))
    lines += ["", f"recordings: {run_dir}/*.mcap  (humanpt replay {run_dir}; humanpt view {run_dir})"]
    if paths:
        lines.append(f"path file:  {paths[-1]}")
    return "\n".join(lines)


def _progress(now_s: float, duration_s: float) -> None:
    print(f"\r  {now_s:5.1f} / {duration_s:.1f} s", end="", file=sys.stderr, flush=True)


def run_lockstep(args, cfg, run_dir: Path) -> int:
    from humanpt.twin.run import run

    # Record once the target starts to move (the servo has acquired it by then).
    res = run(cfg, robot=args.robot, duration_s=args.duration or None, record_from_s=cfg.operator.start_delay_s,
              run_dir=run_dir, progress=_progress)
    print(file=sys.stderr)
    res.write_path(run_dir / "paths" / "path-1.csv")
    print(report(res.world, cfg.controller, run_dir, res.wall_s, res.twin_s, "lock-step"))
    return 0


def _wait_alive(cfg_path: Path, names: tuple[str, ...], timeout_s: float, procs) -> bool:
    from humanpt.cli.commands import _open_session
    from humanpt.runtime import config as cfgmod
    from humanpt.runtime.bus import liveliness_key

    cfg = cfgmod.load(cfg_path)
    deadline = time.monotonic() + timeout_s
    with _open_session(cfg) as s:
        while time.monotonic() < deadline:
            if any(p.poll() is not None for _, p in procs):
                return False
            alive = {str(r.ok.key_expr).rsplit("/", 1)[-1]
                     for r in s.liveliness().get(liveliness_key(cfg.runtime.cell, "*")) if r.ok is not None}
            if set(names) <= alive:
                return True
            time.sleep(0.3)
    return False


def _lower_priority(pid: int) -> None:
    """A lower scheduling priority for a child (POSIX; a no-op elsewhere)."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, 10)
    except (AttributeError, OSError):
        pass


def run_live(args, cfg, run_dir: Path) -> int:
    from humanpt.cli.commands import _open_session
    from humanpt.runtime import config as cfgmod
    from humanpt.runtime.bus import free_tcp_port
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import header
    from humanpt.twin.evaluate import RunOutputs
    from humanpt.twin.system import puma_cores
    from humanpt.twin.world import start_flange_for

    port = args.port or free_tcp_port()
    over = parse_overrides(getattr(args, "set", None))
    op, ctl, cam = cfg.operator, cfg.controller, cfg.sim_camera
    start = start_flange_for(op, ctl.dz_mm, cam.flange_T_camera)
    robot, gateway = puma_cores(start)
    pty = str(run_dir / "alter.pty")
    start_in_base = invert_transform(transform_from_x(np.asarray(robot.world_T_base_mm_deg))) @ start
    robot = dataclasses.replace(robot, pty_link=pty,
                                start_pose_mm_deg=tuple(float(v) for v in x_from_transform(start_in_base)))
    # A pty delivers a STATUS at once (no 38 400 baud line time): its pose is for "now".
    gateway = dataclasses.replace(gateway, port=pty, status_delay_ms=0.0)
    # The operator starts with the rest (its start-up must not fall into the running servo
    # loop: on two cores that delayed ALTER statuses by ~85 ms) and holds the start pose
    # while everything comes up and the servo settles.
    op = dataclasses.replace(op, start_delay_s=3.0)
    cfg_path = run_dir / "humanpt.toml"
    sections = {
        "runtime": {"cell": "demo", "connect": [f"tcp/127.0.0.1:{port}"], "listen": [f"tcp/127.0.0.1:{port}"],
                    "run_dir": str(run_dir), "connect_timeout_s": 30.0, "record_thread": True, "mode": "peer"},
        "operator": to_table(op), "sim_robot": to_table(robot), "alter_gateway": to_table(gateway),
        "sim_camera": to_table(cam), "controller": to_table(ctl),
    }
    if "psvs" not in over.get("sim_camera", {}):
        sections["sim_camera"].pop("psvs", None)
    # Other components' overrides (validated in cfg): only the keys given, so the defaults
    # stay theirs.
    for name in ("perception", "pose_filter"):
        if over.get(name):
            sections[name] = over[name]
    write_toml(cfg_path, sections)
    cfgmod.load(cfg_path)  # fail here, clearly, if the written config does not validate
    comps = list(LIVE_COMPONENTS) + (["viz"] if args.viewer else [])
    base = [sys.executable, "-m", "humanpt.cli.main"]
    procs: list[tuple[str, subprocess.Popen]] = []
    log = open(run_dir / "processes.log", "w")  # noqa: SIM115 - closed below
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *a: stop.set())
    duration = args.duration or dataclasses.replace(cfg, operator=op).default_duration_s()
    failed = []
    t0 = time.perf_counter()
    try:
        procs.append(("router", subprocess.Popen(base + ["router", "--config", str(cfg_path)], stdout=log,
                                                 stderr=subprocess.STDOUT)))
        time.sleep(0.5)
        for name in comps + ["operator"]:
            p = subprocess.Popen(base + [name, "--config", str(cfg_path), "--run-dir", str(run_dir)],
                                 stdout=log, stderr=subprocess.STDOUT)
            if name == "operator":
                # The simulated operator (a stand-in for the human, not part of the system)
                # runs at a lower priority.
                _lower_priority(p.pid)
            procs.append((name, p))
        print(f"humanpt demo: starting {', '.join(comps)}, operator (log: {run_dir / 'processes.log'})", flush=True)
        if not _wait_alive(cfg_path, tuple(comps) + ("operator",), 60.0, procs):
            failed.append("the components did not all come up within 60 s")
            return 1
        t_start = time.monotonic()
        cfg = cfgmod.load(cfg_path)
        with _open_session(cfg) as s:
            pub = s.declare_publisher("humanpt/demo/console/command")
            recording = False
            while not stop.wait(0.2):
                el = time.monotonic() - t_start
                print(f"\r  {el:5.1f} / {duration + 1.0:.1f} s", end="", file=sys.stderr, flush=True)
                # Record from a second after everything is up: the operator, which came up
                # with the rest, holds the start pose for start_delay_s, so the path begins
                # with it still whatever the order the processes came up in.
                if not recording and el >= 1.0:
                    pub.put(pb.Command(header=header(time.time_ns()), component="controller",
                                       verb="record_start").SerializeToString())
                    recording = True
                if el >= duration + 1.0:
                    break
                dead = [(n, p.returncode) for n, p in procs if p.poll() is not None]
                if dead:
                    failed += [f"{n} exited with {rc}" for n, rc in dead]
                    break
            pub.undeclare()
        print(file=sys.stderr)
    finally:
        stop_ns = time.time_ns()
        for _, p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for _, p in reversed(procs):
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
        log.close()
    wall = time.perf_counter() - t0
    if failed:
        print(f"humanpt demo: stopped early: {'; '.join(failed)} (see {run_dir / 'processes.log'})", file=sys.stderr)
        return 1
    print(report(RunOutputs(run_dir), ctl, run_dir, wall, duration, "live", stop_ns=stop_ns))
    return 0


def demo(args) -> int:
    from humanpt.cli.commands import run_stamp
    from humanpt.twin.run import SECTIONS, OverrideError, SystemConfig

    over = parse_overrides(getattr(args, "set", None))
    unknown = set(over) - set(SECTIONS)
    if unknown:
        raise SystemExit(f"humanpt demo: --set: no section {sorted(unknown)[0]!r} ({', '.join(SECTIONS)})")
    try:  # a bad key or value fails here, before the run starts
        cfg = SystemConfig.for_scenario(args.scenario, args.seed, over, controller=ControllerConfig(law=args.law))
    except OverrideError as e:
        raise SystemExit(f"humanpt: {e}") from None
    label = Path(args.scenario).stem if Path(args.scenario).suffix else args.scenario
    run_dir = Path(args.run_dir) if args.run_dir else Path("runs") / f"{run_stamp()}-demo-{label}"
    run_dir.mkdir(parents=True, exist_ok=True)
    print(f"humanpt demo: scenario {label}, {'lock-step' if args.lockstep else 'live'}, recording to {run_dir}/",
          flush=True)
    if args.lockstep:
        return run_lockstep(args, cfg, run_dir)
    return run_live(args, cfg, run_dir)
