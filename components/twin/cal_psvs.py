"""The PSVS calibration and the mirrors check on the digital twin (issue 17).

How the views are gathered: the target stands still in the world; a planned set of camera
poses around it (depths 450-800 mm, the target spread over the image and turned up to
15 deg, a fixed seeded plan) is what the robot would move the camera to. For each pose
the twin's own camera core (:class:`humanpt.sim_camera.core.SimCameraCore`, configured
by the world: its optics, mirrors, sensor) gets the flange's and the target's truth and a
tick, and renders ``frames_per_pose`` images; perception
(:class:`humanpt.perception.core.PerceptionCore`, configured by the *rig*) measures them.
The estimators (:mod:`humanpt.calibration.psvs`, :mod:`humanpt.calibration.mirrors`) see
only perception's FULL measurements. The robot's motion between poses is not simulated
(the views are still, as a robot stopping at each pose gives). The world's truth is read
only to report the estimate against it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from humanpt.calibration import mirrors as mirrors_mod
from humanpt.calibration import psvs as psvs_mod
from humanpt.calibration.psvs import CalibrationError, PsvsEstimate, StereoViews
from humanpt.geometry.psvs import project, triangulate
from humanpt.geometry.rig import DEFAULT_DZ_MM, Rig, camera_T_desired
from humanpt.geometry.transforms import (
    compose,
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    rotvec_from_matrix,
)
from humanpt.geometry.units import to_mm
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.core import PerceptionCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header, pose_from_mm
from humanpt.sim_camera.core import SimCameraCore

from .report import Check, TruthLines
from .run import SystemConfig
from .worlds import World

__all__ = ["plan_camera_T_tob", "gather_views", "measure_at", "servo_pose_error", "calibrate_psvs_on_twin",
           "check_mirrors_on_twin", "truth_lines_psvs", "ACCEPT_DEPTH_MM"]

ACCEPT_DEPTH_MM = 0.1
"""The stage's acceptance: the TOB's depth at the servo's pose (600 mm, on the axis) within
0.1 mm, and its 1-sigma there (the focal length's and this fit's) within the same."""

Progress = Callable[[float, float], None]

WORLD_T_TOB_MM = make_transform(np.eye(3), np.array([800.0, 0.0, 300.0]))
"""Where the still target stands (any place: only camera_T_tob matters to the camera)."""


def plan_camera_T_tob(n_poses: int = 36, seed: int = 0, depth_mm: tuple[float, float] = (450.0, 800.0)) -> np.ndarray:
    """(n, 4, 4) target poses in the camera frame (mm): depths evenly over ``depth_mm``,
    the target's centre within 60 % of each view's half-field, turned by up to 15 deg about
    each axis (seeded)."""
    rng = np.random.default_rng([seed, 17])
    out = np.empty((n_poses, 4, 4))
    for k in range(n_poses):
        z = depth_mm[0] + (depth_mm[1] - depth_mm[0]) * k / max(n_poses - 1, 1)
        x = rng.uniform(-0.18, 0.18) * z  # the two views are ~b apart: both must stay inside
        y = rng.uniform(-0.25, 0.25) * z
        rot = matrix_from_rotvec(np.radians(rng.uniform(-15.0, 15.0, 3)))
        out[k] = make_transform(rot, np.array([x, y, z]))
    return out


def gather_views(world: World, rig: Rig, seed: int = 0, n_poses: int = 36, frames_per_pose: int = 2,
                 progress: Progress | None = None, perception: PerceptionConfig | None = None) -> StereoViews:
    """Render the planned poses (:func:`plan_camera_T_tob`) with the world's camera and
    measure them with perception on the rig (module docstring): the FULL measurements'
    centres as :class:`StereoViews`."""
    measured = measure_at(world, rig, plan_camera_T_tob(n_poses, seed), seed, frames_per_pose, progress,
                          perception)
    return psvs_mod.views_from_measurements(m for m, _ in measured)


def measure_at(world: World, rig: Rig, plan: np.ndarray, seed: int = 0, frames_per_pose: int = 2,
               progress: Progress | None = None, perception: PerceptionConfig | None = None
               ) -> list[tuple[pb.TobMeasurement, np.ndarray]]:
    """Render the target still at each of ``plan`` (n, 4, 4) camera_T_tob (mm, as the
    rig believes the camera: the robot puts the flange there through the rig's hand-eye)
    ``frames_per_pose`` times with the world's camera and measure each image with
    perception on the rig: [(perception's TobMeasurement, the TRUE camera_T_tob (4, 4) mm
    of that image)] (the truth for diagnostics only)."""
    cfg = SystemConfig.for_scenario("static", seed=seed, rig=rig, world=world)
    cam_cfg = dataclasses.replace(cfg.sim_camera, seed=seed)
    camera = SimCameraCore(cam_cfg)
    percept = PerceptionCore(perception or cfg.perception, rig)
    # The robot is told where to put the flange by the rig's hand-eye (all it knows); the
    # camera is then truly at the world's, so the target's true pose differs slightly.
    flange_T_camera_rig = rig.hand_eye.flange_T_camera_mm()
    flange_T_camera_true = cam_cfg.flange_T_camera
    period_ns = cam_cfg.tick_period_ns
    out: list[tuple[pb.TobMeasurement, np.ndarray]] = []
    t_ns = 0
    for k, camera_T_tob in enumerate(plan):
        world_T_flange = compose(WORLD_T_TOB_MM, invert_transform(camera_T_tob), invert_transform(flange_T_camera_rig))
        true_camera_T_tob = compose(invert_transform(compose(world_T_flange, flange_T_camera_true)), WORLD_T_TOB_MM)
        for _ in range(frames_per_pose):
            t_ns += period_ns
            outs = []
            for stamp in (t_ns - period_ns // 2, t_ns + period_ns // 2):  # the still poses around the exposure
                truth = pb.Truth(header=header(stamp, 0, "world"))
                truth.world_T_tob.CopyFrom(pose_from_mm(WORLD_T_TOB_MM))
                outs += camera.step(stamp, "operator/truth", truth)
                flange = pb.Truth(header=header(stamp, 0, "world"))
                flange.world_T_flange.CopyFrom(pose_from_mm(world_T_flange))
                outs += camera.step(stamp, "sim_robot/truth", flange)
                if stamp < t_ns:
                    outs += camera.step(t_ns, "tick", pb.Tick(header=header(t_ns), period_ns=period_ns))
            for topic, msg in outs:
                if topic == "camera/image":
                    for ptopic, pmsg in percept.step(t_ns + period_ns // 2, "camera/image", msg):
                        if ptopic == "perception/tob":
                            out.append((pmsg, true_camera_T_tob))
        if progress is not None:
            progress(k + 1, len(plan))
    return out


def servo_pose_error(world: World, rig: Rig, seed: int = 0, dz_mm: float = DEFAULT_DZ_MM,
                     frames: int = 30) -> tuple[np.ndarray, np.ndarray, int]:
    """Against the twin's TRUTH (a diagnostic: the pipeline never reads it): the TOB still
    where the servo holds it (on the camera's axis at ``dz_mm``, parallel to the camera,
    :func:`humanpt.geometry.rig.camera_T_desired`), ``frames`` images rendered by the
    world's camera and measured by perception on ``rig``: the mean of
    ``true^-1 @ measured`` camera_T_tob, as (translation (3,) mm in the TOB frame, rotation
    vector (3,) deg, frames measured FULL). Along the TOB's z (the camera's axis) it is
    the measured depth's error; a fixed-pattern noise of the world's sensor makes part of
    it particular to that place in the image."""
    err = []
    for m, true in measure_at(world, rig, np.array([camera_T_desired(dz_mm)]), seed, frames):
        if m.status == pb.TOB_STATUS_FULL:
            err.append(invert_transform(true) @ to_mm(from_pose(m.camera_T_tob)))
    if not err:
        return np.full(3, np.nan), np.full(3, np.nan), 0
    e = np.array(err)
    rot = np.degrees([rotvec_from_matrix(x[:3, :3]) for x in e])
    return e[:, :3, 3].mean(axis=0), rot.mean(axis=0), len(e)


def _true_rig(world: World, rig: Rig, seed: int) -> Rig:
    """The rig a perfect calibration would write: the world's camera optics (for the
    report against the truth only)."""
    cfg = SystemConfig.for_scenario("static", seed=seed, rig=rig, world=world)
    return dataclasses.replace(rig, psvs=cfg.sim_camera.psvs)


def depth_errors_mm(believed: Rig, true: Rig, depths_mm=(450.0, 600.0, 800.0), field_mm: float = 50.0) -> np.ndarray:
    """(len(depths), 3) error (mm) of points triangulated with ``believed`` from their
    exact images through ``true``: for each depth the worst |error| over a 5 x 5 grid
    within ``field_mm`` of the axis, of x, y, z."""
    g = np.linspace(-field_mm, field_mm, 5)
    out = []
    for z in depths_mm:
        pts = np.array([(x, y, z) for x in g for y in g])
        uv_r, uv_l = project(true.params(), pts)
        est = triangulate(believed.params(), uv_r, uv_l)
        out.append(np.max(np.abs(est - pts), axis=0))
    return np.array(out)


def truth_lines_psvs(world: World, rig_before: Rig, rig_after: Rig, seed: int,
                     estimate: PsvsEstimate | None = None) -> TruthLines:
    """The estimate against the world's truth: the views' rotations, principal points and
    baseline, what each rig gets wrong in triangulated points, and the TOB's depth at the
    servo's pose measured with each (:func:`servo_pose_error`); the checks
    (:data:`ACCEPT_DEPTH_MM`): that depth after, and (with ``estimate``) its 1-sigma there
    (:func:`humanpt.calibration.psvs.depth_sigma_mm`: the rig's own, no truth)."""
    true = _true_rig(world, rig_before, seed)
    t, a = true.psvs, rig_after.psvs
    out = TruthLines([f"against the twin's truth (world {world.name!r}):",
           f"  left view rotation: calibrated ({', '.join(f'{v:+.4f}' for v in a.rotvec_left_deg)}) deg, "
           f"true ({', '.join(f'{v:+.4f}' for v in t.rotvec_left_deg)}) deg (right view true "
           f"({', '.join(f'{v:+.4f}' for v in t.rotvec_right_deg)}))",
           f"  true left principal point off by ({t.du0_left_px:+.2f}, {t.dv0_left_px:+.2f}) px "
           f"(= a pan of {np.degrees(-t.du0_left_px / t.a_u):+.4f} deg, a tilt of {np.degrees(t.dv0_left_px / t.a_v):+.4f} deg)",
           f"  baseline: calibrated {a.baseline_mm:.4f} mm, true {t.baseline_mm:.4f} mm (b + m: "
           f"{rig_after.params().baseline_mm + rig_after.params().m_mm:.4f} vs {true.params().baseline_mm + true.params().m_mm:.4f})"])
    for name, r in (("before", rig_before), ("after", rig_after)):
        err = depth_errors_mm(r, true)
        out.append(f"  worst point error with the rig {name:6s} (x, y, z mm, within 50 mm of the axis): "
                   + "; ".join(f"{z:.0f} mm: {e[0]:.3f} {e[1]:.3f} {e[2]:.3f}" for z, e in zip((450, 600, 800), err, strict=True)))
    depth = {}
    for name, r in (("before", rig_before), ("after", rig_after)):
        dt, drot, n = servo_pose_error(world, r, seed)
        depth[name] = dt[2]
        out.append(f"  the TOB at the servo's pose ({DEFAULT_DZ_MM:g} mm on the axis), measured with the rig {name:6s} "
                   f"- true: ({', '.join(f'{v:+.3f}' for v in dt)}) mm, ({', '.join(f'{v:+.4f}' for v in drot)}) deg "
                   f"({n} images; z: the depth)")
    out.checks.append(Check("psvs", f"TOB depth at the servo's pose ({DEFAULT_DZ_MM:g} mm) off the truth",
                            abs(depth["after"]), ACCEPT_DEPTH_MM, "mm"))
    if estimate is not None and estimate.covariance.size:
        d = psvs_mod.depth_sigma_mm(rig_after, estimate)
        out.checks.append(Check("psvs", f"depth 1-sigma at {DEFAULT_DZ_MM:g} mm (the focal length's "
                                f"{d['a_u']:.3f}, this fit's {d['psvs']:.3f} mm)", d["total"], ACCEPT_DEPTH_MM, "mm"))
    return out


def calibrate_psvs_on_twin(world: World, rig: Rig, seed: int = 0, progress: Progress | None = None, *,
                           n_poses: int = 36, frames_per_pose: int = 6, fit_l: bool = False,
                           date: str = "") -> tuple[PsvsEstimate, list[str], list[str]]:
    """``humanpt calibrate psvs --twin``: gather the views (:func:`gather_views`),
    estimate (:func:`humanpt.calibration.psvs.estimate_psvs`). Returns (estimate,
    report lines, lines against the world's truth); :func:`humanpt.calibration.psvs.apply_to_rig`
    writes it into the rig. Raises CalibrationError when the views cannot give it."""
    views = gather_views(world, rig, seed, n_poses, frames_per_pose, progress)
    est = psvs_mod.estimate_psvs(rig, views, fit_l=fit_l)
    report = [f"views: {len(views)} FULL measurements of {n_poses * frames_per_pose} images "
              f"({n_poses} poses around a still target, world {world.name!r}, seed {seed})"]
    report += psvs_mod.report_lines(rig, est)
    after = psvs_mod.apply_to_rig(rig, est, date or "twin")
    return est, report, truth_lines_psvs(world, rig, after, seed, est)


def check_mirrors_on_twin(world: World, rig: Rig, seed: int = 0, progress: Progress | None = None, *,
                          n_poses: int = 36, frames_per_pose: int = 6, budget_mm: float = 0.1
                          ) -> tuple[mirrors_mod.MirrorCheck, list[str], list[str]]:
    """``humanpt calibrate mirrors --twin``: gather the views, check the mirrors against
    the rig (:func:`humanpt.calibration.mirrors.check_mirrors`). Returns (check, report
    lines, lines against the world's truth)."""
    views = gather_views(world, rig, seed, n_poses, frames_per_pose, progress)
    if len(views) == 0:
        raise CalibrationError("no view had the target in both halves of the image")
    check = mirrors_mod.check_mirrors(rig, views, budget_mm=budget_mm)
    true = _true_rig(world, rig, seed).psvs
    rel = np.subtract(true.rotvec_left_deg, true.rotvec_right_deg) - np.subtract(
        rig.psvs.rotvec_left_deg, rig.psvs.rotvec_right_deg)
    pp = np.array([np.degrees(true.dv0_left_px / true.a_v), np.degrees(-true.du0_left_px / true.a_u), 0.0])
    truth = [f"against the twin's truth (world {world.name!r}): the left view turned beyond the rig by "
             f"x {rel[0]:+.4f}, y {rel[1]:+.4f}, z {rel[2]:+.4f} deg"
             + (f" (plus its principal point, worth x {pp[0]:+.4f}, y {pp[1]:+.4f} deg)" if np.any(pp) else "")]
    return check, [f"views: {len(views)} FULL measurements ({n_poses} poses, world {world.name!r}, seed {seed})"]\
        + mirrors_mod.report_lines(check), truth
