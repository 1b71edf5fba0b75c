"""The demo on the twin from Python (``humanpt demo`` parses its arguments and prints what
these return): the system's configuration for a scenario, a run live or in lock-step, and
the accuracy report against ground truth.

    from humanpt.twin.demo import demo_config, run_live_demo
    cfg = demo_config("arc", seed=0)
    res, text = run_live_demo(cfg, "runs/arc", duration_s=10)
"""

from __future__ import annotations

import threading
import tomllib
from collections.abc import Callable
from pathlib import Path

from humanpt.runtime import config as cfgmod

from .run import SystemConfig


def parse_overrides(items: list[str] | tuple[str, ...] | None) -> dict[str, dict]:
    """``SECTION.KEY=VALUE`` items -> {section: {key: value}}; VALUE is a TOML value (a bare
    word that is not TOML is taken as a string); ``SECTION.SUB.KEY`` nests a table (e.g.
    ``sim_camera.psvs.image_width_px=320``).  ValueError naming a malformed item."""
    out: dict[str, dict] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        parts = key.strip().split(".")
        if not sep or len(parts) < 2 or not all(parts):
            raise ValueError(f"--set {item!r}: expected SECTION.KEY=VALUE, e.g. sim_camera.fps=15")
        try:
            value = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw
        table = out.setdefault(parts[0], {})
        for p in parts[1:-1]:
            table = table.setdefault(p, {})
        table[parts[-1]] = value
    return out


def scenario_label(scenario: str) -> str:
    """A scenario's name in run directories: a built-in's name, a file's stem."""
    return Path(scenario).stem if Path(scenario).suffix else scenario


def demo_config(scenario: str, seed: int = 0, overrides: dict[str, dict] | None = None, *,
                world: str = "ideal", rig_file: str | Path | None = None, law: str = "thetau",
                rig_kind: str = "psvs") -> SystemConfig:
    """The twin's system for ``scenario`` (a built-in name or a scenario file): ``world``
    (ideal, realistic, ideal+SOURCE..., a world file), the pipeline's rig ``rig_file``
    (default nominal), the servo ``law``, ``overrides`` {section: {key: value}} of the
    twin's sections; ``rig_kind`` "stereo": an ordinary stereo pair (the world's camera
    renders the PSVS's virtual cameras apart; the pipeline's rig is the same pair as its
    rig's PSVS makes it, unless the rig file is of kind stereo already).  A bad key, value,
    world or rig fails here (ValueError, ConfigError)."""
    from humanpt.controller.config import ControllerConfig
    from humanpt.runtime.rigfile import load_rig

    from .run import SECTIONS
    from .worlds import World

    unknown = set(overrides or {}) - set(SECTIONS)
    if unknown:
        raise ValueError(f"--set: no section {sorted(unknown)[0]!r} ({', '.join(SECTIONS)})")
    rig = load_rig(rig_file) if rig_file else None
    cfg = SystemConfig.for_scenario(scenario, seed, overrides or {}, rig=rig, world=World.named(world),
                                    controller=ControllerConfig(law=law))
    return with_rig_kind(cfg, rig_kind)


RIG_KINDS = ("psvs", "stereo")


def with_rig_kind(cfg: SystemConfig, rig_kind: str) -> SystemConfig:
    """``cfg`` as it runs with a camera of ``rig_kind``: "psvs" unchanged; "stereo" an
    ordinary stereo pair (the world's camera renders the PSVS's virtual cameras apart, so an
    error source of the world's PSVS becomes the pair's; the pipeline's rig is the pair its
    rig's PSVS makes, unless the rig is of kind stereo already).  ValueError for another kind."""
    if rig_kind == "stereo":
        import dataclasses

        from humanpt.geometry.rig import Stereo

        stereo = cfg.rig.stereo if cfg.rig.kind == "stereo" else Stereo.of_psvs(cfg.rig.psvs)
        return dataclasses.replace(cfg, sim_camera=dataclasses.replace(cfg.sim_camera, stereo=True),
                                   rig=dataclasses.replace(cfg.rig, kind="stereo", stereo=stereo))
    if rig_kind != "psvs":
        raise ValueError(f"rig kind {rig_kind!r}: {' or '.join(RIG_KINDS)}")
    return cfg


def write_world(run_dir: Path, cfg: SystemConfig, world: str) -> None:
    """The twin's world of the run, for the record (``world.toml`` in ``run_dir``)."""
    (run_dir / "world.toml").write_text(
        "# the twin's world in this run (humanpt demo --world " + str(world) + ")\n"
        + cfgmod.dumps_toml({"name": cfg.world.name, "sources": list(cfg.world.sources), **cfg.world.extra}))


def header_lines(cfg: SystemConfig, scenario: str, run_dir: Path, lockstep: bool, rig_file: str | None) -> list[str]:
    """What the demo says before it runs: the scenario, the mode, the world, the rig."""
    return [f"humanpt demo: scenario {scenario_label(scenario)}, {'lock-step' if lockstep else 'live'}, "
            f"recording to {run_dir}/",
            f"humanpt demo: world {cfg.world.name}"
            + (f" ({len(cfg.world.sources)} error sources: {', '.join(cfg.world.sources)})" if cfg.world.sources
               else " (the hardware is exactly as the rig says)")
            + f"; the pipeline's rig: {rig_file or 'nominal'} ({cfg.rig.methods()})"]


def report(src, cfg, run_dir: Path, wall_s: float, sim_s: float, mode: str,
           stop_ns: int | None = None) -> str:
    """The accuracy table against ground truth (:func:`humanpt.twin.run.accuracy`), and
    where things are. Warnings stamped after ``stop_ns`` (the processes being stopped: e.g.
    the gateway seeing the controller go) are counted apart."""
    from humanpt.controller.servo_report import servo_summary
    from humanpt.runtime.recording import losses_lines

    from . import evaluate
    from .run import accuracy

    acc = accuracy(src, cfg.controller, cfg.sim_camera.flange_T_camera, stop_ns)
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
    servo = servo_summary(src, evaluate.scenario_start_ns(src))
    if servo.cycles:
        lines.append(f"(the controller's own view while it moved) {servo.line()}")
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
    lines += losses_lines(run_dir)  # a component's recording lost messages to a write error
    return "\n".join(lines)


def run_lockstep_demo(cfg: SystemConfig, run_dir: Path, *, robot: str = "puma", duration_s: float | None = None,
                      link: str = "alter", cycle_ms: float | None = None,
                      progress: Callable[[float, float], None] | None = None) -> str:
    """The demo in one process on virtual time, recording into ``run_dir`` from when the
    target starts to move; the report (:func:`report`)."""
    from humanpt.runtime.rigfile import write_rig

    from .live import link_cycle_ms
    from .run import run

    write_rig(run_dir / "rig.toml", cfg.rig, "what the twin's pipeline believed in this run", overwrite=True)
    rsi_ms = link_cycle_ms("rsi", cycle_ms) if link == "rsi" else None
    abb_ms = link_cycle_ms("abb", cycle_ms) if link == "abb" else None
    ur_ms = link_cycle_ms("ur", cycle_ms) if link == "ur" else None
    res = run(cfg, robot=robot, duration_s=duration_s or None, record_from_s=cfg.operator.start_delay_s,
              run_dir=run_dir, progress=progress, rsi_cycle_ms=rsi_ms, abb_cycle_ms=abb_ms, ur_cycle_ms=ur_ms)
    res.write_path(run_dir / "paths" / "path-1.csv")
    return report(res.world, cfg, run_dir, res.wall_s, res.twin_s, "lock-step")


def run_live_demo(cfg: SystemConfig, run_dir: Path, *, port: int | None = None, viewer: bool = False,
                  duration_s: float | None = None, overrides: dict[str, dict] | None = None,
                  stop: threading.Event | None = None, on_started: Callable[[list[str]], None] | None = None,
                  progress: Callable[[float, float], None] | None = None, secure: bool = False,
                  link: str = "alter", cycle_ms: float | None = None):
    """The demo live (:func:`humanpt.twin.live.run_live`: every component a process over
    Zenoh); (its LiveResult, the report, "" when the run failed)."""
    from .evaluate import RunOutputs
    from .live import run_live

    res = run_live(cfg, run_dir, port=port, viewer=viewer, duration_s=duration_s, overrides=overrides,
                   stop=stop, on_started=on_started, progress=progress, secure=secure, link=link,
                   cycle_ms=cycle_ms)
    if res.failed:
        return res, ""
    text = report(RunOutputs(run_dir), res.config, run_dir, res.wall_s, res.duration_s, "live", stop_ns=res.stop_ns)
    if link == "rsi":
        from humanpt.robot_gateway.links.rsi.runstats import rsi_cycles

        text += "\n" + str(rsi_cycles(run_dir) or "RSI: no <Rob> recorded by sim_robot")
    if link == "abb":
        from humanpt.robot_gateway.links.abb.runstats import egm_cycles

        text += "\n" + str(egm_cycles(run_dir) or "EGM: no EgmRobot recorded by sim_robot")
    return res, text
