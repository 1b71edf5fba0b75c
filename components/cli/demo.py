"""``humanpt demo``: the whole system on the digital twin, and its accuracy against ground truth.

Live (default, :func:`humanpt.twin.live.run_live`): the router, sim_robot behind a pty,
robot_gateway, operator, sim_camera, perception, pose_filter and controller (and viz with
``--viewer``) as separate processes over Zenoh.  ``--lockstep`` (:func:`humanpt.twin.run.run`):
the same cores in one process on virtual time.  Either way every component records its
MCAP in the run directory, the path is written as CSV, and an accuracy table against
ground truth is printed.  This module parses and prints.
"""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path

from humanpt.runtime import config as cfgmod
from humanpt.runtime.progress import Bars


def parse_overrides(items: list[str] | None) -> dict[str, dict]:
    """``--set SECTION.KEY=VALUE`` items -> {section: {key: value}}
    (:func:`humanpt.twin.demo.parse_overrides`); a malformed one ends the command, named."""
    from humanpt.twin.demo import parse_overrides as parse

    try:
        return parse(items)
    except ValueError as e:
        raise SystemExit(f"humanpt: {e}") from None


def run_lockstep(args, cfg, run_dir: Path) -> int:
    from humanpt.twin.demo import run_lockstep_demo

    with Bars("s") as bars:
        text = run_lockstep_demo(cfg, run_dir, robot=args.robot, duration_s=args.duration,
                                 link=getattr(args, "link", "alter"), cycle_ms=args.cycle_ms,
                                 progress=bars.stage("twin"))
    print(text)
    return 0


def run_live(args, cfg, run_dir: Path) -> int:
    from humanpt.twin.demo import run_live_demo

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *a: stop.set())

    def started(comps: list[str]) -> None:
        print(f"humanpt demo: starting {', '.join(comps)}, operator (log: {run_dir / 'processes.log'})", flush=True)
        written = cfgmod.load(run_dir / "humanpt.toml")  # by run_live before the start
        rt = written.runtime
        print(f"humanpt demo: router {', '.join(rt.listen)}, cell {rt.cell}; watch it with "
              f"`humanpt topics --config {run_dir / 'humanpt.toml'}` (or echo, console, view)", flush=True)
        fox = written.sections.get("foxglove_bridge")
        if fox and "foxglove_bridge" in comps:
            print(f"humanpt demo: Foxglove: open ws://127.0.0.1:{fox['port']} (Open connection > Foxglove "
                  f"WebSocket; layout docs/foxglove-layout.json on cell {rt.cell})", flush=True)
        if rt.security == "mtls":
            print(f"humanpt demo: mTLS, a throwaway PKI in {rt.pki}; every process a client of the router, "
                  f"which enforces the access control; tools present {rt.identity!r} (operator)", flush=True)

    with Bars("s") as bars:
        res, text = run_live_demo(cfg, run_dir, port=args.port, viewer=args.viewer, duration_s=args.duration,
                                  overrides=parse_overrides(getattr(args, "set", None)), stop=stop,
                                  on_started=started, progress=bars.stage("live"),
                                  secure=getattr(args, "secure", False), link=getattr(args, "link", "alter"),
                                  cycle_ms=getattr(args, "cycle_ms", None))
    if res.failed:
        print(f"humanpt demo: stopped early: {'; '.join(res.failed)} (see {run_dir / 'processes.log'})",
              file=sys.stderr)
        return 1
    print(text)
    return 0


def calibrate_report(res, paper_mae=(0.9949, 0.7873, 0.392)) -> str:
    """The job's table: each stage's estimate beside the twin's truth, then the taught path
    and the played-back tool path against the seam."""
    lines = ["calibration (estimates; against the twin's truth, which the tools never read)"]
    for s in res.stages:
        if s.ok:
            lines += [f"  [{s.name}] {s.seconds:.0f} s"] + [f"    {r}" for r in s.report if _summary_line(r)] + \
                     [f"    truth: {t.strip()}" for t in s.truth]
        elif getattr(s, "skipped", ""):  # nothing to do here (the arm on the stand-in): said, not warned
            lines.append(f"  [{s.name}] not run: {s.skipped}")
        else:
            lines.append(f"  [{s.name}] SKIPPED: {s.error} (the rig keeps its previous {s.name} values)")
    lines.append(f"  the rig now: {res.rig.methods()}")

    def row(name, d, key):
        c = getattr(res, "compared", {}).get(key)  # humanpt.seam.compare.compare_points against the seam
        if c is None or not len(d):
            return f"  {name:44s} (no points)"
        return (f"  {name:44s} RMS {c.rms_mm:6.3f} mm   mean {c.mean_mm:6.3f}   max {c.max_mm:6.3f}   covered "
                f"{100 * c.covered:5.1f} %, largest gap {c.largest_gap_mm:5.1f} mm at {c.gap_from_mm:.0f}-"
                f"{c.gap_to_mm:.0f} of {c.length_mm:.0f}   n = {c.n}")

    lines += ["", "against the seam (distance to the intended seam; coverage along it, its start and end included; "
              f"the paper's Table 3 MAE is {' / '.join(f'{v:g}' for v in paper_mae)} mm in x / y / z)",
              row("taught path (the driver's tip)", res.taught_mm, "taught"),
              row("taught path, RTS-smoothed" + (" (what is played)" if res.play == "smoothed" else ""),
                  res.smoothed_mm, "smoothed")]
    if res.fitted_mm is not None:
        kinds = [sg.kind for sg in res.fitted.segments]
        lines.append(row(f"taught seam, fitted: {kinds.count('line')} lines, {kinds.count('arc')} arcs"
                         + (" (what is played)" if res.play == "seam" else ""), res.fitted_mm, "fitted"))
    if getattr(res, "refused", ""):
        lines.append(f"  played back: REFUSED before any motion: {res.refused}")
    lines.append(row("played back (the torch's true path)", res.played_mm, "played"))
    if getattr(res, "max_joint_step_deg", None) is not None:
        lines.append(f"  {'  largest joint step of a cycle (the Puma)':44s} {res.max_joint_step_deg:.2f} deg "
                     f"(limit {res.joint_step_limit_deg:.2f} deg per cycle)")
    if "played_fitted" in getattr(res, "compared", {}):  # the playback alone
        lines.append(row("  ... against the fitted seam it was given", res.played_mm, "played_fitted"))
    if res.taught_truth is not None:
        lines += ["", evaluate_format(res.taught_truth)]
    if res.warnings:
        from collections import Counter

        lines += ["", "warnings: " + ", ".join(f"{k} x{n}" for k, n in Counter(res.warnings).most_common(6))]
    lines.append(f"\ndone in {res.seconds:.0f} s" + (f"; recordings of the teach-and-play run: {res.run_dir}"
                                                     if res.run_dir else ""))
    return "\n".join(lines)


def _summary_line(line: str) -> bool:
    """A stage's report without its per-view / per-pose rows (the tool prints them all)."""
    s = line.strip()
    return bool(s) and not (s[0].isdigit() or s.startswith(("right-", "left-", "planned pose", "pose ", "view ")))


def evaluate_format(stats) -> str:
    from humanpt.twin import evaluate

    return evaluate.format_stats("taught path against the truth at its stamps", stats)


# The options the job (--calibrate, lock-step, ALTER's cycle) has no use for: refused when
# given, never dropped.  (--set and --speed (the teach-and-play run's), --robot standin,
# --law, --seed, --world, --rig, --scenario and --run-dir it takes; --lockstep it is anyway.)
_NOT_FOR_CALIBRATE = {"viewer": "the job runs lock-step, without a viewer process",
                      "port": "the job runs lock-step, without a router",
                      "secure": "the job runs lock-step, without a bus",
                      "duration": "the job teaches the whole scenario and plays it back to its end",
                      "cycle_ms": "the job runs on ALTER's 28 ms cycle",
                      }


def refuse_for_calibrate(args) -> None:
    """End the command, naming the option, when ``args`` give one the job does not take."""
    ur = getattr(args, "robot", None) == "ur" or getattr(args, "link", "alter") == "ur"
    for name, why in _NOT_FOR_CALIBRATE.items():
        if name == "cycle_ms" and ur:  # the UR5e's: RTDE's 2 ms (e-Series) or 8 ms (CB3)
            if getattr(args, name, None) not in (None, 2.0, 8.0):
                raise SystemExit(f"humanpt demo --calibrate: --cycle-ms {args.cycle_ms:g}: UR RTDE runs at 2 ms "
                                 "(e-Series) or 8 ms (CB3)")
            continue
        if getattr(args, name, None) not in (None, False):
            raise SystemExit(f"humanpt demo --calibrate: --{name.replace('_', '-')} is not taken: {why}")
    # The job runs on the robot asked for (issue 33.2): the simulated Puma behind the gateway
    # and its ALTER link (default), or the stand-in; never another one.
    if getattr(args, "link", "alter") not in ("alter", "ur"):  # (--link ur: the UR5e, as --robot ur)
        raise SystemExit(f"humanpt demo --calibrate: the job runs over the ALTER link, not --link {args.link}")
    if getattr(args, "rig_kind", "psvs") not in ("psvs", "stereo"):
        raise SystemExit(f"humanpt demo --calibrate: --rig-kind {args.rig_kind}: psvs or stereo")
    if getattr(args, "robot", None) not in (None, "puma", "standin", "ur"):
        raise SystemExit(f"humanpt demo --calibrate: --robot {args.robot} is not taken: the job runs on the simulated "
                         "Puma over ALTER (--robot puma, the default), on the simulated UR5e over RTDE (--robot ur) "
                         "or on the stand-in (--robot standin)")


ROBOT_NAMES = {"puma": "the simulated Puma (robot_gateway + ALTER + sim_robot)", "standin": "the stand-in",
               "ur": "the simulated UR5e (robot_gateway + RTDE + sim_robot)"}


def run_calibrate(args, run_dir: Path, overrides: dict[str, dict] | None = None) -> int:
    from humanpt.runtime.rigfile import load_rig, write_rig
    from humanpt.twin.teach import calibrate_then_teach
    from humanpt.twin.worlds import World

    world = World.named(args.world)
    rig = load_rig(args.rig) if args.rig else None
    if getattr(args, "link", "alter") == "ur":  # --robot ur (= --link ur): the job on the UR5e
        args.robot = "ur"
    told = "".join(f" --set {sec}.{k}={v}" for sec, t in (overrides or {}).items() for k, v in t.items())
    kind = getattr(args, "rig_kind", "psvs")
    if kind == "psvs" and rig is not None and rig.kind == "stereo":
        kind = "stereo"  # a rig file of a pair: the job on the pair
    camera = "the PSVS" if kind == "psvs" else "an ordinary stereo pair (the stereo stage in place of camera and psvs)"
    print(f"humanpt demo --calibrate: camera {camera}; scenario {args.scenario}, world {world.name}, seed {args.seed}, robot "
          f"{ROBOT_NAMES.get(args.robot, args.robot)}, law {args.law}{';' + told if told else ''}; recording the teach-and-play run to "
          f"{run_dir}/", flush=True)
    bar = Bars("s")
    try:
        ur = {"ur_cycle_ms": float(getattr(args, "cycle_ms", None) or 2.0)} if args.robot == "ur" else {}
        res = calibrate_then_teach(args.scenario, world, args.seed, rig=rig, run_dir=run_dir, progress=bar,
                                   robot=args.robot, overrides=overrides, law=args.law, rig_kind=kind, **ur)
    finally:
        bar.close()
    from humanpt.twin.report import job_report

    write_rig(run_dir / "rig.toml", res.rig, "the rig humanpt demo --calibrate ended with", overwrite=True)
    print(calibrate_report(res))
    rep = job_report(res, run_dir / "accuracy.png")
    (run_dir / "accuracy.txt").write_text(rep.text() + "\n")
    print("\n" + rep.text())
    print(f"calibrated rig: {run_dir / 'rig.toml'}")
    if res.fitted is not None:
        from humanpt.seam import seamfile

        (run_dir / "paths").mkdir(exist_ok=True)
        seam = seamfile.write(run_dir / "paths" / "taught.seam.json", res.fitted, overwrite=True)
        print(f"taught seam: {seam}  (humanpt path export {seam} --format krl|rapid|urscript|val|json; "
              f"humanpt view {run_dir} draws it)")
    return 0


def demo(args) -> int:
    from humanpt.runtime.run import run_stamp
    from humanpt.twin.demo import demo_config, header_lines, scenario_label, write_world
    from humanpt.twin.run import SECTIONS, OverrideError

    calibrate = getattr(args, "calibrate", False)
    if calibrate:
        refuse_for_calibrate(args)
    # --robot: the lock-step robot (the job's too: issue 33.2): the simulated Puma by default.
    args.robot = getattr(args, "robot", None) or "puma"
    # --robot LINK (issue 22's spelling): the link's simulated robot over it (the Puma over alter and
    # rsi, the IRB 1600 over abb, the UR5e over ur)
    if args.robot in ("alter", "rsi", "abb", "ur"):
        if args.link != "alter" and args.link != args.robot:
            raise SystemExit(f"humanpt demo: --robot {args.robot} and --link {args.link} disagree")
        args.link, args.robot = args.robot, "puma"
    # The job's defaults: the paper's Table 3 seam (the tip) in a realistic world; a plain
    # demo: the arc in the ideal world.
    args.scenario = args.scenario or ("trapezium" if calibrate else "arc")
    args.world = getattr(args, "world", None) or ("realistic" if calibrate else "ideal")
    over = parse_overrides(getattr(args, "set", None))
    if getattr(args, "speed", None) is not None:  # --speed: the operator's, as --set operator.speed_mm_s
        over.setdefault("operator", {})["speed_mm_s"] = args.speed
    unknown = set(over) - set(SECTIONS)
    if unknown:
        raise SystemExit(f"humanpt demo: --set: no section {sorted(unknown)[0]!r} ({', '.join(SECTIONS)})")
    try:  # a bad key or value, world or rig fails here, before the run starts
        cfg = demo_config(args.scenario, args.seed, over, world=args.world, rig_file=getattr(args, "rig", None),
                          law=args.law, rig_kind=getattr(args, "rig_kind", "psvs"))
    except (OverrideError, cfgmod.ConfigError) as e:
        raise SystemExit(f"humanpt: {e}") from None
    if calibrate:
        run_dir = Path(args.run_dir) if args.run_dir else Path("runs") / f"{run_stamp()}-calibrate-teach"
        run_dir.mkdir(parents=True, exist_ok=True)
        return run_calibrate(args, run_dir, over)
    run_dir = Path(args.run_dir) if args.run_dir else Path("runs") / f"{run_stamp()}-demo-{scenario_label(args.scenario)}"
    run_dir.mkdir(parents=True, exist_ok=True)
    for line in header_lines(cfg, args.scenario, run_dir, args.lockstep, getattr(args, "rig", None)):
        print(line, flush=True)
    write_world(run_dir, cfg, args.world)
    from humanpt.twin.live import link_cycle_ms

    try:  # a cycle the link does not have fails here, before anything starts
        link_cycle_ms(args.link, args.cycle_ms)
    except ValueError as e:
        raise SystemExit(f"humanpt demo: {e}") from None
    if args.lockstep and args.link in ("rsi", "abb", "ur") and args.robot != "puma":
        arm = {"rsi": "Puma", "abb": "ABB IRB 1600", "ur": "UR5e"}[args.link]
        raise SystemExit(f"humanpt demo: --link {args.link} drives the simulated {arm} (--robot puma or "
                         f"--robot {args.link}), not the stand-in")
    if args.lockstep:
        if getattr(args, "secure", False):
            raise SystemExit("humanpt demo: --secure is for the live demo (lock-step runs in one process, "
                             "without a bus)")
        return run_lockstep(args, cfg, run_dir)
    return run_live(args, cfg, run_dir)
