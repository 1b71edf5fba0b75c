"""``humanpt calibrate tip``: the driver tip (Section 4.1) into the rig's ``[tip]``.

On a live cell (``--config``): asks the running controller to ``calibrate`` (the operator
then pivots the target on its needle's tip held on a fixed point), waits for its result and
writes it into the rig.  ``--twin``: the same on the digital twin."""

from __future__ import annotations

import sys
from datetime import UTC, datetime
from pathlib import Path

from humanpt.calibration.tip import apply_to_rig
from humanpt.cli.calibrate import add_rig_args, add_world_args
from humanpt.geometry.rig import Rig
from humanpt.runtime.rigfile import load_rig, write_rig


def add_parser(csub) -> None:
    q = csub.add_parser("tip", help="the driver tip (pivot the target on its needle) into the rig",
                        description="Calibrate the driver's tip P in the TOB frame (the paper's Section 4.1): the "
                        "operator keeps the needle's tip on a fixed point and turns the target about it; the "
                        "controller fits the tip (least-squares pivot) and this writes it into the rig's [tip]. "
                        "Live (--config: the running controller) or on the digital twin (--twin).")
    add_rig_args(q)
    q.add_argument("--samples", type=int, help="distinct poses to fit (>= 6; default: 160 on the twin, the "
                   "controller's calibration_samples live)")
    q.add_argument("--method", choices=("pivot", "paper"), default="pivot",
                   help="pivot (default): the least-squares pivot fit; paper: Section 4.1 as written - P' measured "
                   "first as the centre of a printed circle through the PSVS over --pattern-poses robot poses "
                   "(eq. 10-11), then eq. 12-13 on the poses collected while the target pivots on P' (twin only)")
    q.add_argument("--pattern-poses", type=int, default=10, metavar="N",
                   help="--method paper: robot poses that measure P' (default 10)")
    q.add_argument("--twin", action="store_true", help="on the digital twin instead of a live cell")
    add_world_args(q)
    q.add_argument("--config", "-c", metavar="FILE", help="live: the cell's config file")
    q.add_argument("--timeout", type=float, default=120.0, help="live: seconds to wait for the result (default 120)")


def _read_rig(path: Path) -> Rig:
    return load_rig(path) if path.exists() else Rig()


def run(args) -> int:
    if args.samples is not None and args.samples < 6:
        raise ValueError("--samples must be >= 6 (the pivot fit has 6 unknowns)")
    if args.pattern_poses < 1:
        raise ValueError(f"--pattern-poses must be >= 1, got {args.pattern_poses}")
    if args.method == "paper" and not args.twin:
        raise ValueError("--method paper runs on the twin (--twin): measuring P' live needs the printed pattern "
                         "in the camera's view, which the live console does not drive yet")
    rig_path = Path(args.rig)
    rig = _read_rig(rig_path)  # a bad rig fails before anything moves
    if args.twin:
        from humanpt.twin.cal_tip import PIVOT_SAMPLES, TipCalibrationError, calibrate_tip_on_twin
        from humanpt.twin.worlds import World

        try:
            result, report, truth = calibrate_tip_on_twin(
                World.named(args.world), rig, args.seed, args.samples or PIVOT_SAMPLES,
                progress=lambda now, end: print(f"\r  twin {now:4.0f} / {end:.0f} s", end="", file=sys.stderr),
                method=args.method, pattern_poses=args.pattern_poses)
        except TipCalibrationError as e:
            print(file=sys.stderr)
            raise ValueError(str(e)) from None
        print(file=sys.stderr)
    else:
        if not args.config:
            raise ValueError("give --config FILE (a live cell) or --twin")
        from humanpt.cli.commands import load_cfg
        from humanpt.console.calibration import calibrate_tip_live

        result = calibrate_tip_live(load_cfg(args), args.samples, args.timeout)
        report = [f"tip: tob_t_tip = ({', '.join(f'{v:.3f}' for v in result.tob_t_tip_mm)}) mm +- "
                  f"{result.sigma_mm:.3f} mm ({result.samples} poses, residual RMS {result.residual_rms_mm:.3f} mm)"]
        truth = []
    for line in report + truth:
        print(line)
    if args.dry_run:
        print("dry run: the rig is unchanged")
        return 0
    date = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    write_rig(rig_path, apply_to_rig(rig, result, date, args.method), "written by humanpt calibrate tip",
              overwrite=True)
    print(f"wrote the tip into {rig_path}" + (" (the old rig kept as .bak)" if rig_path.with_name(
        rig_path.name + ".bak").exists() else ""))
    return 0
