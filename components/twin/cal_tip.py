"""Driver-tip calibration on the twin: the operator pivots the target on its needle's tip
held on a fixed point (the paper's Section 4.1), the controller's ``calibrate`` mode fits
the tip, and the result goes into the rig.  Nothing here reads the world's true tip except
to report against it."""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np

from humanpt.calibration.tip import (
    TipResult,
    paper_result,
    pattern_centre_px,
    pivot_point_from_views,
    tip_result_from_event,
)
from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry.rig import Rig, viewing_world_T_flange
from humanpt.geometry.transforms import invert_transform, matrix_from_rotvec, transform_from_x
from humanpt.geometry.units import to_mm
from humanpt.operator import OperatorConfig
from humanpt.operator.scenario import NEEDLE_MM
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header

from .evaluate import truth_at, truths_from
from .report import Check, TruthLines
from .run import SystemConfig
from .system import build_system
from .worlds import World

__all__ = ["pivot_scenario", "calibrate_tip_on_twin", "PIVOT_TILT_DEG", "PIVOT_SPREAD_DEG", "PIVOT_SAMPLES", "PrintedCircle", "measure_pivot_point_on_twin",
           "PIVOT_X", "METHODS"]

METHODS = ("pivot", "paper")
# Where the pivot scenario holds the tip (world, mm/deg: the table at z = 0, the frame of the
# target's start pose); the paper's P' is printed there.
PIVOT_X = (236.0, 1249.0, 0.0, 0.0, 0.0, 180.0)


class PrintedCircle:
    """A black disc of ``radius_mm`` printed on white paper (the plane z = 0 of its frame,
    centred on its origin), for :func:`humanpt.sim_camera.board.render_board` (reflectance
    and a cell per region, the edge pixels supersampled)."""

    def __init__(self, radius_mm: float = 5.0):
        self.radius_mm = float(radius_mm)

    def reflectance(self, x_mm, y_mm):
        inside = np.hypot(np.asarray(x_mm), np.asarray(y_mm)) <= self.radius_mm
        return np.where(inside, 0.05, 0.9)

    def cell_id(self, x_mm, y_mm):
        return (np.hypot(np.asarray(x_mm), np.asarray(y_mm)) <= self.radius_mm).astype(np.int64)


def measure_pivot_point_on_twin(world: World, rig: Rig, seed: int = 0, n_poses: int = 10,
                                pivot_x=PIVOT_X) -> tuple[np.ndarray, list[str], float]:
    """Section 4.1, eq. (10)-(11), on the twin: a circle printed at P' (``pivot_x``) is
    rendered by the world's camera (its true optics and hand-eye; one view at a time, the
    other covered) from ``n_poses`` robot poses around the one that views it; its centre is
    found in each view (:func:`pattern_centre_px`), triangulated with the rig's PSVS and
    carried to the world with the rig's hand-eye. Returns (P' mm (3,), report lines, its
    distance from the true point mm: the twin's truth, for the report only)."""
    from humanpt.sim_camera.board import render_board

    if n_poses < 1:
        raise ValueError(f"the pattern needs at least one robot pose, got {n_poses}")
    cfg = SystemConfig.for_scenario("static", seed=seed, rig=rig, world=world)
    cam = cfg.sim_camera  # the world's camera: true optics, true hand-eye
    params = cam.psvs.params()
    true_f_T_c = cam.flange_T_camera
    world_T_print = transform_from_x(np.asarray(pivot_x, dtype=float))
    base = viewing_world_T_flange(world_T_print, flange_T_camera=rig.hand_eye.flange_T_camera_mm())
    rng = np.random.default_rng([int(seed), 4101])
    circle = PrintedCircle()
    flanges, uv_r, uv_l = [], [], []
    for _ in range(n_poses):
        F = base.copy()
        F[:3, :3] = matrix_from_rotvec(np.radians(rng.uniform(-3.0, 3.0, 3))) @ F[:3, :3]
        F[:3, 3] += rng.uniform(-20.0, 20.0, 3)
        camera_T_print = invert_transform(F @ true_f_T_c) @ world_T_print
        uv = [pattern_centre_px(render_board(params, view, camera_T_print, circle, cam, rng))
              for view in ("right", "left")]
        flanges.append(F)
        uv_r.append(uv[0])
        uv_l.append(uv[1])
    p, per = pivot_point_from_views(rig, np.array(flanges), np.array(uv_r), np.array(uv_l))
    spread = float(np.max(np.linalg.norm(per - p, axis=1)))
    lines = [f"P' = ({', '.join(f'{v:.3f}' for v in p)}) mm: the printed circle's centre through the PSVS "
             f"over {n_poses} robot poses (eq. 10-11; the poses' points within {spread:.3f} mm of their mean)"]
    return p, lines, float(np.linalg.norm(p - world_T_print[:3, 3]))


# The tip's acceptance: every taught point moves with its error, so at most the seam fit's
# tolerance (0.2 mm, humanpt.seam.fit.FitConfig).
ACCEPT_MM = 0.2
# The paper's procedure (P' measured, then eq. 12-13): issue 33.4's acceptance.
ACCEPT_PAPER_MM = 0.3

# The twin operator's pivot for the tip stage: +-30 deg (a +-20 deg pivot found the tip's
# component along the needle from a cone 3.6 mm deep: a pose error that follows the tilt
# moved it by its size over that depth), poses at least 1.5 deg apart (at 0.5 deg the 300
# poses were all taken in the first 70 % of the pivot, ten a second, neighbours' errors
# alike), and 160 of them (about 80 % of the ~200 the pivot gives: the controller ends when
# it has them), at 7.5 deg/s (at 5 deg/s the stage took 50 s of twin time instead of 35 for
# no better tip).  Figures: docs/results.md, "The tip's bias and its sigma".
PIVOT_TILT_DEG = 30.0
PIVOT_SPREAD_DEG = 1.5
PIVOT_SAMPLES = 160
PIVOT_SPEED_DEG_S = 7.5


def pivot_scenario(driver_mm=NEEDLE_MM, angular_speed_deg_s: float = 5.0, tilt_deg: float = 20.0) -> str:
    """The scenario text of a pivot: the operator holds the needle's tip (``driver_mm``, TOB
    frame) on a point of the table and turns the target about it, +-``tilt_deg`` about two axes,
    slowly, as a welder would. At 5 deg/s (the default) the fit gets 300 poses 0.5 deg apart
    and the hand's tremor averages out (80 poses 1.5 deg apart: 0.2-0.45 mm off the true tip
    with 0.2 mm / 0.2 deg of tremor; 300: 0.08 mm)."""
    x, y, z = driver_mm
    a = float(tilt_deg)
    return f"""scenario pivot
driver {x:g} {y:g} {z:g}
path tip
start 236 1249 0 0 0 180
angular_speed {angular_speed_deg_s:g}
dwell 1.5
line 236 1249 0 {a:g} 0 180
line 236 1249 0 {a:g} {a:g} 180
line 236 1249 0 {-a:g} {a:g} {180 - a:g}
line 236 1249 0 {-a:g} {-a:g} {180 + a:g}
line 236 1249 0 {a:g} {-a:g} {180 - a:g}
line 236 1249 0 0 0 180
"""


def _keep_truth(w, ctl: ControllerCore, keep: dict) -> None:
    """The controller's fitted poses and the twin's truth at their stamps (the filter's
    state each one was taken from), into ``keep``."""
    fitted = np.array([to_mm(a) for a, _ in ctl.cal_samples])
    states = [s for s in (pb.TobState.FromString(o.data) for o in w.outputs("pose_filter/tob_state"))
              if s.after_measurement]
    poses = np.array([to_mm(from_pose(s.world_T_tob_at_measurement))[:3, 3] for s in states])
    stamps = np.array([s.measurement_stamp_ns for s in states], dtype=np.int64)
    pick = [int(np.argmin(np.linalg.norm(poses - f[:3, 3], axis=1))) for f in fitted]
    keep.update(fitted=fitted, true_tob=truth_at(w, stamps[pick]),
                true_tip_world=truth_at(w, stamps[pick], field="world_T_tip")[:, :3, 3],
                span_s=float((stamps[pick[-1]] - stamps[pick[0]]) * 1e-9))


class TipCalibrationError(RuntimeError):
    """The pivot calibration did not finish (target lost, too little rotation...)."""


def calibrate_tip_on_twin(world: World, rig: Rig, seed: int = 0, samples: int = PIVOT_SAMPLES,
                          progress: Callable[[float, float], None] | None = None,
                          driver_mm=NEEDLE_MM, method: str = "pivot",
                          pattern_poses: int = 10, *, min_spread_deg: float = PIVOT_SPREAD_DEG,
                          tilt_deg: float = PIVOT_TILT_DEG, angular_speed_deg_s: float = PIVOT_SPEED_DEG_S,
                          keep: dict | None = None) -> tuple[TipResult, list[str], list[str]]:
    """Pivot the twin's target (design driver ``driver_mm``, the world's true one may
    differ) and find its tip with the pipeline on ``rig``: ``method`` ``pivot`` (the
    least-squares pivot fit) or ``paper`` (Section 4.1 as written: P' measured first as the
    centre of a printed circle through the PSVS over ``pattern_poses`` robot poses, eq.
    10-11, then eq. 12-13 on the poses collected while the target pivots on P'). Returns
    (result, report lines, lines against the twin's truth). Raises TipCalibrationError
    when it does not finish. ``min_spread_deg``: the least rotation between two fitted
    poses; ``tilt_deg``, ``angular_speed_deg_s``: the pivot's (:func:`pivot_scenario`). ``keep`` (a dict, for a
    diagnosis against the truth, :mod:`humanpt.twin.tip_bias`): filled with the fitted poses
    (``fitted`` (N, 4, 4) mm, in their order) and the true TOB and tip at their stamps
    (``true_tob`` (N, 4, 4), ``true_tip_world`` (N, 3) mm)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    report: list[str] = []
    cal_args: dict = {"samples": samples}
    if method == "paper":
        pivot_mm, report, p_off = measure_pivot_point_on_twin(world, rig, seed, pattern_poses)
        cal_args["pivot_mm"] = [round(float(v), 4) for v in pivot_mm]
    text = pivot_scenario(driver_mm, angular_speed_deg_s, tilt_deg=tilt_deg)
    cfg = SystemConfig.for_scenario(OperatorConfig(scenario_text=text, start_delay_s=1.0), seed, rig=rig, world=world,
                                    controller=ControllerConfig(has_driver=False, calibration_samples=samples,
                                                                calibration_min_spread_deg=min_spread_deg))
    # The stand-in robot carries the camera: while the target pivots +-30 deg the servo turns
    # the flange with it, which takes the simulated Puma's wrist to its joint limits at this
    # mounting (a welder would pivot within the arm's reach; the tip's fit does not depend on
    # the arm).
    w = build_system(cfg.operator, seed=seed, controller=cfg.controller, robot="standin", rig=cfg.rig,
                     sim_camera=cfg.sim_camera, perception=cfg.perception, pose_filter=cfg.pose_filter,
                     keep_outputs=True, digest=False, robot_overrides=cfg.robot_overrides)
    limit_s = 90.0
    try:
        w.run_for(2.0)
        w.lockstep.inject(w.now_ns, "controller", "console/command",
                          pb.Command(header=header(w.now_ns), component="controller", verb="calibrate",
                                     args_json=json.dumps(cal_args)))
        done = failed = None
        while w.now_ns < limit_s * 1e9 and done is None and failed is None:
            w.run_for(1.0)
            if progress:
                progress(w.now_ns / 1e9, limit_s)
            for o in w.outputs("controller/events"):
                ev = pb.Event.FromString(o.data)
                if ev.code == "calibration_done":
                    done = ev
                elif ev.code == "calibration_failed":
                    failed = ev
        ctl = next(c for c in w.extra if isinstance(c, ControllerCore))
        # The twin's truth, for the report only: where the true tip was (it stays on the
        # pivot point but for the hand's tremor).
        tips = [p["world_T_tip"][:3, 3] for _, p in truths_from(w.outputs("operator/truth")) if "world_T_tip" in p]
        world_p_true_mm = np.mean(tips, axis=0) if tips else np.asarray(PIVOT_X[:3], dtype=float)
        if keep is not None and done is not None:
            _keep_truth(w, ctl, keep)
    finally:
        w.close()
    if failed is not None or done is None:
        why = failed.text if failed is not None else f"not done after {limit_s:g} s (target lost, too few poses?)"
        raise TipCalibrationError(f"tip calibration failed: {why}")
    res = tip_result_from_event(done.text, ctl.rig.tip.calibration.sigma.get("tob_t_tip_mm"))
    how = "pivot fit"
    if method == "paper":
        try:
            res = paper_result(res)
        except ValueError as e:
            raise TipCalibrationError(f"tip calibration failed: {e}") from None
        how = "eq. 12-13 on P'"
    report = report + [f"tip: tob_t_tip = ({', '.join(f'{v:.3f}' for v in res.tob_t_tip_mm)}) mm +- "
                       f"{res.sigma_mm:.3f} mm ({how}, {res.samples} poses, residual RMS {res.residual_rms_mm:.3f} mm)"]
    true_tip = np.asarray(cfg.operator.build_scenario().driver_mm, dtype=float)
    if keep is not None:
        keep["true_tip"] = true_tip
    err = np.asarray(res.tob_t_tip_mm) - true_tip
    accept = (f"acceptance {ACCEPT_PAPER_MM:g} mm" if method == "paper" else
              "with the measured TOB frame's own bias, which the tip takes up")
    truth = TruthLines([f"tip: true ({', '.join(f'{v:.3f}' for v in true_tip)}) mm; calibrated off by "
                        f"{np.linalg.norm(err):.3f} mm ({accept}; the design value was off by "
                        f"{np.linalg.norm(np.asarray(driver_mm) - true_tip):.3f} mm)"])
    if method == "paper":
        truth.append(f"P': {p_off:.3f} mm off the true pivot point")
        truth.checks.append(Check("tip", "off the truth", float(np.linalg.norm(err)), ACCEPT_PAPER_MM, "mm"))
    else:
        # What a taught point gets, and the pivot fit's check: the calibrated tip carried by
        # the measured poses lands on the fitted pivot point on average.  A bias of the
        # measured TOB frame that is the same at every pose (perception's, at the servo's
        # camera-to-target pose: 0.14-0.28 mm along the TOB's z on the realistic world after
        # calibration) moves the tip vector off the true one by as much but not this point:
        # the tip takes it up and it cancels while teaching at the same pose.
        p_err = np.asarray(res.world_p_pivot_mm) - world_p_true_mm
        truth.append(f"tip: the calibrated tip on the measured poses lands {np.linalg.norm(p_err):.3f} mm off the true "
                     f"tip (({', '.join(f'{v:+.3f}' for v in p_err)}) mm, the fitted pivot point against the true one: "
                     f"what a taught point gets from this stage)")
        truth.checks.append(Check("tip", "tip point in the world off the truth", float(np.linalg.norm(p_err)), ACCEPT_MM, "mm"))
    return res, report, truth
