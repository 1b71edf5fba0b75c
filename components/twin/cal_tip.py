"""Driver-tip calibration on the twin: the operator pivots the target on its needle's tip
held on a fixed point (the paper's Section 4.1), the controller's ``calibrate`` mode fits
the tip, and the result goes into the rig.  Nothing here reads the world's true tip except
to report against it."""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np

from humanpt.calibration.tip import TipResult, tip_result_from_event
from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry.rig import Rig
from humanpt.operator import OperatorConfig
from humanpt.operator.scenario import NEEDLE_MM
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

from .report import Check, TruthLines
from .run import SystemConfig
from .system import build_system
from .worlds import World

__all__ = ["pivot_scenario", "calibrate_tip_on_twin"]

# The tip's acceptance: every taught point moves with its error, so at most the seam fit's
# tolerance (0.2 mm, humanpt.seam.fit.FitConfig).
ACCEPT_MM = 0.2

def pivot_scenario(driver_mm=NEEDLE_MM, angular_speed_deg_s: float = 5.0) -> str:
    """The scenario text of a pivot: the operator holds the needle's tip (``driver_mm``, TOB
    frame) on a point of the table and turns the target about it, +-20 deg about two axes,
    slowly, as a welder would. At 5 deg/s (the default) the fit gets 300 poses 0.5 deg apart
    and the hand's tremor averages out (80 poses 1.5 deg apart: 0.2-0.45 mm off the true tip
    with 0.2 mm / 0.2 deg of tremor; 300: 0.08 mm)."""
    x, y, z = driver_mm
    return f"""scenario pivot
driver {x:g} {y:g} {z:g}
path tip
start 236 1249 0 0 0 180
angular_speed {angular_speed_deg_s:g}
dwell 1.5
line 236 1249 0 20 0 180
line 236 1249 0 20 20 180
line 236 1249 0 -20 20 160
line 236 1249 0 -20 -20 200
line 236 1249 0 20 -20 160
line 236 1249 0 0 0 180
"""


class TipCalibrationError(RuntimeError):
    """The pivot calibration did not finish (target lost, too little rotation...)."""


def calibrate_tip_on_twin(world: World, rig: Rig, seed: int = 0, samples: int = 300,
                          progress: Callable[[float, float], None] | None = None,
                          driver_mm=NEEDLE_MM) -> tuple[TipResult, list[str], list[str]]:
    """Pivot the twin's target (design driver ``driver_mm``, the world's true one may
    differ) and fit its tip with the pipeline on ``rig``. Returns (result, report lines,
    lines against the twin's truth). Raises TipCalibrationError when it does not finish."""
    text = pivot_scenario(driver_mm)
    cfg = SystemConfig.for_scenario(OperatorConfig(scenario_text=text, start_delay_s=1.0), seed, rig=rig, world=world,
                                    controller=ControllerConfig(has_driver=False, calibration_samples=samples,
                                                                           calibration_min_spread_deg=0.5))
    # The stand-in robot carries the camera: while the target pivots +-20 deg the servo turns
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
                                     args_json=json.dumps({"samples": samples})))
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
    finally:
        w.close()
    if failed is not None or done is None:
        why = failed.text if failed is not None else f"not done after {limit_s:g} s (target lost, too few poses?)"
        raise TipCalibrationError(f"tip calibration failed: {why}")
    res = tip_result_from_event(done.text, ctl.rig.tip.calibration.sigma.get("tob_t_tip_mm"))
    report = [f"tip: tob_t_tip = ({', '.join(f'{v:.3f}' for v in res.tob_t_tip_mm)}) mm +- {res.sigma_mm:.3f} mm "
              f"(pivot fit, {res.samples} poses, residual RMS {res.residual_rms_mm:.3f} mm)"]
    true_tip = np.asarray(cfg.operator.build_scenario().driver_mm, dtype=float)
    err = np.asarray(res.tob_t_tip_mm) - true_tip
    truth = TruthLines([f"tip: true ({', '.join(f'{v:.3f}' for v in true_tip)}) mm; calibrated off by "
                        f"{np.linalg.norm(err):.3f} mm (acceptance {ACCEPT_MM:g} mm; the design value was off by "
                        f"{np.linalg.norm(np.asarray(driver_mm) - true_tip):.3f} mm)"])
    truth.checks.append(Check("tip", "off the truth", float(np.linalg.norm(err)), ACCEPT_MM, "mm"))
    return res, report, truth
