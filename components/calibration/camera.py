"""Camera calibration (issue 17, deliverable 1): Zhang's method [40] through OpenCV.

One virtual camera of the PSVS at a time (the other path covered, as the paper's user
covers a mirror): views of a board -> corners (OpenCV's ``findChessboardCornersSB``, the
paper's appendix detector :mod:`humanpt.calibration.corners_paper`, or OpenCV's ChArUco
detector) -> ``cv2.calibrateCameraExtended`` -> a_u, a_v, u0, v0, distortion (k1, k2, p1,
p2, k3, fewer with ``dist_model``), each with its 1-sigma, the per-view and overall
reprojection RMS.

Checks before a result is accepted (each a :class:`CalibrationError` with the reason):
no board in any image, too few views, blurred images (the edge blur, px, of every image
is measured and reported), corners covering too little of the image, too few tilted views.

Rig convention (:func:`apply_to_rig`): the rig's ``psvs.u0, v0`` are the RIGHT view's
principal point (and the centre of the lens distortion), ``du0_right_px = dv0_right_px =
0``, and ``du0_left_px, dv0_left_px`` are the LEFT view's principal point minus the right
view's. ``a_u``, ``a_v`` and the distortion are the lens's, shared by both views: taken
a_u, a_v the inverse-variance mean of both views' when both were calibrated (else the
one view's), the distortion from the right view when it was calibrated, else the left. The skew stays 0 (OpenCV's model has none; a modern sensor has none).

Units: px (image), mm (board). Image points (n, 2) float, pixel centres at integers.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from humanpt.geometry.rig import Calibration, Rig

from .board import CharucoSpec, Chessboard

__all__ = [
    "CalibrationError",
    "CameraSettings",
    "ViewDetection",
    "ViewCalibration",
    "CameraCalibration",
    "DIST_MODELS",
    "edge_blur_px",
    "detect_opencv",
    "detect_charuco",
    "detect_views",
    "calibrate_view",
    "apply_to_rig",
    "report_lines",
]

DIST_MODELS = {
    # name -> (OpenCV flags that fix the coefficients the model leaves out, its coefficients)
    "k1": ("CALIB_FIX_K2 CALIB_FIX_K3 CALIB_ZERO_TANGENT_DIST", ("k1",)),
    "k1k2": ("CALIB_FIX_K3 CALIB_ZERO_TANGENT_DIST", ("k1", "k2")),
    "k1k2p": ("CALIB_FIX_K3", ("k1", "k2", "p1", "p2")),
    "full": ("", ("k1", "k2", "p1", "p2", "k3")),
}
# "auto": k1, k2 (no tangential terms: they trade off with the principal point), then k2
# dropped when the views do not determine it (|k2| < 2 sigma: a narrow field of view).
_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")


class CalibrationError(ValueError):
    """Input that cannot give a calibration; the message says why (one line)."""


@dataclass(frozen=True)
class CameraSettings:
    """What a calibration needs besides the images.

    ``min_views``: fewer usable views are refused (Zhang needs 3; with distortion and
    the 1-sigma worth reporting, 6). ``max_blur_px``: an image whose measured edge blur
    (Gaussian sigma, px, :func:`edge_blur_px`) exceeds it is dropped as blurred (refused
    when too few remain). ``min_coverage``: the union of the boards' outlines must cover
    this fraction of the image. ``min_tilt_deg``: at least 2 views tilted more than this
    (the board's normal against the optical axis), about different axes, else the focal
    length is not observable. ``dist_model``: a key of :data:`DIST_MODELS` or ``"auto"`` (k1, k2; k2 dropped
    when it is not significant, |k2| < 2 sigma)."""

    min_views: int = 6
    max_blur_px: float = 2.0
    min_coverage: float = 0.35
    min_tilt_deg: float = 10.0
    dist_model: str = "auto"

    def __post_init__(self) -> None:
        if self.dist_model not in DIST_MODELS and self.dist_model != "auto":
            raise CalibrationError(f"dist_model must be one of {', '.join(DIST_MODELS)}, got {self.dist_model!r}")
        if self.min_views < 3:
            raise CalibrationError(f"min_views must be >= 3 (Zhang's method), got {self.min_views}")


@dataclass(frozen=True)
class ViewDetection:
    """One image's board: ``name`` (file or view number), ``image_px`` (n, 2) corners,
    ``object_mm`` (n, 3) the same corners on the board, ``blur_px`` the image's edge blur,
    ``seconds`` the detector's time; ``image_px`` is None when no board was found."""

    name: str
    image_px: np.ndarray | None
    object_mm: np.ndarray | None
    blur_px: float
    seconds: float


@dataclass(frozen=True)
class ViewCalibration:
    """One virtual camera's calibration. ``camera_matrix`` (3, 3) px, ``dist_coeffs`` (5,)
    OpenCV (k1, k2, p1, p2, k3); ``sigma`` 1-sigma of each estimated parameter (a_u, a_v,
    u0, v0 px, k1...); ``rms_px`` overall reprojection RMS; ``per_view_rms_px`` one per
    used view (``view_names``); ``camera_T_board_mm`` (n, 4, 4) each view's board pose
    in this virtual camera's frame; ``rejected`` [(name, reason)] images not used."""

    view: str
    image_size_px: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    sigma: dict[str, float]
    rms_px: float
    per_view_rms_px: tuple[float, ...]
    view_names: tuple[str, ...]
    camera_T_board_mm: np.ndarray
    n_corners: int
    coverage: float
    detector: str
    rejected: tuple[tuple[str, str], ...] = ()
    dist_model: str = "k1k2"

    @property
    def a_u(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def a_v(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def u0(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def v0(self) -> float:
        return float(self.camera_matrix[1, 2])


@dataclass(frozen=True)
class CameraCalibration:
    """The result of ``humanpt calibrate camera``: ``views`` {'right'|'left': ViewCalibration}."""

    views: dict[str, ViewCalibration] = field(default_factory=dict)

    def main(self) -> ViewCalibration:
        """The view whose a_u, a_v and distortion go to the rig (right if calibrated)."""
        return self.views["right"] if "right" in self.views else self.views["left"]


# --------------------------------------------------------------------------- detection


def _grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3:
        import cv2

        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.ndim != 2:
        raise CalibrationError(f"an image must be grey (h, w) or colour (h, w, 3), got shape {img.shape}")
    if img.dtype != np.uint8:
        img = np.clip(img, 0, 255).astype(np.uint8)
    return img


def edge_blur_px(image: np.ndarray) -> float:
    """The image's edge blur as the sigma (px) of a Gaussian that would blur a step to it:
    ``contrast / (sqrt(2 pi) * steepest gradient)``, the contrast from the 2nd and 98th
    percentiles of the grey levels, the steepest gradient the 99.8th percentile of the
    central-difference gradient magnitude (edges are a few % of a board image). About
    0.8 px for a sharp image (a step sampled by pixels), grows with defocus or motion."""
    g = _grey(image).astype(float)
    gx = 0.5 * (g[1:-1, 2:] - g[1:-1, :-2])
    gy = 0.5 * (g[2:, 1:-1] - g[:-2, 1:-1])
    grad = np.hypot(gx, gy)
    lo, hi = np.percentile(g, [2, 98])
    steep = float(np.percentile(grad, 99.8))
    if steep <= 0 or hi - lo <= 0:
        return math.inf
    return float((hi - lo) / (math.sqrt(2 * math.pi) * steep))


def _refine_window_half_px(corners: np.ndarray, board: Chessboard) -> int:
    """cornerSubPix's half window: 35 % of the smallest distance between neighbouring
    corners (the window must hold one corner only), 3..10 px. Larger windows average more
    pixels (less noise) but see more of the perspective's asymmetry."""
    grid = corners.reshape(board.rows, board.cols, 2)
    d = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(), np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    return int(np.clip(0.35 * d, 3, 10))


def detect_opencv(image: np.ndarray, board: Chessboard) -> np.ndarray | None:
    """OpenCV's chessboard detector: ``findChessboardCornersSB`` finds and numbers the
    corners (else ``findChessboardCorners``), ``cornerSubPix`` refines them with a window
    sized to the squares (on the twin's realistic sensor: 0.07 px RMS against 0.11 px for
    SB's own subpixel estimate). (n, 2) corners px in OpenCV's order, or None."""
    import cv2

    img = _grey(image)
    ok, corners = cv2.findChessboardCornersSB(img, board.pattern_size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok or corners is None:
        ok, corners = cv2.findChessboardCorners(img, board.pattern_size,
                                                flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok or corners is None:
        return None
    corners = np.asarray(corners, np.float32).reshape(-1, 1, 2).copy()
    half = _refine_window_half_px(corners.reshape(-1, 2).astype(float), board)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    corners = cv2.cornerSubPix(img, corners, (half, half), (-1, -1), crit)
    return np.asarray(corners, dtype=float).reshape(-1, 2)


def detect_charuco(image: np.ndarray, spec: CharucoSpec) -> tuple[np.ndarray, np.ndarray] | None:
    """OpenCV's ChArUco detector: (image_px (n, 2), object_mm (n, 3)) of the corners it
    identified (at least 6), or None."""
    board, detector = spec.build()
    corners, ids, _, _ = detector.detectBoard(_grey(image))
    if corners is None or ids is None or len(ids) < 6:
        return None
    obj = np.asarray(board.getChessboardCorners(), dtype=float).reshape(-1, 3)[np.asarray(ids).ravel()]
    return np.asarray(corners, dtype=float).reshape(-1, 2), obj


Detector = Callable[[np.ndarray], "tuple[np.ndarray, np.ndarray] | None"]


def detector_for(board: Chessboard | CharucoSpec, detector: str) -> Detector:
    """image -> (image_px (n, 2), object_mm (n, 3)) or None, for ``detector`` 'opencv' or
    'paper' (chessboard only)."""
    if isinstance(board, CharucoSpec):
        if detector != "opencv":
            raise CalibrationError("the paper's detector reads chessboards only: use --board chessboard")
        return lambda img: detect_charuco(img, board)
    obj = board.object_points_mm()
    if detector == "opencv":
        def run(img):
            c = detect_opencv(img, board)
            return None if c is None else (c, obj)
        return run
    if detector == "paper":
        from .corners_paper import detect_paper

        def run_paper(img):
            found = detect_paper(img, board)
            return None if found is None else (found[0], obj[found[1]])
        return run_paper
    raise CalibrationError(f"detector must be 'opencv' or 'paper', got {detector!r}")


def detect_views(images: Sequence[tuple[str, np.ndarray]], board: Chessboard | CharucoSpec,
                 detector: str = "opencv", progress: Callable[[int, int], None] | None = None) -> list[ViewDetection]:
    """Run ``detector`` on each (name, image); one :class:`ViewDetection` per image."""
    find = detector_for(board, detector)
    out = []
    for k, (name, img) in enumerate(images):
        grey = _grey(img)
        t0 = time.perf_counter()
        found = find(grey)
        dt = time.perf_counter() - t0
        blur = edge_blur_px(grey)
        if found is None:
            out.append(ViewDetection(name, None, None, blur, dt))
        else:
            out.append(ViewDetection(name, found[0], found[1], blur, dt))
        if progress is not None:
            progress(k + 1, len(images))
    return out


# --------------------------------------------------------------------------- calibration


def _coverage(points: Sequence[np.ndarray], size: tuple[int, int]) -> float:
    """Fraction of the image inside the union of the boards' convex hulls (on a 1/4-scale
    mask)."""
    import cv2

    w, h = size
    mask = np.zeros((max(1, h // 4), max(1, w // 4)), np.uint8)
    for p in points:
        hull = cv2.convexHull(np.asarray(p / 4.0, np.float32).reshape(-1, 1, 2)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 1)
    return float(mask.mean())


def _tilts_deg(rvecs) -> np.ndarray:
    """(n, 2) each board's tilt about the camera's x and y axes (deg): the angle of its
    normal (board z) against the optical axis, split into its two components."""
    from humanpt.geometry.transforms import matrix_from_rotvec

    out = []
    for r in rvecs:
        n = matrix_from_rotvec(np.asarray(r, float).ravel()) @ np.array([0.0, 0.0, 1.0])
        out.append((math.degrees(math.atan2(-n[1], n[2])), math.degrees(math.atan2(n[0], n[2]))))
    return np.array(out)


def _zhang(obj, img, size, model: str):
    """cv2.calibrateCameraExtended with the flags of ``model`` (no skew in OpenCV)."""
    import cv2

    flags = 0
    for name in DIST_MODELS[model][0].split():
        flags |= getattr(cv2, name)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    # On one thread: OpenCV's parallel sums differ in the last bits from run to run, and a
    # calibration that is not reproducible makes every run after it differ too (seen: the
    # same calibrate-then-teach job 0.414 then 0.422 mm from the seam).
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        return cv2.calibrateCameraExtended(obj, img, size, None, None, flags=flags, criteria=crit)
    finally:
        cv2.setNumThreads(threads)


def calibrate_view(detections: Sequence[ViewDetection], image_size_px: tuple[int, int], view: str = "right",
                   settings: CameraSettings | None = None, detector: str = "opencv") -> ViewCalibration:
    """Zhang's method on the detected views of one virtual camera (``cv2.calibrateCameraExtended``,
    no skew, the distortion of ``settings.dist_model``). Raises :class:`CalibrationError`
    with the reason: no board, blurred, too few views, too little coverage, too few tilts."""

    from humanpt.geometry.transforms import make_transform, matrix_from_rotvec

    settings = CameraSettings() if settings is None else settings
    if not detections:
        raise CalibrationError("no images to calibrate from")
    found = [d for d in detections if d.image_px is not None]
    if not found:
        raise CalibrationError(f"no board found in any of the {len(detections)} images "
                               "(check --board, the pattern size, the lighting)")
    rejected = [(d.name, "no board found") for d in detections if d.image_px is None]
    sharp = []
    for d in found:
        if not d.blur_px <= settings.max_blur_px:
            rejected.append((d.name, f"blurred: edge blur {d.blur_px:.2f} px > {settings.max_blur_px:.2f} px"))
        else:
            sharp.append(d)
    if len(sharp) < settings.min_views:
        blurred = len(found) - len(sharp)
        why = f" ({blurred} blurred: edge blur above {settings.max_blur_px:.2f} px)" if blurred else ""
        raise CalibrationError(f"too few views: {len(sharp)} usable of {len(detections)} images{why}, "
                               f"need at least {settings.min_views}")
    w, h = image_size_px
    coverage = _coverage([d.image_px for d in sharp], (w, h))
    if coverage < settings.min_coverage:
        raise CalibrationError(f"badly covered: the boards cover {100 * coverage:.0f} % of the image, need "
                               f"{100 * settings.min_coverage:.0f} % (move the board to the corners and edges)")
    obj = [np.asarray(d.object_mm, np.float32).reshape(-1, 1, 3) for d in sharp]
    img = [np.asarray(d.image_px, np.float32).reshape(-1, 1, 2) for d in sharp]
    model = "k1k2" if settings.dist_model == "auto" else settings.dist_model
    res = _zhang(obj, img, (int(w), int(h)), model)
    if settings.dist_model == "auto":
        k2, s_k2 = float(np.ravel(res[2])[1]), float(np.ravel(res[5])[5])
        if not abs(k2) >= 2 * s_k2:  # the views do not determine k2: fewer coefficients
            model = "k1"
            res = _zhang(obj, img, (int(w), int(h)), model)
    rms, k, dist, rvecs, tvecs, std_intr, _std_extr, per_view = res[:8]
    tilts = _tilts_deg(rvecs)
    about_x = int(np.sum(np.abs(tilts[:, 0]) > settings.min_tilt_deg))
    about_y = int(np.sum(np.abs(tilts[:, 1]) > settings.min_tilt_deg))
    if about_x < 2 or about_y < 2:
        raise CalibrationError(f"too few tilted views: {about_x} tilted about x and {about_y} about y by more than "
                               f"{settings.min_tilt_deg:.0f} deg, need 2 of each (tilt the board towards each edge)")
    std = np.asarray(std_intr, float).ravel()
    names = ("a_u", "a_v", "u0", "v0", *_DIST_NAMES)
    kept = set(DIST_MODELS[model][1])
    sigma = {n: float(std[i]) for i, n in enumerate(names) if i < len(std) and (i < 4 or n in kept)}
    dist5 = np.zeros(5)
    dist_arr = np.asarray(dist, float).ravel()
    dist5[:min(5, dist_arr.size)] = dist_arr[:5]
    poses = np.array([make_transform(matrix_from_rotvec(np.asarray(r, float).ravel()), np.asarray(t, float).ravel())
                      for r, t in zip(rvecs, tvecs, strict=True)])
    return ViewCalibration(
        view=view, image_size_px=(int(w), int(h)), camera_matrix=np.asarray(k, float), dist_coeffs=dist5,
        sigma=sigma, rms_px=float(rms), per_view_rms_px=tuple(float(v) for v in np.asarray(per_view).ravel()),
        view_names=tuple(d.name for d in sharp), camera_T_board_mm=poses,
        n_corners=int(sum(len(d.image_px) for d in sharp)), coverage=coverage, detector=detector,
        rejected=tuple(rejected), dist_model=model)


# --------------------------------------------------------------------------- the rig


def apply_to_rig(rig: Rig, result: CameraCalibration, date: str) -> Rig:
    """The rig with its camera part replaced by ``result`` (see the module docstring for
    the convention): a_u, a_v, skew 0, u0, v0 (right view), dist, du0/dv0 of the left view
    relative to the right; ``psvs_calibration`` = Calibration('zhang', date, note, sigma)
    with sigma of a_u, a_v, u0, v0, du0_left_px, dv0_left_px (px) and dist_coeffs (k1's;
    the note gives each coefficient's)."""
    if not result.views:
        raise CalibrationError("no calibrated view to write")
    main = result.main()
    psvs = rig.psvs
    changes: dict = {"a_u": main.a_u, "a_v": main.a_v, "skew": 0.0,
                     "dist_coeffs": tuple(float(v) for v in main.dist_coeffs)}
    sizes = {tuple(int(x) for x in c.image_size_px) for c in result.views.values()}
    if len(sizes) > 1:
        raise CalibrationError(f"the views were calibrated on images of different sizes {sorted(sizes)}: one camera, "
                               "one size")
    (w, h), = sizes
    if (w, h) != (psvs.image_width_px, psvs.image_height_px):
        # A camera of another size (issue 35): the rig takes the images' size. Its principal
        # point comes from the right view, so that one must be calibrated at the new size.
        if "right" not in result.views:
            raise CalibrationError(f"the images are {w} x {h} px, the rig's camera {psvs.image_width_px} x "
                                   f"{psvs.image_height_px} px: calibrate the right view (or both) at the new size, "
                                   "its principal point places the left one")
        changes.update(image_width_px=w, image_height_px=h)
    sigma = {k: v for k, v in main.sigma.items()}
    if len(result.views) == 2:  # one lens: both views' focal lengths, weighted by 1 / sigma^2
        for f in ("a_u", "a_v"):
            vals = [(getattr(c, f), c.sigma.get(f, 0.0)) for c in result.views.values()]
            if all(sd > 0 for _, sd in vals):
                w = [1.0 / sd**2 for _, sd in vals]
                changes[f] = sum(wi * v for wi, (v, _) in zip(w, vals, strict=True)) / sum(w)
                sigma[f] = 1.0 / math.sqrt(sum(w))
    if "right" in result.views:
        right = result.views["right"]
        changes.update(u0=right.u0, v0=right.v0, du0_right_px=0.0, dv0_right_px=0.0)
        right_u0, right_v0 = right.u0, right.v0
    else:  # keep the rig's right view; the left is placed relative to it
        right_u0, right_v0 = psvs.u0 + psvs.du0_right_px, psvs.v0 + psvs.dv0_right_px
        sigma.pop("u0", None)
        sigma.pop("v0", None)
    if "left" in result.views:
        left = result.views["left"]
        changes.update(du0_left_px=left.u0 - right_u0, dv0_left_px=left.v0 - right_v0)
        sl = left.sigma
        sr = result.views["right"].sigma if "right" in result.views else {"u0": 0.0, "v0": 0.0}
        sigma["du0_left_px"] = math.hypot(sl.get("u0", 0.0), sr.get("u0", 0.0))
        sigma["dv0_left_px"] = math.hypot(sl.get("v0", 0.0), sr.get("v0", 0.0))
    # the rig's sigma is one value per field: dist_coeffs gets k1's (the dominant term),
    # the note lists every coefficient's
    dist_sigma = {k: v for k, v in main.sigma.items() if k in _DIST_NAMES}
    for k in dist_sigma:
        sigma.pop(k, None)
    if "k1" in dist_sigma:
        sigma["dist_coeffs"] = dist_sigma["k1"]
    resized = (f"image size {psvs.image_width_px} x {psvs.image_height_px} -> {w} x {h} px; "
               if "image_width_px" in changes else "")
    note = (f"{resized}views {'+'.join(result.views)}, detector {main.detector}, distortion {main.dist_model} (sigma "
            + ", ".join(f"{k} {v:.2g}" for k, v in dist_sigma.items()) + "), "
            + ", ".join(f"{v}: {c.rms_px:.3f} px RMS over {len(c.view_names)} views" for v, c in result.views.items()))
    try:
        new_psvs = dataclasses.replace(psvs, **changes)
    except ValueError as e:
        raise CalibrationError(f"the calibrated camera is not a valid rig: {e}") from None
    return dataclasses.replace(rig, psvs=new_psvs, psvs_calibration=Calibration(
        method="zhang", date=date, note=note, sigma={k: float(v) for k, v in sigma.items()}))


def report_lines(result: CameraCalibration, detections: dict[str, Sequence[ViewDetection]] | None = None) -> list[str]:
    """The report: per view the used images' reprojection RMS and edge blur, the rejected
    ones with their reason, the estimate with its 1-sigma."""
    lines = []
    for view, cal in result.views.items():
        dets = {d.name: d for d in (detections or {}).get(view, ())}
        lines.append(f"{view} view: {len(cal.view_names)} views, {cal.n_corners} corners, detector {cal.detector}, "
                     f"distortion {cal.dist_model}, "
                     f"coverage {100 * cal.coverage:.0f} % of the image")
        for name, rms in zip(cal.view_names, cal.per_view_rms_px, strict=True):
            blur = f", edge blur {dets[name].blur_px:.2f} px" if name in dets else ""
            lines.append(f"  {name:<24} reprojection RMS {rms:.3f} px{blur}")
        for name, why in cal.rejected:
            lines.append(f"  {name:<24} not used: {why}")
        lines.append(f"  reprojection RMS {cal.rms_px:.3f} px overall")
        s = cal.sigma
        lines.append(f"  a_u {cal.a_u:.2f} +- {s.get('a_u', 0):.2f} px   a_v {cal.a_v:.2f} +- {s.get('a_v', 0):.2f} px")
        lines.append(f"  u0 {cal.u0:.2f} +- {s.get('u0', 0):.2f} px   v0 {cal.v0:.2f} +- {s.get('v0', 0):.2f} px")
        lines.append("  dist " + "  ".join(f"{n} {cal.dist_coeffs[i]:+.5f}" + (f" +- {s[n]:.5f}" if n in s else " (fixed)")
                                            for i, n in enumerate(_DIST_NAMES)))
    if "right" in result.views and "left" in result.views:
        r, l = result.views["right"], result.views["left"]
        lines.append(f"left - right principal point: du0 {l.u0 - r.u0:+.2f} px, dv0 {l.v0 - r.v0:+.2f} px "
                     f"(focal left/right {l.a_u / r.a_u - 1:+.2e})")
    return lines
