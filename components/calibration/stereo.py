"""Ordinary stereo pair calibration (issue 35 item 3; the paper: "an ordinary stereovision
system with two parallel cameras could also replace PSVS"): Zhang's method for each camera
(:func:`humanpt.calibration.camera.calibrate_view`, with its checks) as the start, then
OpenCV's ``stereoCalibrate`` refining both cameras and the pose of the left camera in the
right one together (``right_T_left``: a point X_left is at R X_left + T in the right
camera; the distortion terms each camera's model left out stay fixed). Refined together,
because the cameras' offset along the optical axis and their focal lengths trade off: with
the intrinsics fixed, their errors go into the offset unseen.

Uncertainty: the jackknife over the image pairs (each left out once, the joint refinement
done again), as the hand-eye's (:mod:`humanpt.calibration.handeye`): 1-sigma of each of
the six numbers of X (mm, deg), of the baseline and of each camera's a_u, a_v, u0, v0.

Input: image pairs (name, left image, right image) of one board seen by both cameras at
once; a pair whose board is not found in both images is left out and reported.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.geometry.rig import Calibration, Rig, Stereo, StereoCamera
from humanpt.geometry.transforms import make_transform, x_from_transform

from .board import CharucoSpec, Chessboard
from .camera import (
    DIST_MODELS,
    CalibrationError,
    CameraSettings,
    ViewCalibration,
    calibrate_view,
    detect_views,
)

__all__ = ["StereoCalibration", "calibrate_stereo", "apply_stereo_to_rig", "apply_to_rig", "stereo_report_lines",
           "read_pairs", "PAIR_SUFFIXES"]

PAIR_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm")

_X_NAMES = ("x_mm", "y_mm", "z_mm", "psi_deg", "theta_deg", "phi_deg")


@dataclass(frozen=True)
class StereoCalibration:
    """``left``, ``right``: each camera's calibration on the pairs both saw (refined with the
    pair; ``sigma`` of a_u, a_v, u0, v0 from the jackknife, the distortion's from Zhang);
    ``right_T_left_mm`` (4, 4); ``rms_px`` stereoCalibrate's reprojection RMS over both
    images of every pair; ``sigma_x`` the jackknife 1-sigma of X (mm, deg; keys
    ``_X_NAMES``) and ``sigma_baseline_mm``; ``pairs`` the names used; ``rejected``
    [(name, reason)]."""

    left: ViewCalibration
    right: ViewCalibration
    right_T_left_mm: np.ndarray
    rms_px: float
    sigma_x: dict[str, float]
    sigma_baseline_mm: float
    pairs: tuple[str, ...]
    rejected: tuple[tuple[str, str], ...] = ()

    @property
    def baseline_mm(self) -> float:
        return float(np.linalg.norm(self.right_T_left_mm[:3, 3]))


def _stereo(obj, img_l, img_r, left: ViewCalibration, right: ViewCalibration, size):
    """stereoCalibrate from each camera's Zhang result: (rms, K_left, d_left, K_right,
    d_right, right_T_left (4, 4) mm)."""
    import cv2

    flags = cv2.CALIB_USE_INTRINSIC_GUESS
    for model in {left.dist_model, right.dist_model}:
        for name in DIST_MODELS[model][0].split():
            flags |= getattr(cv2, name)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # reproducible sums (as calibrate_view's)
    try:
        rms, k_l, d_l, k_r, d_r, R, T = cv2.stereoCalibrate(
            obj, img_l, img_r, left.camera_matrix.copy(), left.dist_coeffs.copy(), right.camera_matrix.copy(),
            right.dist_coeffs.copy(), size, flags=flags, criteria=crit)[:7]
    finally:
        cv2.setNumThreads(threads)
    return (float(rms), np.asarray(k_l, float), np.asarray(d_l, float).ravel()[:5], np.asarray(k_r, float),
            np.asarray(d_r, float).ravel()[:5], make_transform(np.asarray(R, float), np.asarray(T, float).ravel()))


def _intrinsics(k: np.ndarray) -> np.ndarray:
    return np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2]])


def _spread(samples: list) -> np.ndarray:
    """The jackknife's 1-sigma of each column of ``samples`` (one row per left-out pair)."""
    a = np.asarray(samples, float)
    m = len(a)
    return np.sqrt((m - 1) / m * np.sum((a - a.mean(axis=0)) ** 2, axis=0))


def calibrate_stereo(pairs: Sequence[tuple[str, np.ndarray, np.ndarray]], board: Chessboard | CharucoSpec,
                     settings: CameraSettings | None = None, detector: str = "opencv",
                     progress: Callable[[int, int], None] | None = None) -> StereoCalibration:
    """Calibrate the pair from ``pairs`` (name, left image, right image) of ``board``
    (:class:`CalibrationError` with the reason when it cannot: images of different sizes,
    too few pairs with the board in both images, and each camera's own checks)."""
    settings = CameraSettings() if settings is None else settings
    if not pairs:
        raise CalibrationError("no image pairs to calibrate from")
    sizes = {(img.shape[1], img.shape[0]) for _, a, b in pairs for img in (a, b)}
    if len(sizes) != 1:
        raise CalibrationError(f"the images are of different sizes {sorted(sizes)}: both cameras must give one size")
    (size,) = sizes
    n = len(pairs)
    left_found = detect_views([(name, a) for name, a, _ in pairs], board, detector,
                              progress=None if progress is None else lambda k, _n: progress(k, 2 * n))
    right_found = detect_views([(name, b) for name, _, b in pairs], board, detector,
                               progress=None if progress is None else lambda k, _n: progress(n + k, 2 * n))
    both, rejected = [], []
    for dl, dr in zip(left_found, right_found, strict=True):
        if dl.image_px is None or dr.image_px is None:
            side = "either image" if dl.image_px is None and dr.image_px is None else (
                "the left image" if dl.image_px is None else "the right image")
            rejected.append((dl.name, f"no board found in {side}"))
        elif len(dl.image_px) != len(dr.image_px) or not np.array_equal(dl.object_mm, dr.object_mm):
            rejected.append((dl.name, "the two images show different corners of the board"))
        else:
            both.append((dl, dr))
    if len(both) < settings.min_views:
        raise CalibrationError(f"too few pairs with the board in both images: {len(both)} of {n}, need at least "
                               f"{settings.min_views} (move the board where both cameras see it whole)")
    left = calibrate_view([dl for dl, _ in both], size, "left", settings, detector)
    right = calibrate_view([dr for _, dr in both], size, "right", settings, detector)
    used = [(dl, dr) for dl, dr in both if dl.name in left.view_names and dr.name in right.view_names]
    for dl, _ in both:
        if dl.name not in left.view_names or dl.name not in right.view_names:
            rejected.append((dl.name, "left out of one camera's calibration (blurred)"))
    if len(used) < settings.min_views:
        raise CalibrationError(f"too few sharp pairs: {len(used)}, need at least {settings.min_views}")
    obj = [np.asarray(dl.object_mm, np.float32).reshape(-1, 1, 3) for dl, _ in used]
    img_l = [np.asarray(dl.image_px, np.float32).reshape(-1, 1, 2) for dl, _ in used]
    img_r = [np.asarray(dr.image_px, np.float32).reshape(-1, 1, 2) for _, dr in used]
    rms, k_l, d_l, k_r, d_r, right_T_left = _stereo(obj, img_l, img_r, left, right, size)
    # jackknife: each pair left out once, the joint refinement again (the hand-eye's spread)
    rows = []
    for k in range(len(used)):
        keep = [i for i in range(len(used)) if i != k]
        _, jk_l, _, jk_r, _, T = _stereo([obj[i] for i in keep], [img_l[i] for i in keep],
                                         [img_r[i] for i in keep], left, right, size)
        rows.append([*x_from_transform(T), float(np.linalg.norm(T[:3, 3])), *_intrinsics(jk_l), *_intrinsics(jk_r)])
    spread = _spread(rows)
    names = ("a_u", "a_v", "u0", "v0")

    def refined(cal: ViewCalibration, k: np.ndarray, d: np.ndarray, sd: np.ndarray) -> ViewCalibration:
        sigma = {**cal.sigma, **{n: float(v) for n, v in zip(names, sd, strict=True)}}
        return dataclasses.replace(cal, camera_matrix=k, dist_coeffs=d, sigma=sigma)

    return StereoCalibration(left=refined(left, k_l, d_l, spread[7:11]), right=refined(right, k_r, d_r, spread[11:15]),
                             right_T_left_mm=right_T_left, rms_px=rms,
                             sigma_x={k: float(v) for k, v in zip(_X_NAMES, spread[:6], strict=True)},
                             sigma_baseline_mm=float(spread[6]), pairs=tuple(dl.name for dl, _ in used),
                             rejected=tuple(rejected))


def read_pairs(folder: str | Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """[(name, left grey, right grey)] from ``folder/left/NAME`` and ``folder/right/NAME``
    (the same file name in both: one pair), sorted by name. :class:`CalibrationError` for
    a missing folder, no images, an image without its other half (named) or one that does
    not read."""
    import cv2

    root = Path(folder)
    files = {}
    for side in ("left", "right"):
        d = root / side
        if not d.is_dir():
            raise CalibrationError(f"{d}: no such folder (a stereo set is {root}/left/NAME.png and "
                                   f"{root}/right/NAME.png, one pair per name)")
        files[side] = {f.name: f for f in d.iterdir() if f.suffix.lower() in PAIR_SUFFIXES}
    if not files["left"] and not files["right"]:
        raise CalibrationError(f"{root}: no images in left/ and right/ ({', '.join(PAIR_SUFFIXES)})")
    for side, other in (("left", "right"), ("right", "left")):
        lonely = sorted(set(files[side]) - set(files[other]))
        if lonely:
            raise CalibrationError(f"{root / side / lonely[0]}: no {other} image of the same name"
                                   + (f" (and {len(lonely) - 1} more)" if len(lonely) > 1 else ""))
    out = []
    for name in sorted(files["left"]):
        imgs = []
        for side in ("left", "right"):
            img = cv2.imread(str(files[side][name]), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise CalibrationError(f"{files[side][name]}: not a readable image")
            imgs.append(img)
        out.append((name, imgs[0], imgs[1]))
    return out


def _camera(cal: ViewCalibration) -> StereoCamera:
    return StereoCamera(a_u=cal.a_u, a_v=cal.a_v, u0=cal.u0, v0=cal.v0,
                        dist_coeffs=tuple(float(v) for v in cal.dist_coeffs))


def apply_stereo_to_rig(rig: Rig, result: StereoCalibration, date: str) -> Rig:
    """The rig of kind ``"stereo"`` with ``[stereo]`` from ``result``; its calibration's
    sigma: the baseline's (``right_T_left_x``, mm), the note every number's. The rig's
    ``camera_T_right_x`` is kept: where the rig's camera frame (the hand-eye's) sits on the
    right camera, which a calibration of the pair does not move (a fresh rig's: the right
    camera's own frame)."""
    note = (f"pairs {len(result.pairs)}, stereoCalibrate RMS {result.rms_px:.3f} px, baseline "
            f"{result.baseline_mm:.2f} +- {result.sigma_baseline_mm:.2g} mm; right_T_left 1-sigma "
            + ", ".join(f"{k} {v:.2g}" for k, v in result.sigma_x.items())
            + f"; left {result.left.rms_px:.3f} px, right {result.right.rms_px:.3f} px RMS (Zhang, before the joint "
            "refinement)")
    try:
        stereo = Stereo(image_width_px=int(result.left.image_size_px[0]),
                        image_height_px=int(result.left.image_size_px[1]),
                        left=_camera(result.left), right=_camera(result.right),
                        right_T_left_x=tuple(float(v) for v in x_from_transform(result.right_T_left_mm)),
                        camera_T_right_x=rig.stereo.camera_T_right_x,
                        calibration=Calibration(method="stereo-zhang", date=date, note=note,
                                                sigma={"right_T_left_x": float(result.sigma_baseline_mm)}))
    except ValueError as e:
        raise CalibrationError(f"the calibrated pair is not a valid rig: {e}") from None
    return dataclasses.replace(rig, kind="stereo", stereo=stereo)


# The name the job's stages apply their result by (humanpt.twin.teach.STAGES).
apply_to_rig = apply_stereo_to_rig


def stereo_report_lines(result: StereoCalibration) -> list[str]:
    """The report: each camera's estimate, the pair's pose with its 1-sigma, what was left out."""
    lines = []
    for cal in (result.left, result.right):
        s = cal.sigma
        lines.append(f"{cal.view} camera: a_u {cal.a_u:.2f} +- {s.get('a_u', 0):.2g}, a_v {cal.a_v:.2f} +- "
                     f"{s.get('a_v', 0):.2g}, u0 {cal.u0:.2f} +- {s.get('u0', 0):.2g}, v0 {cal.v0:.2f} +- "
                     f"{s.get('v0', 0):.2g} px; {cal.rms_px:.3f} px RMS over {len(cal.view_names)} views")
    x = x_from_transform(result.right_T_left_mm)
    lines.append("right_T_left: " + ", ".join(f"{k.rsplit('_', 1)[0]} {v:.3f} +- {result.sigma_x[k]:.2g} "
                                              f"{k.rsplit('_', 1)[1]}" for k, v in zip(_X_NAMES, x, strict=True)))
    lines.append(f"baseline {result.baseline_mm:.3f} +- {result.sigma_baseline_mm:.2g} mm; stereoCalibrate "
                 f"{result.rms_px:.3f} px RMS over {len(result.pairs)} pairs")
    for name, why in result.rejected:
        lines.append(f"left out {name}: {why}")
    return lines
