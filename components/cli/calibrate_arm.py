"""``humanpt calibrate arm``: the playing arm's kinematic errors with the hand-eye (issue 32.4).

The robot moves itself through N poses around a fixed target (wider tilts than the
hand-eye's), the PSVS measures the target at each, and :func:`humanpt.calibration.arm
.solve_arm` gives the arm's joint zero offsets and DH length errors (those the data
determine; the rest held at 0 and named) with the hand-eye and their 1-sigma, written to
the rig's ``[arm]`` and ``[hand_eye]``.  Sources: ``--twin`` (the digital twin's Puma,
mounted as ``humanpt demo --calibrate`` mounts it for ``--scenario``, the target where that
seam starts), or ``--pairs FILE`` (pairs a live cell collected: what ``humanpt calibrate
hand-eye --save-pairs`` writes, with the robot's mounting ``--world-T-base``).  The maths
is :mod:`humanpt.calibration.arm`; this module parses and prints."""

from __future__ import annotations

import datetime as _dt
import sys
from pathlib import Path

from humanpt.cli.calibrate import add_rig_args, add_world_args

__all__ = ["add_parser", "run"]


def add_parser(csub) -> None:
    p = csub.add_parser(
        "arm", help="the arm's kinematic calibration: joint offsets and link lengths, with the hand-eye",
        description="The robot (the Puma over ALTER) moves itself through --poses safe poses around a fixed target, "
        "the PSVS measures the target at each while still, and least squares on the arm's joint zero offsets and DH "
        "lengths, the hand-eye and the target's pose gives the arm's errors against its nominal model with their "
        "1-sigma (those no camera on the flange can see, or these poses do not determine, held at 0 and named), "
        "written to the rig's [arm] (with the hand-eye estimated with it, [hand_eye]). A playback then commands what "
        "puts the calibrated arm on the seam, and a taught path is placed with it.")
    add_rig_args(p)
    p.add_argument("--twin", action="store_true", help="observe the digital twin's Puma (its truth is only reported)")
    add_world_args(p)
    p.add_argument("--scenario", default="trapezium",
                   help="--twin: mount the Puma as `humanpt demo --calibrate` does for this seam and hold the target "
                   "where it starts (default trapezium)")
    p.add_argument("--poses", type=int, default=None, help="poses to plan (default 28; at least 8)")
    p.add_argument("--pairs", default=None, help="solve from a JSON file of collected pairs: "
                   "[{\"world_T_flange\": 4x4 mm, \"camera_T_target\": 4x4 mm}, ...] (what `calibrate hand-eye "
                   "--save-pairs` writes)")
    p.add_argument("--world-T-base", default=None, metavar="X,Y,Z,YAW,PITCH,ROLL",
                   help="--pairs: where the robot's base is in the world (mm, deg; the gateway's world_T_base_mm_deg)")
    p.add_argument("--model", default="puma762", help="--pairs: the arm's nominal model (default puma762)")


def _fail(msg: str) -> int:
    print(f"humanpt calibrate arm: {msg}", file=sys.stderr)
    return 2


def _six(text: str, what: str) -> list[float]:
    try:
        v = [float(s) for s in text.split(",")]
    except ValueError:
        raise ValueError(f"{what} {text!r}: not six numbers separated by commas") from None
    if len(v) != 6:
        raise ValueError(f"{what} {text!r}: needs six numbers (x, y, z mm, yaw, pitch, roll deg), got {len(v)}")
    return v


def run(args) -> int:
    import numpy as np

    from humanpt.calibration.arm import MIN_POSES, ArmCalibrationError, apply_to_rig, solve_arm
    from humanpt.calibration.handeye import HandEyeError
    from humanpt.geometry.rig import Rig
    from humanpt.geometry.transforms import transform_from_x
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.rigfile import load_rig, write_rig

    if bool(args.twin) == bool(args.pairs):
        return _fail("give one of --twin (observe the digital twin) or --pairs FILE (pairs collected before, with "
                     "--world-T-base)")
    if args.poses is not None and args.poses < MIN_POSES:
        return _fail(f"--poses {args.poses}: too few; the arm's calibration needs at least {MIN_POSES}")
    rig_path = Path(args.rig)
    try:
        rig = load_rig(rig_path) if rig_path.exists() else Rig()
    except ConfigError as e:
        return _fail(str(e))
    truth: list[str] = []
    try:
        if args.twin:
            from humanpt.twin.cal_arm import (
                DEFAULT_POSES,
                calibrate_arm_on_twin,
                fixture_at_seam_start,
            )
            from humanpt.twin.run import SystemConfig
            from humanpt.twin.teach import mounting
            from humanpt.twin.worlds import World

            world = World.named(args.world)
            cfg = SystemConfig.for_scenario(args.scenario, args.seed, rig=rig, world=world)
            _, mount, joints = mounting(cfg, "puma")

            def progress(done: int, planned: int) -> None:
                print(f"\rarm: pose {done}/{planned}", end="", file=sys.stderr, flush=True)

            result, report, truth = calibrate_arm_on_twin(world, rig, args.seed, progress,
                                                          n_poses=args.poses or DEFAULT_POSES, mount=(mount, joints),
                                                          scenario=fixture_at_seam_start(cfg.operator))
            print(file=sys.stderr)
        else:
            from humanpt.console.calibration import load_pairs

            if not args.world_T_base:
                return _fail("--pairs needs --world-T-base X,Y,Z,YAW,PITCH,ROLL (where the robot's base is: the "
                             "gateway's world_T_base_mm_deg)")
            W = transform_from_x(np.asarray(_six(args.world_T_base, "--world-T-base")))
            A, B = load_pairs(args.pairs)
            result = solve_arm(A, B, W, model=args.model)
            report = result.summary_lines()
    except (ArmCalibrationError, HandEyeError, ConfigError, ValueError) as e:
        if args.twin:
            print(file=sys.stderr)  # after the progress line
        return _fail(str(e))
    print("\n".join(report))
    if truth:
        print("\n".join(truth))
    if args.dry_run:
        print("dry run: the rig is not written")
        return 0
    date = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    write_rig(rig_path, apply_to_rig(rig, result, date), f"arm by humanpt calibrate arm ({date})", overwrite=True)
    print(f"wrote [arm] and [hand_eye] to {rig_path}" + (f" (the old rig kept as {rig_path.name}.bak)"
                                                          if rig_path.with_name(rig_path.name + ".bak").exists()
                                                          else ""))
    return 0
