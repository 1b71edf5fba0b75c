"""PSVS calibration (issue 17, the paper's (d)): each virtual camera's pose relative to the
other, from the TOB's three sources seen by both views at several depths.

What is estimated, and why only that
------------------------------------
The two virtual cameras of eq. (3) sit at ``O1 = (b/2, 0, -b/2)`` (right) and
``O2 = (-b/2 - m, 0, -b/2 + l)`` (left), each turned by its ``rotvec_*_deg``. From image
points alone only the *relative* pose of the two views is observable: a rotation common to
both is a rotation of the camera frame (the hand-eye calibration's), a shift common to both
its origin. So the estimate is

* ``rotvec_left_deg`` (3,): the left view's rotation, the right view's staying what the
  rig says (the reference);
* ``baseline_mm`` b, with the rig's m: the views' x separation is ``b + m`` and only that
  sum is observable (b and m separately move the frame's origin); the scale comes from the
  target's known triangle (:class:`humanpt.geometry.rig.TargetGeometry`);
* optionally ``l_mm`` (the left view's forward shift, ~0.4 mm: it changes the left image's
  scale by l/z ~ 6e-4, a few hundredths of a pixel on the target, so it is poorly
  determined and fixed at the rig's value by default).

The camera's intrinsics, distortion and both principal points are the camera calibration's
(the rig's) and are held. A left principal point off in u is, to first order, a pan
(rotation about y) of ``-du0 / a_u`` rad, and one off in v a tilt about x: the estimate
absorbs them as rotations, which is what triangulation needs.

The method: bundle adjustment (Gauss-Newton) over the TOB pose of every view (6 each) and
the PSVS parameters (4 or 5), minimising the reprojection error in pixels of the three
sources in both views, with the rig's lens distortion removed from the observations first.
The 1-sigma of each parameter comes from the Gauss-Newton normal matrix scaled by the
residual variance.

Observability of the pan (the parameter that costs most): a pan of the left view by w rad
shifts its image by ``-a_u w`` px, i.e. a disparity offset, which a baseline change mimics
except for how it varies with depth; the target's known size at several depths separates
the two, and at the working depth their *combination* (what the depth depends on) is
measured directly by the target's size. See README.md for the measured figures.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from humanpt.geometry.config import PsvsConfig
from humanpt.geometry.psvs import project, triangulate
from humanpt.geometry.rig import DEFAULT_DZ_MM, Calibration, Rig
from humanpt.geometry.target import tob_frame_from_points
from humanpt.geometry.transforms import matrix_from_rotvec, rotvec_from_matrix

__all__ = [
    "CalibrationError",
    "StereoViews",
    "PsvsEstimate",
    "MIN_VIEWS",
    "MIN_DEPTH_SPAN_MM",
    "estimate_psvs",
    "depth_sigma_mm",
    "depth_sigma_text",
    "apply_to_rig",
    "report_lines",
    "views_from_measurements",
]

MIN_VIEWS = 6
"""Fewest views (images with all three sources paired in both views) an estimate takes."""
MIN_DEPTH_SPAN_MM = 80.0
"""Smallest spread of the target's depth over the views: at one depth a pan and a baseline
error cannot be told apart."""


class CalibrationError(ValueError):
    """The input cannot give a calibration; the message says why, in one line."""


@dataclass(frozen=True)
class StereoViews:
    """The target seen by both views in N images: observed (distorted) complex-image
    centres of the sources A, B, C (as perception labels them in a FULL measurement),
    ``uv_right_px`` and ``uv_left_px`` (N, 3, 2), px. ``stamp_ns`` (N,): when each image
    was taken (for the report only)."""

    uv_right_px: np.ndarray
    uv_left_px: np.ndarray
    stamp_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:
        r = np.asarray(self.uv_right_px, dtype=float).reshape(-1, 3, 2)
        left = np.asarray(self.uv_left_px, dtype=float).reshape(-1, 3, 2)
        if r.shape != left.shape:
            raise CalibrationError(f"right and left centres differ in shape: {r.shape} vs {left.shape}")
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(left))):
            raise CalibrationError("a source centre is not a finite number")
        object.__setattr__(self, "uv_right_px", r)
        object.__setattr__(self, "uv_left_px", left)
        stamps = np.asarray(self.stamp_ns, dtype=np.int64).ravel()
        object.__setattr__(self, "stamp_ns", stamps if len(stamps) == len(r) else np.arange(len(r), dtype=np.int64))

    def __len__(self) -> int:
        return len(self.uv_right_px)


@dataclass(frozen=True)
class PsvsEstimate:
    """The result of :func:`estimate_psvs`.

    ``baseline_mm`` (b, with the rig's ``m_mm``), ``rotvec_left_deg`` (3,) (camera frame,
    the right view's rotation held at the rig's), ``l_mm``; ``sigma``: 1-sigma of each
    estimated field ({"baseline_mm": mm, "rotvec_left_deg_x": deg, ...}); ``rms_px``: RMS
    reprojection error over all used views; ``view_rms_px`` (N,): per view (NaN: not
    used); ``used`` (N,) bool: views kept (a view whose error is far above the rest is
    dropped); ``depth_mm`` (N,): the target's depth (z of its centroid, camera frame) in
    each view; ``camera_T_tob_mm`` (N, 4, 4): the adjusted target poses; ``fit_baseline``,
    ``fit_l``: which fields were free."""

    baseline_mm: float
    rotvec_left_deg: tuple[float, float, float]
    l_mm: float
    sigma: dict[str, float]
    rms_px: float
    view_rms_px: np.ndarray
    used: np.ndarray
    depth_mm: np.ndarray
    camera_T_tob_mm: np.ndarray
    fit_baseline: bool = True
    fit_l: bool = False
    iterations: int = 0
    # the fitted parameters' covariance (in the order of ``sigma``'s keys: mm, deg), for
    # what it makes of a depth (:func:`depth_sigma_mm`); empty when not known
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def n_views(self) -> int:
        return int(np.sum(self.used))


# --------------------------------------------------------------------------- the model


def _ideal(rig: Rig, uv_px: np.ndarray) -> np.ndarray:
    """Observed pixels -> ideal pixels: the rig's distortion removed (the real lens's)."""
    from humanpt.geometry.distortion import undistort_pixels

    params = rig.params()
    if not params.has_distortion:
        return np.array(uv_px, dtype=float)
    return undistort_pixels(uv_px, params.real_camera_matrix, params.dist_coeffs)


class _Problem:
    """Residuals (px) of the bundle adjustment for a parameter vector
    ``[b, rx, ry, rz (deg), (l)] + N x [rotvec (rad, 3), t (mm, 3)]``."""

    def __init__(self, rig: Rig, uv_r: np.ndarray, uv_l: np.ndarray, fit_baseline: bool, fit_l: bool):
        self.rig = rig
        self.psvs = rig.psvs
        if fit_l and rig.psvs.splitter_thickness_mm is not None:
            # l becomes its own value: m and l explicit from the thickness
            p = rig.params()
            self.psvs = dataclasses.replace(rig.psvs, splitter_thickness_mm=None, m_mm=p.m_mm, l_mm=p.l_mm)
        self.tob_p_mm = rig.target_model().source_positions_mm  # (3, 3) rows A, B, C
        self.uv_r, self.uv_l = uv_r, uv_l
        self.fit_baseline, self.fit_l = fit_baseline, fit_l
        self.names = (["baseline_mm"] if fit_baseline else []) + [
            "rotvec_left_deg_x", "rotvec_left_deg_y", "rotvec_left_deg_z"] + (["l_mm"] if fit_l else [])
        self.n_global = len(self.names)
        # central-difference steps: mm, deg, (mm) for the global; rad, mm for the poses
        self.h_global = np.array(([1e-3] if fit_baseline else []) + [1e-4] * 3 + ([1e-3] if fit_l else []))
        self.h_pose = np.array([1e-6] * 3 + [1e-4] * 3)

    def config(self, g: np.ndarray) -> PsvsConfig:
        i = 0
        kw = {}
        if self.fit_baseline:
            kw["baseline_mm"] = float(g[0])
            i = 1
        kw["rotvec_left_deg"] = tuple(float(v) for v in g[i:i + 3])
        if self.fit_l:
            kw["l_mm"] = float(g[i + 3])
        return dataclasses.replace(self.psvs, **kw)

    def global0(self) -> np.ndarray:
        p = self.psvs
        return np.array(([p.baseline_mm] if self.fit_baseline else []) + list(p.rotvec_left_deg)
                        + ([self.psvs.params().l_mm] if self.fit_l else []), dtype=float)

    def points(self, poses: np.ndarray) -> np.ndarray:
        """Per-view poses (N, 6) -> the sources in the camera frame (N, 3, 3), mm."""
        rot = matrix_from_rotvec(poses[:, :3]).reshape(-1, 3, 3)
        return np.einsum("nij,kj->nki", rot, self.tob_p_mm) + poses[:, None, 3:]

    def residuals(self, g: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 12) px: (right u, v, left u, v) predicted - observed for A, B, C."""
        params = self.config(g).params()
        uv_r, uv_l = project(params, self.points(poses), distort=False)
        return np.concatenate([(uv_r - self.uv_r).reshape(-1, 6), (uv_l - self.uv_l).reshape(-1, 6)], axis=1)

    def jacobians(self, g: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(d r / d global (N, 12, G), d r / d own pose (N, 12, 6)), central differences;
        a pose parameter is stepped in every view at once (each view's residuals depend on
        its own pose only)."""
        jg = np.empty(self.uv_r.shape[:1] + (12, self.n_global))
        for k, h in enumerate(self.h_global):
            d = np.zeros_like(g)
            d[k] = h
            jg[:, :, k] = (self.residuals(g + d, poses) - self.residuals(g - d, poses)) / (2 * h)
        jp = np.empty(self.uv_r.shape[:1] + (12, 6))
        for k, h in enumerate(self.h_pose):
            d = np.zeros_like(poses)
            d[:, k] = h
            jp[:, :, k] = (self.residuals(g, poses + d) - self.residuals(g, poses - d)) / (2 * h)
        return jg, jp


def _initial_poses(rig: Rig, uv_r: np.ndarray, uv_l: np.ndarray) -> np.ndarray:
    """(N, 6) target poses from the rig's own triangulation and eq. (7), (8)."""
    p = triangulate(rig.params(), uv_r, uv_l, method="lsq", undistort=False)  # (N, 3, 3)
    tob_p = rig.target_model().source_positions_mm
    poses = np.empty((len(p), 6))
    for n, pts in enumerate(p):
        frame = tob_frame_from_points(*pts)
        # eq. (7) puts A on the TOB x axis at its model position: place the model's origin
        poses[n, :3] = rotvec_from_matrix(frame[:3, :3])
        poses[n, 3:] = pts.mean(axis=0) - frame[:3, :3] @ tob_p.mean(axis=0)
    return poses


def _solve(problem: _Problem, g: np.ndarray, poses: np.ndarray, max_iter: int = 30):
    """Gauss-Newton with the Schur complement (poses eliminated view by view)."""
    n = len(poses)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        r = problem.residuals(g, poses)
        jg, jp = problem.jacobians(g, poses)
        # per view: [A_i B_i; B_i^T C_i] with A = Jp^T Jp (6x6), B = Jp^T Jg, C = Jg^T Jg
        a = np.einsum("nki,nkj->nij", jp, jp)
        b = np.einsum("nki,nkj->nij", jp, jg)
        c = np.einsum("nki,nkj->ij", jg, jg)
        ep = np.einsum("nki,nk->ni", jp, r)
        eg = np.einsum("nki,nk->i", jg, r)
        a_inv = np.linalg.inv(a)
        s = c - np.einsum("nji,njk,nkl->il", b, a_inv, b)
        rhs = eg - np.einsum("nji,njk,nk->i", b, a_inv, ep)
        dg = -np.linalg.solve(s, rhs)
        dp = -np.einsum("nij,nj->ni", a_inv, ep + np.einsum("nij,j->ni", b, dg))
        g = g + dg
        poses = poses + dp
        # converged: steps far below any figure reported (1e-7 mm, deg, rad); the
        # central differences leave ~1e-9 of jitter, so a tighter test would not end
        if np.max(np.abs(dg)) < 1e-7 and np.max(np.abs(dp)) < 1e-7:
            break
    r = problem.residuals(g, poses)
    jg, jp = problem.jacobians(g, poses)
    a = np.einsum("nki,nkj->nij", jp, jp)
    b = np.einsum("nki,nkj->nij", jp, jg)
    c = np.einsum("nki,nkj->ij", jg, jg)
    s = c - np.einsum("nji,njk,nkl->il", b, np.linalg.inv(a), b)
    dof = max(r.size - 6 * n - problem.n_global, 1)
    var = float(np.sum(r**2)) / dof
    cov = var * np.linalg.inv(s)  # the global block of the inverse normal matrix
    return g, poses, r, cov, it


def estimate_psvs(rig: Rig, views: StereoViews, *, fit_baseline: bool = True, fit_l: bool = False,
                  min_views: int = MIN_VIEWS, min_depth_span_mm: float = MIN_DEPTH_SPAN_MM) -> PsvsEstimate:
    """Estimate the left view's rotation and the baseline (and l, ``fit_l``) from the
    target's centres in both views (module docstring). ``rig``: the rig to start from
    (intrinsics, distortion, principal points, m, the right view, the target's triangle are
    taken from it). ``fit_baseline`` False: hold the rig's baseline (the mirrors check
    does, to read a pan from the target's size). Raises :class:`CalibrationError` for too
    few views, a target at one depth only, or views the rig cannot triangulate."""
    if len(views) < min_views:
        raise CalibrationError(f"too few views of the target in both halves of the image: {len(views)} "
                               f"(need at least {min_views}, at several depths)")
    uv_r = _ideal(rig, views.uv_right_px)
    uv_l = _ideal(rig, views.uv_left_px)
    try:
        poses = _initial_poses(rig, uv_r, uv_l)
    except Exception as e:  # noqa: BLE001 - a geometry error names what is wrong with the pairs
        raise CalibrationError(f"the rig cannot triangulate the views ({e}): are the right and left centres swapped?") from None
    depth = poses[:, 5].copy()
    if np.ptp(depth) < min_depth_span_mm and (fit_baseline or fit_l):
        raise CalibrationError(f"the target was seen at one depth only ({depth.min():.0f}-{depth.max():.0f} mm): "
                               f"spread it over at least {min_depth_span_mm:.0f} mm")
    used = np.ones(len(views), dtype=bool)
    for _ in range(2):  # fit, drop views far off the rest (a wrong pair), fit again
        problem = _Problem(rig, uv_r[used], uv_l[used], fit_baseline, fit_l)
        g, p_used, r, cov, it = _solve(problem, problem.global0(), poses[used])
        poses[used] = p_used
        view_rms = np.full(len(views), np.nan)
        view_rms[used] = np.sqrt(np.mean(r**2, axis=1))
        limit = max(0.2, 5.0 * float(np.nanmedian(view_rms)))  # px: a mismatched source, not noise
        bad = used & (view_rms > limit)
        if not bad.any() or used.sum() - bad.sum() < min_views:
            break
        used &= ~bad
    cfg = problem.config(g)
    sig = np.sqrt(np.diag(cov))
    points = problem.points(poses)
    rot = matrix_from_rotvec(poses[:, :3]).reshape(-1, 3, 3)
    tf = np.tile(np.eye(4), (len(poses), 1, 1))
    tf[:, :3, :3] = rot
    tf[:, :3, 3] = poses[:, 3:]
    return PsvsEstimate(
        baseline_mm=cfg.baseline_mm,
        rotvec_left_deg=tuple(float(v) for v in cfg.rotvec_left_deg),
        l_mm=cfg.params().l_mm,
        sigma={name: float(s) for name, s in zip(problem.names, sig, strict=True)},
        rms_px=float(np.sqrt(np.mean(r**2))),
        view_rms_px=view_rms,
        used=used,
        depth_mm=points[:, :, 2].mean(axis=1),
        camera_T_tob_mm=tf,
        fit_baseline=fit_baseline,
        fit_l=fit_l,
        iterations=it,
        covariance=np.array(cov, dtype=float),
    )


def depth_sigma_mm(rig: Rig, result: PsvsEstimate, dz_mm: float = DEFAULT_DZ_MM) -> dict[str, float]:
    """1-sigma (mm) of the depth of a point on the camera's axis at ``dz_mm`` (the servo's
    distance: where every taught point is measured) triangulated with ``rig`` after
    ``result`` (:func:`apply_to_rig`): ``"psvs"`` the fit's own (its covariance of the
    baseline, the left view's rotation and l carried through eq. (4) by central
    differences, the pixels held), ``"a_u"`` the camera calibration's focal length (the
    rig's ``psvs_calibration`` sigma of a_u; 0 without one): a focal length off by a
    fraction e scales every depth by 1 + e (the target's known size and the disparity both
    give depth over focal length, so no view of the target tells it: only the board's),
    ``dz_mm e``; ``"total"`` the two combined (independent)."""
    problem = _Problem(rig, np.zeros((0, 3, 2)), np.zeros((0, 3, 2)), result.fit_baseline, result.fit_l)
    g = problem.global0()
    point = np.array([0.0, 0.0, float(dz_mm)])
    uv_r, uv_l = project(problem.config(g).params(), point, distort=False)
    jac = np.empty(len(g))
    for k, h in enumerate(problem.h_global):
        d = np.zeros_like(g)
        d[k] = h
        z = [triangulate(problem.config(gg).params(), uv_r, uv_l, undistort=False)[2] for gg in (g + d, g - d)]
        jac[k] = (z[0] - z[1]) / (2 * h)
    cov = np.asarray(result.covariance, dtype=float)
    psvs = float(np.sqrt(max(jac @ cov @ jac, 0.0))) if cov.shape == (len(g), len(g)) else float("nan")
    s_au = float(rig.psvs_calibration.sigma.get("a_u", 0.0) or 0.0)
    a_u = float(rig.params().a_u)
    focal = float(dz_mm) * s_au / a_u
    return {"psvs": psvs, "a_u": focal, "total": float(np.hypot(psvs, focal))}


def apply_to_rig(rig: Rig, result: PsvsEstimate, date: str, note: str = "") -> Rig:
    """``rig`` with the PSVS part replaced: ``baseline_mm`` (when fitted), ``rotvec_left_deg``,
    ``l_mm`` (when fitted); ``psvs_calibration`` keeps what the camera calibration wrote
    (the same table holds the intrinsics) and adds this tool: method ``"<old>+psvs-ba"``
    (``"psvs-ba"`` over a nominal one), its sigma merged in, the note appended."""
    psvs = _after(rig, result).psvs
    old = rig.psvs_calibration
    method = "psvs-ba" if old.method in ("", "nominal") else f"{old.method}+psvs-ba"
    s = result.sigma
    rot_sigma = [s[f"rotvec_left_deg_{a}"] for a in "xyz"]
    text = (f"psvs: bundle adjustment of {result.n_views} views, {result.rms_px:.3f} px RMS; 1-sigma of "
            f"rotvec_left_deg x, y, z: {rot_sigma[0]:.5f}, {rot_sigma[1]:.5f}, {rot_sigma[2]:.5f} deg"
            + (f"; {note}" if note else ""))
    # the rig file keeps one sigma per field: a rotation vector's is its largest component's
    sigma = {"rotvec_left_deg": float(max(rot_sigma))}
    sigma.update({k: float(s[k]) for k in ("baseline_mm", "l_mm") if k in s})
    cal = Calibration(method=method, date=date, note="", sigma={**old.sigma, **sigma})
    out = dataclasses.replace(rig, psvs=psvs, psvs_calibration=cal)
    if result.covariance.size:
        text += "; " + depth_sigma_text(out, result)
    cal = dataclasses.replace(cal, note=f"{old.note}; {text}" if old.note else text)
    return dataclasses.replace(out, psvs_calibration=cal)


def depth_sigma_text(rig: Rig, result: PsvsEstimate, dz_mm: float = DEFAULT_DZ_MM) -> str:
    """One line: :func:`depth_sigma_mm` at ``dz_mm``, its parts named."""
    d = depth_sigma_mm(rig, result, dz_mm)
    return (f"depth 1-sigma at {dz_mm:g} mm {d['total']:.3f} mm (this fit {d['psvs']:.3f} mm, "
            f"the focal length's {d['a_u']:.3f} mm)")


def report_lines(rig: Rig, result: PsvsEstimate) -> list[str]:
    """The estimate with its 1-sigma against the rig it started from, and the per-view
    residuals."""
    out = [f"PSVS bundle adjustment: {result.n_views} of {len(result.used)} views, depth "
           f"{np.min(result.depth_mm):.0f}-{np.max(result.depth_mm):.0f} mm, reprojection RMS "
           f"{result.rms_px:.3f} px ({result.iterations} iterations)"]
    before = rig.psvs
    if result.fit_baseline:
        out.append(f"  baseline b      {result.baseline_mm:10.4f} mm  +- {result.sigma['baseline_mm']:.4f}"
                   f"   (rig {before.baseline_mm:.4f}; with m = {rig.params().m_mm:.4f} mm held)")
    for k, axis in enumerate("xyz"):
        name = f"rotvec_left_deg_{axis}"
        what = {"x": "tilt", "y": "pan", "z": "roll"}[axis]
        out.append(f"  left view {what:4s} ({axis}) {result.rotvec_left_deg[k]:+9.4f} deg +- {result.sigma[name]:.4f}"
                   f"   (rig {before.rotvec_left_deg[k]:+.4f}; the right view held at "
                   f"{before.rotvec_right_deg[k]:+.4f})")
    if result.fit_l:
        out.append(f"  l               {result.l_mm:10.4f} mm  +- {result.sigma['l_mm']:.4f}")
    rms = result.view_rms_px
    worst = np.argsort(np.nan_to_num(rms, nan=np.inf))[::-1][:3]
    out.append(f"  per view: median {np.nanmedian(rms):.3f} px, worst "
               + ", ".join(f"#{i} ({result.depth_mm[i]:.0f} mm) {rms[i]:.3f} px" for i in worst if np.isfinite(rms[i]))
               + (f"; dropped {int(np.sum(~result.used))}: " + ", ".join(f"#{i}" for i in np.flatnonzero(~result.used))
                  if not np.all(result.used) else ""))
    if result.covariance.size:
        out.append("  " + depth_sigma_text(_after(rig, result), result))
    return out


def _after(rig: Rig, result: PsvsEstimate) -> Rig:
    """``rig`` with ``result``'s fields (its calibration table untouched)."""
    kw: dict = {"rotvec_left_deg": tuple(result.rotvec_left_deg)}
    if result.fit_baseline:
        kw["baseline_mm"] = float(result.baseline_mm)
    psvs = rig.psvs
    if result.fit_l:
        if psvs.splitter_thickness_mm is not None:
            kw["m_mm"] = psvs.params().m_mm
            kw["splitter_thickness_mm"] = None
        kw["l_mm"] = float(result.l_mm)
    return dataclasses.replace(rig, psvs=dataclasses.replace(psvs, **kw))


def views_from_measurements(measurements) -> StereoViews:
    """:class:`StereoViews` from perception's ``TobMeasurement`` messages (an iterable):
    the FULL ones (three pairs, labelled A, B, C), their pairs' right and left centres;
    every other measurement is skipped (a target seen by one view only gives no pair)."""
    from humanpt.schemas import humanpt_pb2 as pb

    right, left, stamps = [], [], []
    for m in measurements:
        if m.status != pb.TOB_STATUS_FULL or len(m.pairs) != 3:
            continue
        c = np.array([(p.u, p.v) for p in m.centers_px], dtype=float)
        right.append(c[[p.right for p in m.pairs]])
        left.append(c[[p.left for p in m.pairs]])
        stamps.append(m.header.stamp_ns)
    return StereoViews(np.array(right).reshape(-1, 3, 2), np.array(left).reshape(-1, 3, 2),
                       np.array(stamps, dtype=np.int64))
