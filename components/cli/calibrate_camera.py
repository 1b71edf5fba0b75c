"""``humanpt calibrate camera``: Zhang's method on views of a board, one PSVS path at a
time (cover the other mirror), from a folder of images or from the digital twin; writes
the camera part of the rig (:func:`humanpt.calibration.camera.apply_to_rig`)."""

from __future__ import annotations

import datetime
import sys
from pathlib import Path

from humanpt.calibration.board import BoardError, CharucoSpec, Chessboard
from humanpt.calibration.camera import (
    DIST_MODELS,
    CalibrationError,
    CameraCalibration,
    CameraSettings,
    apply_to_rig,
    calibrate_view,
    detect_views,
    report_lines,
)
from humanpt.cli.calibrate import add_rig_args, add_world_args
from humanpt.runtime.config import ConfigError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def add_board_and_check_args(p) -> None:
    """The board's and the checks' options (``calibrate camera`` and ``calibrate stereo``)."""
    b = p.add_argument_group("board")
    b.add_argument("--board", choices=("chessboard", "charuco"), default="chessboard")
    b.add_argument("--cols", type=int, default=11, help="chessboard inner corners along a row (11, the twin's)")
    b.add_argument("--rows", type=int, default=8, help="chessboard inner corners along a column (8)")
    b.add_argument("--square-mm", type=float, default=20.0, help="square side, mm (20)")
    b.add_argument("--squares-x", type=int, default=10, help="charuco squares along x (10)")
    b.add_argument("--squares-y", type=int, default=7, help="charuco squares along y (7)")
    b.add_argument("--marker-mm", type=float, default=18.0, help="charuco marker side, mm (18)")
    b.add_argument("--dictionary", default="DICT_4X4_50", help="charuco ArUco dictionary (DICT_4X4_50)")
    s = p.add_argument_group("checks")
    s.add_argument("--dist-model", choices=("auto", *DIST_MODELS), default="auto",
                   help="distortion coefficients: auto (k1, k2; k2 dropped when not significant), k1, k1k2, "
                   "k1k2p (+ tangential), full (+ k3)")
    s.add_argument("--min-views", type=int, default=6, help="fewer usable views are refused (6)")
    s.add_argument("--max-blur-px", type=float, default=2.0, help="images with a larger edge blur are dropped (2 px)")
    s.add_argument("--min-coverage", type=float, default=0.35, help="fraction of the image the boards must cover")


def add_parser(csub) -> None:
    p = csub.add_parser(
        "camera", help="the camera's intrinsics and distortion (Zhang's method), one PSVS view at a time",
        description="Calibrate the camera by Zhang's method (OpenCV's calibrateCamera) from views of a board, "
        "each virtual camera of the PSVS in turn with the other mirror covered. The rig gets a_u, a_v, skew 0, "
        "u0, v0 (the right view's principal point, also the distortion's centre), the distortion, and du0/dv0 "
        "of the left view's principal point relative to the right's, each with its 1-sigma. Sources: "
        "--images DIR (and --left-images DIR) or --twin. Bad input (no board, too few views, blurred or "
        "badly covered sets) is refused with the reason and writes nothing.")
    src = p.add_argument_group("source")
    src.add_argument("--images", metavar="DIR", help="images (png/jpg, grey or colour) of the board seen through "
                     "the view --view (default: the right one)")
    src.add_argument("--left-images", metavar="DIR", help="images of the board through the LEFT view (with "
                     "--images for the right view: both are calibrated)")
    src.add_argument("--live", action="store_true", help="the camera component's images (camera/image over "
                     "Zenoh, --config/--cell/--connect): press Enter to capture the next frame, q to finish; one "
                     "view per run (--view right, then --view left)")
    src.add_argument("--save", metavar="DIR", help="with --live: also write the captured frames there (png), "
                     "for a later --images run")
    src.add_argument("--twin", action="store_true", help="observe the digital twin (it renders the board through "
                     "the world's true optics and sensor; the estimate never reads its truth)")
    add_world_args(src)
    src.add_argument("--views", type=int, default=20, metavar="N", help="board poses per view on the twin (20)")
    p.add_argument("--view", choices=("right", "left", "both"), default=None,
                   help="which virtual camera (twin default: both; --images default: right)")
    p.add_argument("--detector", choices=("opencv", "paper", "both"), default="opencv",
                   help="corners by OpenCV (findChessboardCornersSB + cornerSubPix), by the paper's appendix "
                   "detector, or both compared on the same images (the rig gets OpenCV's)")
    add_board_and_check_args(p)
    add_rig_args(p)
    lv = p.add_argument_group("live (--live)")
    lv.add_argument("--config", "-c", metavar="FILE", help="TOML config file ([runtime] cell and router)")
    lv.add_argument("--cell", help="cell name; overrides [runtime] cell")
    lv.add_argument("--connect", action="append", metavar="ENDPOINT", help="router endpoint; overrides [runtime] connect")
    lv.add_argument("--frame-timeout-s", type=float, default=5.0, help="wait this long for a frame after Enter (5 s)")


def settings_of(args) -> CameraSettings:
    return CameraSettings(min_views=args.min_views, max_blur_px=args.max_blur_px, min_coverage=args.min_coverage,
                          dist_model=args.dist_model)


def board_of(args):
    if args.board == "charuco":
        return CharucoSpec(args.squares_x, args.squares_y, args.square_mm, args.marker_mm, args.dictionary)
    return Chessboard(args.cols, args.rows, args.square_mm)


def _progress(what: str):
    from humanpt.runtime.progress import StepProgress

    return StepProgress(what)


def read_images(folder: str | Path) -> list[tuple[str, object]]:
    """[(file name, (h, w) uint8 grey)] of the images in ``folder``, sorted by name;
    CalibrationError for a missing folder, no images, unreadable or mixed-size images."""
    import cv2

    d = Path(folder)
    if not d.is_dir():
        raise CalibrationError(f"{d}: no such folder")
    files = sorted(f for f in d.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise CalibrationError(f"{d}: no images ({', '.join(IMAGE_SUFFIXES)})")
    out = []
    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise CalibrationError(f"{f}: not a readable image")
        if out and img.shape != out[0][1].shape:
            raise CalibrationError(f"{f}: {img.shape[1]} x {img.shape[0]} px, but {out[0][0]} is "
                                   f"{out[0][1].shape[1]} x {out[0][1].shape[0]} px: one camera, one size")
        out.append((f.name, img))
    return out


def _from_images(args, rig, settings) -> tuple[CameraCalibration, list[str], list[str]]:
    board = board_of(args)
    view = args.view or "right"
    folders = {}
    if args.images:
        if view == "both":
            raise CalibrationError("--view both with images: give --images (right) and --left-images (left)")
        folders[view] = args.images
    if args.left_images:
        if "left" in folders:
            raise CalibrationError("--images is the left view already (--view left): drop --left-images")
        folders["left"] = args.left_images
    if not folders:
        raise CalibrationError("no source: give --images DIR or --twin")
    detectors = ("opencv", "paper") if args.detector == "both" else (args.detector,)
    views, dets_of, extra = {}, {}, []
    for v, folder in folders.items():
        images = read_images(folder)
        h, w = images[0][1].shape
        if (w, h) != tuple(rig.psvs.params().image_size_px):  # the rig takes the images' size (apply_to_rig)
            if "right" not in folders:
                raise CalibrationError(f"{folder}: images are {w} x {h} px, the rig's camera {rig.psvs.image_width_px} "
                                       f"x {rig.psvs.image_height_px} px: calibrate the right view (or both) at the "
                                       "new size, its principal point places the left one")
            print(f"{folder}: images are {w} x {h} px, the rig's camera {rig.psvs.image_width_px} x "
                  f"{rig.psvs.image_height_px} px: the calibrated rig will say {w} x {h} px", flush=True)
        for d in detectors:
            dets = detect_views(images, board, d, _progress(f"{v} view, {d} detector"))
            try:
                cal = calibrate_view(dets, (w, h), v, settings, d)
            except CalibrationError as e:
                raise CalibrationError(f"{v} view ({folder}): {e}") from None
            if d == detectors[0]:
                views[v], dets_of[v] = cal, dets
            if len(detectors) > 1:
                extra.append(f"  {d:<7} {v:<5} reprojection {cal.rms_px:.3f} px   "
                             f"{1e3 * sum(x.seconds for x in dets) / len(dets):6.1f} ms/image   a_u {cal.a_u:.2f} px")
    result = CameraCalibration(views)
    lines = report_lines(result, dets_of)
    if extra:
        lines += ["detectors on the same images (reprojection RMS, time per image, focal length):", *extra]
    return result, lines, []


def run(args) -> int:
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.rigfile import load_rig, write_rig

    try:
        rig_path = Path(args.rig)
        rig = load_rig(rig_path) if rig_path.exists() else Rig()
        settings = settings_of(args)
        if sum(bool(x) for x in (args.twin, args.live, args.images or args.left_images)) > 1:
            raise CalibrationError("one source: --images, --live or --twin")
        if args.live:
            from humanpt.cli.commands import load_cfg
            from humanpt.console.calibration import calibrate_camera_live

            result, lines, truth = calibrate_camera_live(
                load_cfg(args), rig, settings, board_of(args), view=args.view or "right", detector=args.detector,
                frame_timeout_s=args.frame_timeout_s, save=args.save, lines=sys.stdin)
        elif args.twin:
            if args.images or args.left_images:
                raise CalibrationError("--twin or --images, not both")
            if args.board != "chessboard":
                raise CalibrationError("the twin shows a chessboard: drop --board charuco")
            from humanpt.twin.cal_camera import calibrate_camera_on_twin
            from humanpt.twin.worlds import World

            result, lines, truth = calibrate_camera_on_twin(
                World.named(args.world), rig, args.seed, _progress("twin images"), detector=args.detector,
                view=args.view or "both", n_views=args.views, settings=settings, board=board_of(args))
        else:
            result, lines, truth = _from_images(args, rig, settings)
        new_rig = apply_to_rig(rig, result, datetime.date.today().isoformat())
    except (CalibrationError, BoardError, ConfigError) as e:
        print(f"humanpt calibrate camera: error: {e}", file=sys.stderr)
        return 2
    print("\n".join(lines))
    if truth:
        print("\n".join(truth))
    if args.dry_run:
        print(f"dry run: {rig_path} not written")
        return 0
    from humanpt.cli.rig import differences

    existed = rig_path.exists()
    write_rig(rig_path, new_rig, "camera calibrated by `humanpt calibrate camera`", overwrite=True)
    print(f"wrote {rig_path} (its camera part: psvs, psvs_calibration)"
          + (f"; the old one kept as {rig_path.name}.bak" if existed else ", from the nominal rig"))
    for line in differences(rig, new_rig):
        print(f"  {line}")
    return 0
