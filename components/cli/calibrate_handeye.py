"""``humanpt calibrate hand-eye``: the camera on the flange (AX = YB).

The robot moves itself through N poses around a fixed target, the PSVS measures the target
at each, and AX = YB gives flange_T_camera, written to the rig's ``[hand_eye]``. Sources:
``--twin`` (the digital twin, ``--world``, ``--seed``), or ``--pairs FILE`` (pairs a live
cell collected: a JSON list of {"world_T_flange": 4x4 mm, "camera_T_target": 4x4 mm}).
The maths is :mod:`humanpt.calibration.handeye`; this module parses and prints."""

from __future__ import annotations

import datetime as _dt
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["add_parser", "run"]


def add_parser(csub) -> None:
    p = csub.add_parser(
        "hand-eye", help="hand-eye calibration AX = YB: where the camera sits on the flange",
        description="The robot moves itself through --poses safe poses around a fixed target (through the "
        "controller's playback, the gateway's limits; the console's stop ends it), the PSVS measures the target "
        "at each while still, and AX = YB (Zhuang et al. 1994; closed form, then least squares) gives "
        "flange_T_camera with its 1-sigma, written to the rig's [hand_eye]. OpenCV's calibrateRobotWorldHandEye "
        "and calibrateHandEye cross-check it when the installed OpenCV has them.")
    p.add_argument("--rig", default="rig.toml", help="the rig file to update (created from the nominal rig if "
                   "absent; the old one is kept as .bak)")
    p.add_argument("--dry-run", action="store_true", help="estimate and report; write nothing")
    p.add_argument("--twin", action="store_true", help="observe the digital twin (its truth is only reported)")
    p.add_argument("--world", default="realistic", help="the twin's world: ideal, realistic or a world file")
    p.add_argument("--seed", type=int, default=0, help="the twin's seed")
    p.add_argument("--poses", type=int, default=None, help="poses to plan (default 10; at least 3)")
    p.add_argument("--pairs", default=None, help="a JSON file of collected pairs from a real cell: "
                   "[{\"world_T_flange\": 4x4 mm, \"camera_T_target\": 4x4 mm}, ...]")


def _fail(msg: str) -> int:
    print(f"humanpt calibrate hand-eye: {msg}", file=sys.stderr)
    return 2


def _load_pairs(path: str) -> tuple[np.ndarray, np.ndarray]:
    from humanpt.calibration.handeye import HandEyeError

    p = Path(path)
    if not p.is_file():
        raise HandEyeError(f"{p}: no such pairs file")
    try:
        data = json.loads(p.read_text())
        A = np.array([d["world_T_flange"] for d in data], dtype=float)
        B = np.array([d["camera_T_target"] for d in data], dtype=float)
    except (ValueError, TypeError, KeyError) as e:
        raise HandEyeError(f"{p}: not a JSON list of {{\"world_T_flange\", \"camera_T_target\"}} 4x4 pairs ({e})") \
            from None
    return A, B


def run(args) -> int:
    from humanpt.calibration.handeye import HandEyeError, apply_to_rig, solve_ax_yb
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.rigfile import load_rig, write_rig

    if args.twin == bool(args.pairs):
        return _fail("give --twin (observe the digital twin) or --pairs FILE (pairs a live cell collected)")
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
                                                               n_poses=args.poses or DEFAULT_POSES)
            print(file=sys.stderr)
        else:
            A, B = _load_pairs(args.pairs)
            result = solve_ax_yb(A, B)
            report = result.summary_lines()
    except (HandEyeError, ConfigError) as e:
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
