"""``humanpt calibrate stereo``: an ordinary stereo pair from image pairs of a board
(:mod:`humanpt.calibration.stereo`); writes ``[stereo]`` and ``kind = "stereo"`` to the rig."""

from __future__ import annotations

import datetime
import sys
from pathlib import Path

from humanpt.calibration.board import BoardError
from humanpt.calibration.camera import CalibrationError
from humanpt.cli.calibrate import add_rig_args
from humanpt.cli.calibrate_camera import add_board_and_check_args, board_of, settings_of
from humanpt.runtime.config import ConfigError


def add_parser(csub) -> None:
    p = csub.add_parser(
        "stereo", help="an ordinary stereo pair (two cameras): each camera and their relative pose",
        description="Calibrate an ordinary stereo pair (the paper: two parallel cameras could replace the PSVS) "
        "from pairs of images of a board, both cameras at once: Zhang's method for each camera, then OpenCV's "
        "stereoCalibrate refining both and the left camera's pose in the right one, each number with its "
        "1-sigma (the jackknife over the pairs). The images: DIR/left/NAME and DIR/right/NAME, one pair per "
        "name. Writes [stereo] and kind = \"stereo\" to the rig. (This version calibrates the pair; the "
        "pipeline perceives with the PSVS.)")
    p.add_argument("--images", metavar="DIR", required=True,
                   help="DIR/left/ and DIR/right/: the board seen by each camera, the same file name per pair")
    p.add_argument("--detector", choices=("opencv", "paper"), default="opencv",
                   help="corner detector (opencv: findChessboardCornersSB; paper: the appendix's)")
    add_board_and_check_args(p)
    add_rig_args(p)


def run(args) -> int:
    from humanpt.calibration.stereo import (
        apply_stereo_to_rig,
        calibrate_stereo,
        read_pairs,
        stereo_report_lines,
    )
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.progress import StepProgress
    from humanpt.runtime.rigfile import load_rig, write_rig

    try:
        rig_path = Path(args.rig)
        rig = load_rig(rig_path) if rig_path.exists() else Rig()
        pairs = read_pairs(args.images)
        result = calibrate_stereo(pairs, board_of(args), settings_of(args), args.detector,
                                  StepProgress("board corners, left then right"))
        new_rig = apply_stereo_to_rig(rig, result, datetime.date.today().isoformat())
    except (CalibrationError, BoardError, ConfigError) as e:
        print(f"humanpt calibrate stereo: error: {e}", file=sys.stderr)
        return 2
    print("\n".join(stereo_report_lines(result)))
    if args.dry_run:
        print(f"dry run: {rig_path} not written")
        return 0
    existed = rig_path.exists()
    write_rig(rig_path, new_rig, "stereo pair calibrated by `humanpt calibrate stereo`", overwrite=True)
    print(f"wrote {rig_path} (kind = \"stereo\", [stereo])"
          + (f"; the old one kept as {rig_path.name}.bak" if existed else ", from the nominal rig"))
    return 0
