"""The target measured by an ordinary stereo pair (issue 35 item 3): the same blob method
as the PSVS's (:func:`humanpt.perception.weighted.detect_weighted`) on each camera's image,
then the correspondence across the two images and OpenCV's triangulation, in the right
camera's frame, then put in the rig's camera frame (``[stereo] camera_T_right_x``;
identity for a calibrated pair, whose camera frame is the right camera's).

Correspondence: every (left, right) pair of blobs is triangulated at once
(``cv2.triangulatePoints`` on undistorted, normalised coordinates: each camera's own
intrinsics and distortion); the pairs that reproject within ``epipolar_tol_px`` in both
images at a working depth (the best ``MAX_PAIRS``) form trios of disjoint pairs, scored by
their reprojection error and their triangle's sides against the target model; the best
candidate within the model's side tolerance,
between ``min_depth_mm`` and ``max_depth_mm``, is named A, B, C (Section 4 steps 6-7:
:func:`humanpt.geometry.target.estimate_camera_T_tob`, viewed from the right camera's
centre). Pure: images in, a :class:`StereoMeasurement` out.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.errors import GeometryError
from humanpt.geometry.rig import Rig, StereoCamera
from humanpt.geometry.target import estimate_camera_T_tob, triangle_sides_mm
from humanpt.geometry.transforms import invert_transform

from .blobs import full_region
from .config import PerceptionConfig
from .correspondence import FULL, LOST, Match
from .image import mask_array
from .weighted import detect_weighted

__all__ = ["StereoMeasurement", "StereoPerception"]

MAX_PAIRS = 12  # the best-reprojecting blob pairs whose trios are tried (C(12, 3) = 220 at most)

# The live component takes a pair as ONE image, the left camera's pixels then the right's,
# side by side (what a side-by-side stereo device gives, and what the camera component
# makes of two devices' frames paired by stamp): (2 W) x H.


@dataclass(frozen=True)
class StereoMeasurement:
    """``status``: "full" (the three sources paired and named) or "lost" (``why``);
    ``camera_T_tob_mm`` (4, 4) in the rig's camera frame; ``points_mm`` (3, 3) A, B, C;
    ``uv_left_px``, ``uv_right_px`` (3, 2) their blob centres (A, B, C order);
    ``reprojection_px`` the RMS reprojection error over both images; ``side_error_mm`` the
    largest triangle side's difference from the model."""

    status: str
    why: str = ""
    camera_T_tob_mm: np.ndarray | None = None
    points_mm: np.ndarray | None = None
    uv_left_px: np.ndarray | None = None
    uv_right_px: np.ndarray | None = None
    reprojection_px: float = math.nan
    side_error_mm: float = math.nan
    left_index: tuple[int, ...] = ()  # the blobs of each image named A, B, C
    right_index: tuple[int, ...] = ()


def _normalised(cam: StereoCamera, uv_px: np.ndarray) -> np.ndarray:
    import cv2

    pts = np.asarray(uv_px, np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(pts, cam.camera_matrix(), np.asarray(cam.dist_coeffs, float)).reshape(-1, 2)


def _project(cam: StereoCamera, cam_T_world: np.ndarray, p_mm: np.ndarray) -> np.ndarray:
    import cv2

    rvec = cv2.Rodrigues(cam_T_world[:3, :3])[0]
    uv, _ = cv2.projectPoints(np.asarray(p_mm, np.float64).reshape(-1, 1, 3), rvec, cam_T_world[:3, 3],
                              cam.camera_matrix(), np.asarray(cam.dist_coeffs, float))
    return uv.reshape(-1, 2)


class StereoPerception:
    """Measures the target on (left, right) image pairs of the rig's ``[stereo]`` pair."""

    def __init__(self, config: PerceptionConfig, rig: Rig):
        self.config = config
        self.rig = rig
        self.stereo = rig.stereo
        self.model = rig.target_model()
        self.model_sides_mm = np.sort(triangle_sides_mm(self.model.source_positions_mm))
        self.right_T_left = self.stereo.right_T_left_mm()
        self.camera_T_right = self.stereo.camera_T_right_mm()
        self.left_T_right = invert_transform(self.right_T_left)
        s = self.stereo
        self.size_px = (s.image_width_px, s.image_height_px)
        a_u = max(s.left.a_u, s.right.a_u)
        self.max_radius_px = 0.5 * config.size_ratio_range[1] * a_u * self.model.source_diameter_mm / \
            config.min_depth_mm + 2.0
        self.side_by_side_px = (2 * s.image_width_px, s.image_height_px)
        self.keep = mask_array(config.mask, self.side_by_side_px)  # the mask's rectangles: side-by-side pixels

    def measure_side_by_side(self, gray: np.ndarray) -> tuple[np.ndarray, Match]:
        """The target on a side-by-side pair ((H, 2 W): left then right): every blob centre
        in the side-by-side image (the left's, then the right's shifted by W) and a
        :class:`Match` whose pairs index them (right, left), as the PSVS's perception gives
        (so the component publishes both alike)."""
        w = self.stereo.image_width_px
        keep = self.keep
        left_gray, right_gray = gray[:, :w], gray[:, w:]
        if keep is not None:
            left_gray = np.where(keep[:, :w] > 0, left_gray, 0).astype(np.uint8)
            right_gray = np.where(keep[:, w:] > 0, right_gray, 0).astype(np.uint8)
        left, right = self.detect(left_gray), self.detect(right_gray)
        uv = np.vstack([left.uv_px, right.uv_px + [w, 0.0]]).reshape(-1, 2)
        m = self._measure_blobs(left, right)
        if m.status != "full":
            return uv, Match(np.zeros((0, 2), int), np.zeros(0), np.zeros((0, 3)), None, LOST, 0.0)
        n_left = len(left)
        pairs = np.array([[n_left + r, li] for li, r in zip(m.left_index, m.right_index, strict=True)], int)
        quality = max(0.0, 1.0 - m.reprojection_px / self.config.epipolar_tol_px)
        return uv, Match(pairs, np.full(3, m.reprojection_px), m.points_mm, m.camera_T_tob_mm, FULL, quality,
                         m.side_error_mm)

    def detect(self, gray: np.ndarray):
        """The weighted method's blobs on one camera's image."""
        c = self.config
        if gray.shape[::-1] != self.size_px:
            raise ValueError(f"image of {gray.shape[1]} x {gray.shape[0]} px; the rig's stereo cameras give "
                             f"{self.size_px[0]} x {self.size_px[1]} px")
        return detect_weighted(gray, full_region(*self.size_px), threshold=c.threshold, noise_k=c.noise_k,
                               aperture_pad_px=c.aperture_pad_px, min_area_px=c.min_area_px,
                               max_area_px=c.max_area_px, max_radius_px=self.max_radius_px,
                               max_elongation=c.max_elongation, min_contrast_dn=c.min_contrast_dn,
                               max_blobs=c.max_blobs)

    def measure(self, left_gray: np.ndarray, right_gray: np.ndarray) -> StereoMeasurement:
        """The target on one image pair (each (H, W) uint8, sources bright)."""
        return self._measure_blobs(self.detect(left_gray), self.detect(right_gray))

    def _measure_blobs(self, left, right) -> StereoMeasurement:
        import cv2

        if len(left) < 3 or len(right) < 3:
            return StereoMeasurement("lost", f"{len(left)} blobs in the left image, {len(right)} in the right: "
                                             "three in each needed")
        c, s = self.config, self.stereo
        # Every (left, right) blob pair triangulated at once; only the pairs that reproject
        # within the tolerance at a working depth go on (a few per source: the cost follows
        # them, not C(n, 3)^2 choices of blobs in a cluttered image).
        li_all, ri_all = (a.ravel() for a in np.meshgrid(np.arange(len(left)), np.arange(len(right)), indexing="ij"))
        n_l, n_r = _normalised(s.left, left.uv_px), _normalised(s.right, right.uv_px)
        x = cv2.triangulatePoints(self.left_T_right[:3, :], np.hstack([np.eye(3), np.zeros((3, 1))]),
                                  n_l[li_all].T, n_r[ri_all].T)
        with np.errstate(divide="ignore", invalid="ignore"):
            p_all = (x[:3] / x[3]).T  # right camera frame, mm
        ok = np.all(np.isfinite(p_all), axis=1) & (p_all[:, 2] >= c.min_depth_mm) & (p_all[:, 2] <= c.max_depth_mm)
        li_all, ri_all, p_all = li_all[ok], ri_all[ok], p_all[ok]
        err = np.hypot(*(_project(s.right, np.eye(4), p_all) - right.uv_px[ri_all]).T) if len(p_all) else np.zeros(0)
        err_l = np.hypot(*(_project(s.left, self.left_T_right, p_all) - left.uv_px[li_all]).T) if len(p_all) else err
        keep = np.flatnonzero(np.maximum(err, err_l) <= c.epipolar_tol_px)
        keep = keep[np.argsort(err[keep] ** 2 + err_l[keep] ** 2, kind="stable")][:MAX_PAIRS]
        best = None
        for trio in itertools.combinations(keep, 3):
            li, ri = tuple(int(li_all[k]) for k in trio), tuple(int(ri_all[k]) for k in trio)
            if len(set(li)) < 3 or len(set(ri)) < 3:  # a blob in two pairs
                continue
            p_mm = p_all[list(trio)]
            sides = np.linalg.norm(p_mm - p_mm[[1, 2, 0]], axis=1)
            side_err = float(np.max(np.abs(np.sort(sides) - self.model_sides_mm)))
            if side_err > self.model.side_tolerance_mm:
                continue
            rms = float(np.sqrt(np.mean(np.concatenate([err[list(trio)], err_l[list(trio)]]) ** 2 / 2.0)))
            score = rms / c.epipolar_sigma_px + side_err / c.side_sigma_mm
            if best is None or score < best[0]:
                best = (score, li, ri, p_mm, rms)
        if best is None:
            return StereoMeasurement("lost", "no three blobs pair into the target's triangle at a working depth")
        _, li, ri, p_mm, rms = best
        # into the rig's camera frame (the hand-eye's): the right camera's pose in it
        p_mm = p_mm @ self.camera_T_right[:3, :3].T + self.camera_T_right[:3, 3]
        try:
            camera_T_tob, lab = estimate_camera_T_tob(self.model, p_mm, viewpoint_mm=self.camera_T_right[:3, 3])
        except GeometryError as e:
            return StereoMeasurement("lost", f"the paired sources are not the target: {e}")
        order = list(lab.order)
        left_index, right_index = tuple(li[k] for k in order), tuple(ri[k] for k in order)
        return StereoMeasurement("full", camera_T_tob_mm=camera_T_tob, points_mm=lab.camera_p_abc_mm,
                                 uv_left_px=left.uv_px[list(left_index)], uv_right_px=right.uv_px[list(right_index)],
                                 reprojection_px=rms, side_error_mm=lab.side_error_mm, left_index=left_index,
                                 right_index=right_index)
