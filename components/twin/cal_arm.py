"""The arm's kinematic calibration observed on the lock-step twin (issue 32.4).

As the hand-eye stage (:mod:`humanpt.twin.cal_handeye`, whose collection it uses): the
simulated Puma behind the ALTER gateway moves itself through poses planned around the TOB
on its fixture, waits still and averages perception's measurement and the robot's reported
flange; then :func:`humanpt.calibration.arm.solve_arm` estimates the arm's joint offsets and
DH length errors with the hand-eye and the target's pose.  The poses tilt the camera
farther about the target than the hand-eye's (:data:`PLAN`): the arm's errors show only in
how the measured target moves as the joints do.  The estimate uses only what a real cell
has (the reported flange poses, the gateway's mounting, the measurements); the world's arm
is read only to report the error against it.

The stand-in robot has no joints and exact kinematics: the stage refuses it
(:class:`humanpt.calibration.arm.ArmCalibrationError`) with the reason.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from humanpt.calibration.arm import (
    PARAMETERS,
    UNOBSERVABLE,
    ArmCalibrationError,
    ArmResult,
    solve_arm,
)
from humanpt.calibration.handeye import CollectorSettings, HandEyeError, pose_difference
from humanpt.geometry.rig import Rig

from .cal_handeye import ACCEPT_DEG, ACCEPT_MM, collect_on_twin
from .cal_stereo import true_flange_T_camera
from .report import Check, TruthLines
from .worlds import World

__all__ = ["calibrate_arm_on_twin", "collection_checks", "fixture_at_seam_start", "DEFAULT_POSES", "PLAN", "truth_lines"]

DEFAULT_POSES = 28
# Wider than the hand-eye's plan (10-20 deg of tilt, 15 deg of roll, 60 mm of distance): the
# joints must move for their errors to show.
PLAN = {"tilt_deg": (12.0, 25.0), "roll_deg": 30.0, "distance_mm": 80.0}
# How far (in its own 1-sigma) an identified error may be from the truth.
ACCEPT_SIGMAS = 3.0


def calibrate_arm_on_twin(world: World, rig: Rig, seed: int, progress: Callable[[int, int], None] | None = None,
                          *, n_poses: int = DEFAULT_POSES, settings: CollectorSettings | None = None,
                          max_twin_s: float = 300.0, world_overrides: dict | None = None, robot: str = "puma",
                          plan: dict | None = None, mount: tuple | None = None, scenario="static",
                          ) -> tuple[ArmResult, list[str], TruthLines]:
    """Calibrate the arm with the hand-eye on the twin (module doc); the arguments as
    :func:`humanpt.twin.cal_handeye.calibrate_hand_eye_on_twin`'s; ``mount``: (flange pose,
    joints deg) the Puma is mounted around, as the job will mount it to teach and weld
    (:func:`humanpt.twin.teach.mounting`; the twin places the base per job, a cell's arm
    stays where it is): the poses then move the joints where the job will; ``scenario``:
    where the TOB is held still (:func:`fixture_at_seam_start`: where the seam starts).  Returns (result, report
    lines, lines against the world's arm with their checks).  Raises
    :class:`ArmCalibrationError` on the stand-in, when too few poses were collected or the
    data do not determine the arm; nothing is written."""
    if robot != "puma":
        raise ArmCalibrationError(f"the {robot} robot has no joints (its kinematics are exact): there is no arm "
                                  "to calibrate; the stage runs on the simulated Puma")
    try:
        got = collect_on_twin(world, rig, seed, progress, n_poses=n_poses, settings=settings, max_twin_s=max_twin_s,
                              world_overrides=world_overrides, robot=robot, plan=PLAN if plan is None else plan,
                              mount=mount, scenario=scenario)
    except HandEyeError as e:
        raise ArmCalibrationError(str(e)) from None
    result = solve_arm(got.A, got.B, got.world_T_base_mm, model=got.robot_truth.model,
                       q_ref_rad=got.start_joints_rad)
    report = [f"arm on the twin (world {world.name}, seed {seed}): {len(got.samples)} of {len(got.poses)} poses "
              f"collected in {got.twin_s:.1f} s of twin time ({got.wall_s:.1f} s wall)"]
    report += [f"  {n}" for n in got.notes]
    report += result.summary_lines()
    truth = truth_lines(result, got.robot_truth, true_flange_T_camera(got.camera_truth, rig))
    truth.checks += collection_checks(got.notes, len(got.poses), len(got.samples))
    return result, report, truth


def collection_checks(notes: list[str], planned: int, collected: int) -> list[Check]:
    """A check (no truth needed) when the collection ended before its plan did (the robot
    faulted on the way: on arc seed 4 at pose 8 of 28, the wrist at its limit, and the arm
    fitted from 8 poses came out 4-7 sigma off; issue 32.4): the poses never collected,
    against none. Poses skipped one by one (not reached, target not seen) are the plan's
    own margin and are not checked."""
    ended = next((n for n in notes if "collection ended" in n), "")
    if not ended:
        return []
    return [Check("arm", f"poses not collected ({ended})", float(planned - collected), 0.0, "poses")]


def fixture_at_seam_start(operator):
    """An OperatorConfig holding the TOB still where ``operator``'s seam starts (its design
    scenario's start pose, driver and path): the arm's calibration target where the job
    will watch and weld, seen as the job sees it."""
    import dataclasses

    sc = operator.design_scenario()
    lines = ["scenario fixture"]
    if sc.driver_mm is not None:
        lines.append("driver " + " ".join(f"{v:.6g}" for v in sc.driver_mm))
    lines += [f"path {sc.path}", "start " + " ".join(f"{v:.6f}" for v in sc.start_x_mm_deg)]
    return dataclasses.replace(operator, scenario_file="", scenario_text="\n".join(lines) + "\n")


def truth_lines(result: ArmResult, robot_truth, true_flange_T_camera_mm: np.ndarray) -> TruthLines:
    """Each error's estimate against the world's arm (``robot_truth``: its
    :class:`humanpt.sim_robot.config.SimRobotConfig`), with a check per identified error
    (off the truth by at most :data:`ACCEPT_SIGMAS` of its 1-sigma); the hand-eye estimated
    with it against the true one minus what the hand-eye takes of the arm (d6 and joint 6's
    offset: module doc of :mod:`humanpt.calibration.arm`)."""
    from humanpt.geometry.transforms import make_transform, matrix_from_rotvec

    true = np.r_[robot_truth.joint_offsets_deg, robot_truth.link_length_errors_mm]
    lines = TruthLines([f"against the twin's arm ({result.model}): parameter, estimate +- 1-sigma, true"])
    for (p, (v, s)), t in zip(result.values().items(), true, strict=True):
        unit = "deg" if p.endswith("_deg") else "mm"
        if p in result.fixed:
            lines.append(f"  {p:14s} held at 0 (true {t:+.4f} {unit}): "
                         + ("unobservable" if p in UNOBSERVABLE else "not determined by the poses"))
            continue
        off = abs(v - t)
        lines.append(f"  {p:14s} {v:+.4f} +- {s:.4f} {unit}, true {t:+.4f}: off by {off:.4f} ({off / s:.1f} sigma)"
                     if s > 0 else f"  {p:14s} {v:+.4f} {unit}, true {t:+.4f}")
        if s > 0:
            lines.checks.append(Check("arm", f"{p} off the truth", off / s, ACCEPT_SIGMAS, "sigma"))
    # The hand-eye takes the flange's d6 and joint 6's offset (a shift along and a turn about z6).
    d6 = true[PARAMETERS.index("d6_mm")]
    q6 = np.radians(true[PARAMETERS.index("q6_offset_deg")])
    expect = make_transform(matrix_from_rotvec([0.0, 0.0, q6]), [0.0, 0.0, d6]) @ np.asarray(
        true_flange_T_camera_mm, dtype=float)
    dt, da = pose_difference(result.flange_T_camera_mm, expect)
    lines.append(f"  flange_T_camera with it off the true one (with d6 and joint 6's offset in it) by {dt:.4f} mm, "
                 f"{da:.4f} deg (the hand-eye's acceptance: {ACCEPT_MM:g} mm, {ACCEPT_DEG:g} deg)")
    lines.checks += [Check("arm", "the hand-eye estimated with it, position off the truth", dt, ACCEPT_MM, "mm"),
                     Check("arm", "the hand-eye estimated with it, rotation off the truth", da, ACCEPT_DEG, "deg")]
    return lines

