"""``humanpt calibrate hand-eye``: the camera on the flange (AX = YB).

The robot moves itself through N poses around a fixed target, the PSVS measures the target
at each, and AX = YB gives flange_T_camera, written to the rig's ``[hand_eye]``. Sources:
``--twin`` (the digital twin, ``--world``, ``--seed``), or ``--pairs FILE`` (pairs a live
cell collected: a JSON list of {"world_T_flange": 4x4 mm, "camera_T_target": 4x4 mm}).
The maths is :mod:`humanpt.calibration.handeye`; this module parses and prints."""

from __future__ import annotations

import datetime as _dt
import sys
from pathlib import Path

from humanpt.cli.calibrate import add_rig_args, add_world_args

__all__ = ["add_parser", "run"]


def add_parser(csub) -> None:
    p = csub.add_parser(
        "hand-eye", help="hand-eye calibration AX = YB: where the camera sits on the flange",
        description="The robot moves itself through --poses safe poses around a fixed target (through the "
        "controller's playback, the gateway's limits; the console's stop ends it), the PSVS measures the target "
        "at each while still, and AX = YB (Zhuang et al. 1994; closed form, then least squares) gives "
        "flange_T_camera with its 1-sigma, written to the rig's [hand_eye]. OpenCV's calibrateRobotWorldHandEye "
        "and calibrateHandEye cross-check it when the installed OpenCV has them.")
    add_rig_args(p)
    p.add_argument("--twin", action="store_true", help="observe the digital twin (its truth is only reported)")
    add_world_args(p)
    p.add_argument("--poses", type=int, default=None, help="poses to plan (default 12; at least 3)")
    p.add_argument("--pairs", default=None, help="solve from a JSON file of collected pairs: "
                   "[{\"world_T_flange\": 4x4 mm, \"camera_T_target\": 4x4 mm}, ...] (what --save-pairs writes)")
    p.add_argument("--live", action="store_true", help="drive a running cell (controller, gateway, robot, "
                   "camera, perception over Zenoh: --config/--cell/--connect); the target must be fixed in view")
    p.add_argument("--save-pairs", default=None, metavar="FILE", help="also write the collected pairs (JSON)")
    p.add_argument("--config", "-c", metavar="FILE", help="--live: the cell's TOML config file")
    p.add_argument("--cell", help="--live: cell name; overrides [runtime] cell")
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="--live: router endpoint (repeatable)")
    p.add_argument("--timeout", type=float, default=600.0, help="--live: give up after this many seconds")


def _fail(msg: str) -> int:
    print(f"humanpt calibrate hand-eye: {msg}", file=sys.stderr)
    return 2


def _pose_progress(done: int, total: int) -> None:
    print(f"\rhand-eye: pose {done}/{total}", end="", file=sys.stderr, flush=True)


def run(args) -> int:
    from humanpt.calibration.handeye import HandEyeError, apply_to_rig, solve_ax_yb
    from humanpt.console.calibration import collect_hand_eye_live, load_pairs, save_pairs
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.rigfile import load_rig, write_rig

    if sum((bool(args.twin), bool(args.pairs), bool(args.live))) != 1:
        return _fail("give one of --twin (observe the digital twin), --live (drive a running cell) or "
                     "--pairs FILE (pairs collected before)")
    if args.poses is not None and args.poses < 3:
        return _fail(f"--poses {args.poses}: too few; AX = YB needs at least 3 poses with rotations about two "
                     "non-parallel axes")
    rig_path = Path(args.rig)
    try:
        rig = load_rig(rig_path) if rig_path.exists() else Rig()
    except ConfigError as e:
        return _fail(str(e))
    truth: list[str] = []
    try:
        if args.twin:
            from humanpt.twin.cal_handeye import DEFAULT_POSES, calibrate_hand_eye_on_twin
            from humanpt.twin.worlds import World

            world = World.named(args.world)

            def progress(done: int, planned: int) -> None:
                print(f"\rhand-eye: pose {done}/{planned}", end="", file=sys.stderr, flush=True)

            result, report, truth = calibrate_hand_eye_on_twin(world, rig, args.seed, progress,
                                                               n_poses=args.poses or DEFAULT_POSES,
                                                               pairs_out=args.save_pairs)
            print(file=sys.stderr)
        elif args.live:
            from humanpt.cli.commands import load_cfg

            cfg = load_cfg(args)
            if not rig_path.exists():
                rig = cfg.rig()
            A, B, notes = collect_hand_eye_live(cfg, rig, args.poses or 12, args.timeout, progress=_pose_progress)
            save_pairs(args.save_pairs, A, B)
            result = solve_ax_yb(A, B)
            report = [f"hand-eye on the live cell {cfg.runtime.cell}: {len(A)} poses collected",
                      *(f"  {n}" for n in notes), *result.summary_lines()]
        else:
            A, B = load_pairs(args.pairs)
            result = solve_ax_yb(A, B)
            report = result.summary_lines()
    except (HandEyeError, ConfigError, ConnectionError) as e:
        print(file=sys.stderr)
        return _fail(str(e))
    print("\n".join(report))
    if truth:
        print("\n".join(truth))
    if args.dry_run:
        print("dry run: the rig is not written")
        return 0
    date = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    new = apply_to_rig(rig, result, date)
    write_rig(rig_path, new, f"hand-eye by humanpt calibrate hand-eye ({date})", overwrite=True)
    print(f"wrote [hand_eye] to {rig_path}" + (f" (the old rig kept as {rig_path.name}.bak)"
                                                if rig_path.with_name(rig_path.name + ".bak").exists() else ""))
    return 0
