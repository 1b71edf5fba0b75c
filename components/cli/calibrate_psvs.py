"""``humanpt calibrate psvs`` and ``humanpt calibrate mirrors``: the PSVS's virtual cameras
(:mod:`humanpt.calibration.psvs`) and the mirrors alignment check
(:mod:`humanpt.calibration.mirrors`), from the digital twin (``--twin``) or from a
recording of perception (``--recording FILE``: its ``perception/tob`` measurements, the
target moved through several depths in front of a real cell). This module parses and
prints."""

from __future__ import annotations

import datetime
import sys
from pathlib import Path

from humanpt.cli.calibrate import add_rig_args, add_world_args

TOOL_NAMES = ("psvs", "mirrors")


def _common(p) -> None:
    add_rig_args(p)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--twin", action="store_true", help="observe the digital twin (its truth only in the report)")
    src.add_argument("--recording", metavar="MCAP",
                     help="perception's recording (its perception/tob measurements) of the target at several depths")
    add_world_args(p)
    p.add_argument("--poses", type=int, default=36, help="with --twin: camera poses around the still target (default 36)")
    p.add_argument("--frames", type=int, default=6, help="with --twin: images per pose (default 6)")


def add_parser(csub) -> None:
    """Add both sub-parsers (``TOOLS`` lists the module once per tool: the second call adds nothing)."""
    if "psvs" in csub.choices:
        return
    p = csub.add_parser("psvs", help="estimate each virtual camera's pose (rotation, baseline) and write the rig",
                        description="Bundle adjustment of the target's three sources seen by both views at several "
                        "depths: the left view's rotation against the right one, the baseline (with the rig's m; the "
                        "target's triangle gives the scale), optionally l. Intrinsics, distortion and principal "
                        "points are the camera calibration's (the rig's). Writes [psvs] rotvec_left_deg, baseline_mm "
                        "(and l_mm) with their 1-sigma.")
    _common(p)
    p.add_argument("--fit-l", action="store_true", help="also estimate l (poorly determined: ~0.05 mm at best)")
    p.set_defaults(calibrate_tool="psvs")
    q = csub.add_parser("mirrors", help="the mirrors alignment check: vertical disparity, each view's turn, pass/fail",
                        description="The paper's (d): the vertical disparity v_L - v_R of matched pairs across the "
                        "image (a constant part is a tilt about x, a part linear in u a roll about z), the pan about "
                        "y from the target's known size, each against a threshold that keeps the path error under "
                        "--budget mm, and which mirror to turn which way. Exit 0 on pass, 1 on fail. Writes nothing.")
    _common(q)
    q.add_argument("--budget", type=float, default=0.1, help="path error budget, mm (default 0.1)")
    q.set_defaults(calibrate_tool="mirrors")


def _views():
    from humanpt.runtime.progress import StepProgress

    return StepProgress("  views")


def _fail(tool: str, msg: str) -> int:
    print(f"humanpt calibrate {tool}: {msg}", file=sys.stderr)
    return 2


def run(args) -> int:
    from humanpt.calibration import mirrors, psvs
    from humanpt.calibration.psvs import CalibrationError
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.recording import RecordingError
    from humanpt.runtime.rigfile import load_rig, write_rig

    tool = getattr(args, "calibrate_verb", None) or args.calibrate_tool
    rig_path = Path(args.rig)
    try:
        rig = load_rig(rig_path) if rig_path.exists() else Rig()
    except ConfigError as e:
        return _fail(tool, str(e))
    if args.poses < psvs.MIN_VIEWS // 2:
        return _fail(tool, f"--poses {args.poses}: too few poses (need at least {psvs.MIN_VIEWS // 2})")
    if args.frames < 1:
        return _fail(tool, f"--frames {args.frames}: at least one image per pose")
    date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    truth: list[str] = []
    try:
        if args.twin:
            from humanpt.twin import cal_psvs
            from humanpt.twin.worlds import World

            world = World.named(args.world)
            print(f"humanpt calibrate {tool}: the twin, world {world.name!r}, seed {args.seed}, "
                  f"{args.poses} poses; rig {rig_path}{'' if rig_path.exists() else ' (nominal: no such file yet)'}",
                  file=sys.stderr)
            if tool == "psvs":
                est, report, truth = cal_psvs.calibrate_psvs_on_twin(world, rig, args.seed, _views(),
                                                                     n_poses=args.poses, frames_per_pose=args.frames,
                                                                     fit_l=args.fit_l, date=date)
            else:
                check, report, truth = cal_psvs.check_mirrors_on_twin(world, rig, args.seed, _views(),
                                                                      n_poses=args.poses, frames_per_pose=args.frames,
                                                                      budget_mm=args.budget)
        else:
            from humanpt.runtime import recording

            if not Path(args.recording).is_file():
                return _fail(tool, f"{args.recording}: no such recording")
            rec = recording.read(args.recording)
            views = psvs.views_from_measurements(
                e.decode() for e in rec.outputs if e.topic.endswith("perception/tob"))
            if len(views) == 0:
                return _fail(tool, f"{args.recording}: no FULL measurement of the target (all three sources paired "
                             "in both views): was the target seen by both views?")
            if tool == "psvs":
                est = psvs.estimate_psvs(rig, views, fit_l=args.fit_l)
                report = psvs.report_lines(rig, est)
            else:
                check = mirrors.check_mirrors(rig, views, budget_mm=args.budget)
                report = mirrors.report_lines(check)
    except (CalibrationError, ConfigError, RecordingError) as e:
        return _fail(tool, str(e))
    print("\n".join(report))
    if truth:
        print("\n".join(truth))
    if tool == "mirrors":
        return 0 if check.ok else 1
    new = psvs.apply_to_rig(rig, est, date, note="humanpt calibrate psvs" + (" --twin" if args.twin else ""))
    if args.dry_run:
        print(f"--dry-run: {rig_path} not written")
        return 0
    write_rig(rig_path, new, f"humanpt calibrate psvs, {date}", overwrite=True)
    print(f"wrote {rig_path}" + (f" (the old one kept as {rig_path.name}.bak)" if Path(str(rig_path) + ".bak").exists()
                                 else ""))
    return 0
