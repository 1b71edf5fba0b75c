"""Calibrate, then teach, then play back: the welder's whole job on the twin (issue 17.5).

Stages, each observing the twin's world through the same components a real cell uses and
never reading its truth except to report against it:

1. camera (Zhang), 2. PSVS and mirrors, 3. hand-eye (AX = YB), 4. the arm's kinematic
   errors with the hand-eye (on the Puma, mounted as the teach-and-play run mounts it; not
   run on the stand-in), 5. driver tip: each writes its part of the rig (a stage whose
   tool is missing or fails is reported and skipped: the rig keeps what it had); on an
   ordinary stereo pair (``rig_kind="stereo"``, issue 35) one stage, the pair's
   (:mod:`humanpt.twin.cal_stereo`: both cameras and their pose), in place of 1 and 2;
6. teach: the operator moves the target along the seam, the servo follows, the path of the
   driver's tip is recorded with the calibrated rig (and moved by the calibrated arm);
7. play back: the robot's tool follows the recorded path; the tool's true path (the world's
   flange, through the torch) is measured against the seam.

The seam is the scenario as designed (no tremor, the design's path); distances to it are
taken to the nearest point of the seam (a welder judges where the torch went, not when).
"""

from __future__ import annotations

import importlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.controller.pathfile import smooth
from humanpt.controller.playback import PlaybackError, RobotArm, seam_command
from humanpt.geometry.puma import follow
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import invert_transform, transform_from_x, x_from_transform
from humanpt.geometry.units import to_mm
from humanpt.operator.scenario import DEFAULT_SPEED_MM_S, Trajectory
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header
from humanpt.seam.compare import Comparison, compare_points, polyline_seam
from humanpt.seam.fit import Seam, distance_to_seam, fit_path, sample_segment

from . import evaluate
from .run import SystemConfig
from .system import build_system, nominal_rig, operator_config, puma_mount_joints
from .world import start_flange_for
from .worlds import ERROR_SOURCES, World

# Where between watching (0) and welding (1) the seam the Puma's comfortable pose is.
MOUNT_FRACTION = 0.5

__all__ = ["STAGES", "NOT_FOR_KIND", "stereo_job", "StageResult", "TeachResult", "calibrate_then_teach", "seam_distances_mm", "mounting", "arm_share"]

# stage -> (module of humanpt.twin, entry point): each returns (result, report, truth) and has
# an ``apply_to_rig(rig, result, date)`` in humanpt.calibration.<name>.
STAGES: dict[str, tuple[str, str, str]] = {
    "camera": ("cal_camera", "calibrate_camera_on_twin", "camera"),
    "psvs": ("cal_psvs", "calibrate_psvs_on_twin", "psvs"),
    "stereo": ("cal_stereo", "calibrate_stereo_on_twin", "stereo"),  # an ordinary pair's, in their place (issue 35)
    "hand-eye": ("cal_handeye", "calibrate_hand_eye_on_twin", "handeye"),
    "arm": ("cal_arm", "calibrate_arm_on_twin", "arm"),  # the arm's errors with the hand-eye (32.4)
    "tip": ("cal_tip", "calibrate_tip_on_twin", "tip"),
}


# The stages that do not run on a rig of each kind: the PSVS's camera and mirrors are an
# ordinary stereo pair's one stage (its cameras and their pose), and the other way round.
NOT_FOR_KIND: dict[str, tuple[str, ...]] = {"psvs": ("stereo",), "stereo": ("camera", "psvs")}


def stereo_job(world: World, rig: Rig) -> tuple[World, Rig]:
    """``world`` and ``rig`` for the job on an ordinary stereo pair: the world's camera
    renders its PSVS's two virtual cameras apart (``[sim_camera] stereo``: an error source
    of the world's PSVS becomes the pair's), the rig a pair (the pair its PSVS makes,
    :meth:`humanpt.geometry.rig.Stereo.of_psvs`, unless it is one already)."""
    import dataclasses

    from humanpt.geometry.rig import Stereo

    from .worlds import merge_overrides

    world = dataclasses.replace(world, extra=merge_overrides(world.extra, {"sim_camera": {"stereo": True}}))
    if rig.kind != "stereo":
        rig = dataclasses.replace(rig, kind="stereo", stereo=Stereo.of_psvs(rig.psvs))
    return world, rig


@dataclass
class StageResult:
    name: str
    ok: bool
    seconds: float
    report: list[str] = field(default_factory=list)
    truth: list[str] = field(default_factory=list)
    error: str = ""
    checks: list = field(default_factory=list)  # humanpt.twin.report.Check: its acceptance against the truth
    skipped: str = ""  # why the stage did not run, when it has nothing to do here (no warning)


@dataclass
class TeachResult:
    """What the job gave: the stages, the rig it ended with, the taught path's and the
    played-back tool's distances to the seam (mm), and where things were written."""

    stages: list[StageResult]
    rig: Rig
    taught_mm: np.ndarray  # (N,) tip of the taught path to the seam
    smoothed_mm: np.ndarray  # (N,) the same after RTS smoothing (played back with play="smoothed")
    played_mm: np.ndarray  # (M,) the tool's true position during playback to the seam
    taught_truth: evaluate.Stats | None  # the taught path against the truth at its stamps
    warnings: list[str]
    run_dir: Path | None
    seconds: float
    fitted_mm: np.ndarray | None = None  # (K,) the fitted seam (lines and arcs, every 0.5 mm) to the seam
    fitted: Seam | None = None  # humanpt path fit of the taught path
    play: str = "seam"  # what was played back: "seam" (fitted, re-timed) or "smoothed"
    # Each of "taught", "smoothed", "fitted", "played" against the seam as designed
    # (humanpt.seam.compare.compare_points: RMS, max, coverage, the largest stretch left);
    # the played torch from the end of its approach to the path's start.
    compared: dict[str, Comparison] = field(default_factory=dict)
    # For the accuracy report (humanpt.twin.report): the seam as designed and, as polylines
    # (mm), the taught tip, the fitted seam and the played-back torch; the job's own checks
    # (the arm's kinematic error, the time offset at the taught speed).
    seam_mm: np.ndarray | None = None
    # With a calibrated arm: the seam as designed in the frame the arm's own measurements
    # define (the world turned about the arm's joint-1 axis by its zero offset, which no
    # camera on the flange can see: humanpt.calibration.arm), what the taught and fitted
    # seams are judged against; the torch is judged against ``seam_mm`` (teaching and
    # playing in the same frame, it lands on the seam).  (K, 3) mm, None without one.
    seam_arm_frame_mm: np.ndarray | None = None
    arm_frame_note: str = ""
    taught_path_mm: np.ndarray | None = None
    fitted_path_mm: np.ndarray | None = None
    played_path_mm: np.ndarray | None = None
    checks: list = field(default_factory=list)
    # On the Puma (issue 33): the largest joint step of one cycle while playing back (deg,
    # from the robot states' joints), the gateway's per-cycle limit it must stay within (the
    # sim_robot faults beyond max_joint_speed_deg_s x cycle), and why a seam was refused
    # before anything moved ("" when it was played).
    max_joint_step_deg: float | None = None
    joint_step_limit_deg: float | None = None
    refused: str = ""
    # The played torch's true poses (M, 6) mm/deg every cycle from the path's start, and the
    # taught path's (N, 6) (the tip's, else G's): Figure 9b-d.
    played_x: np.ndarray | None = None
    taught_x: np.ndarray | None = None


def seam_distances_mm(points_mm: np.ndarray, seam_mm: np.ndarray) -> np.ndarray:
    """Distance (N,) of each point (N, 3) to the polyline ``seam_mm`` (K, 3), mm
    (humanpt.seam.fit.distance_to_seam of humanpt.seam.compare.polyline_seam)."""
    return distance_to_seam(polyline_seam(seam_mm), np.asarray(points_mm, dtype=float).reshape(-1, 3))


def _compare(seam: Seam, points_mm: np.ndarray, what: str) -> Comparison | None:
    """``points_mm`` (N, 3), in order along their path, against the seam as designed
    (humanpt.seam.compare.compare_points: distances, coverage), None without points."""
    p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    return compare_points(seam, p, approach_mm=None, window=what) if len(p) else None


def _seam(op) -> np.ndarray:
    """The seam as designed (K, 3) mm: the scenario's path every 0.5 mm or so, no tremor."""
    traj = Trajectory(op.design_scenario())
    n = max(200, int(traj.duration_s * 40))
    return np.array([traj.path_pose(t)[:3, 3] for t in np.linspace(0.0, traj.duration_s, n)])


def _arm(w, rig: Rig | None = None) -> RobotArm | None:
    """The simulated Puma of the twin ``w`` as a playback plans on it (its kinematics, its
    mounting, its joints now, its joint speed limit and cycle; the gateway's flange limits;
    the arm as the rig's ``[arm]`` calibrated it, when it has one), None on the stand-in (no
    kinematics)."""
    from humanpt.sim_robot.core import SimRobotCore

    robot = next((c for c in w.lockstep.cores if isinstance(c, SimRobotCore)), None)
    if robot is None:
        return None
    gw = next((c for c in w.lockstep.cores if c.name == "robot_gateway"), None)
    limits = {} if gw is None else {"max_speed_mm_s": float(gw.config.max_speed_mm_s),
                                    "max_angular_deg_s": float(gw.config.max_angular_speed_deg_s)}
    true_arm = rig.arm.true_arm() if rig is not None and rig.arm.model == robot.config.model else None
    return RobotArm(robot.kin, robot.world_T_base.copy(), np.asarray(robot.q_setpoint_rad, dtype=float).copy(),
                    robot.config.max_joint_speed_deg_s, robot.config.cycle_ms * 1e-3, **limits, true_arm=true_arm)


def mounting(cfg: SystemConfig, robot: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Where the job mounts the robot for ``cfg``'s seam: (the flange pose watching the
    seam's start, the mounting flange pose (4, 4) mm, the Puma's joints there (deg), None
    on the stand-in).  The Puma is mounted so that both where it watches the seam (the
    camera d_z from the target) and where its torch welds it (the tool on the seam) are
    comfortably in reach: around the flange pose half way between the two, over the middle
    of the seam, in the joint pose there that keeps its wrist farthest from its singularity
    along both jobs (:func:`humanpt.twin.system.puma_mount_joints`)."""
    view = start_flange_for(cfg.operator, cfg.controller.dz_mm, cfg.sim_camera.flange_T_camera)
    seam = _seam(cfg.operator)
    first = Trajectory(cfg.operator.design_scenario()).path_pose(0.0)
    weld = first @ invert_transform(transform_from_x(np.asarray(cfg.controller.flange_T_tool_x, dtype=float)))
    mount = view.copy()
    mount[:3, 3] = MOUNT_FRACTION * weld[:3, 3] + (1 - MOUNT_FRACTION) * view[:3, 3] + (
        seam.mean(axis=0) - first[:3, 3])
    mount_joints = None
    if robot == "puma":
        traj = Trajectory(cfg.operator.design_scenario())
        along = [traj.path_pose(t) for t in np.linspace(0.0, traj.duration_s, 40)]
        tool_T_flange = invert_transform(transform_from_x(np.asarray(cfg.controller.flange_T_tool_x, dtype=float)))
        watch = np.array([p @ invert_transform(first) @ view for p in along])
        welds = np.array([p @ tool_T_flange for p in along])
        mount_joints, _ = puma_mount_joints(mount, [watch, welds])
    return view, mount, mount_joints


def arm_share(cfg: SystemConfig, rig: Rig, view: np.ndarray, mount: np.ndarray, mount_joints) -> tuple[float, float]:
    """The arm's (and the hand-eye's) share of the played-back error along ``cfg``'s seam,
    RMS mm (:func:`humanpt.twin.report.arm_share_mm`, the Puma mounted as :func:`mounting`
    says): (through the nominal arm and the rig's hand-eye, through the rig's calibrated
    arm and hand-eye; nan without one)."""
    from .report import arm_share_mm

    traj = Trajectory(cfg.operator.design_scenario())
    along = np.array([traj.path_pose(t) for t in np.linspace(0.0, traj.duration_s, 60)])
    watch = np.array([p @ invert_transform(along[0]) @ view for p in along])
    from .cal_stereo import true_flange_T_camera

    true_X = true_flange_T_camera(cfg.sim_camera, rig)  # the world's hand-eye (truth, only to report)
    tool = transform_from_x(np.asarray(cfg.controller.flange_T_tool_x, dtype=float))
    args = (cfg.robot_overrides, mount, mount_joints, watch, along, tool, rig.hand_eye.flange_T_camera_mm(), true_X)

    def rms(e):
        return float(np.sqrt(np.mean(e ** 2))) if len(e) else float("nan")

    nominal = rms(arm_share_mm(*args))
    return nominal, (rms(arm_share_mm(*args, model_arm=rig.arm.true_arm())) if rig.arm.present else float("nan"))


def _run_stage(name: str, world: World, rig: Rig, seed: int, progress, robot: str,
               mount: tuple | None = None) -> tuple[Rig, StageResult]:
    module, entry, lib = STAGES[name]
    if name == "arm" and robot != "puma":
        why = ("the UR5e's kinematics are exact on the twin (the arm stage calibrates the Puma's)" if robot == "ur"
               else f"the {robot} robot has no joints (exact kinematics)")
        return rig, StageResult(name, False, 0.0, skipped=f"{why}: no arm to calibrate")
    t0 = time.perf_counter()
    try:
        fn = getattr(importlib.import_module(f"humanpt.twin.{module}"), entry)
        apply = importlib.import_module(f"humanpt.calibration.{lib}").apply_to_rig
    except (ImportError, AttributeError) as e:
        return rig, StageResult(name, False, 0.0, error=f"not available in this build ({e})")
    try:
        # calibrate the arm that will weld (the UR5e's hand-eye on the stand-in: a camera on a flange, exact)
        kw = {"robot": "standin" if robot == "ur" else robot} if name in ("hand-eye", "arm") else {}
        if name == "arm" and mount is not None:  # where the job mounts it, the target where the seam starts
            kw["mount"], kw["scenario"] = mount
        result, report, truth = fn(world, rig, seed, progress=progress, **kw)
    except Exception as e:  # noqa: BLE001 - a failed stage is a result: the rig keeps what it had
        return rig, StageResult(name, False, time.perf_counter() - t0, error=f"{type(e).__name__}: {e}")
    date = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    return apply(rig, result, date), StageResult(name, True, time.perf_counter() - t0, list(report), list(truth),
                                                 checks=list(getattr(truth, "checks", [])))


UR_CYCLE_MS = 2.0  # the job on the UR5e: the e-Series' RTDE cycle (default)
PUMA_CYCLE_MS = 28.0  # ALTER's: the recording delay's cycles are counted in it


def calibrate_then_teach(scenario: str = "trapezium", world: World | None = None, seed: int = 0, *,
                         stages: tuple[str, ...] | None = None, rig: Rig | None = None,
                         run_dir: str | Path | None = None, playback_speed_mm_s: float = 20.0,
                         robot: str = "standin", smooth_path: bool = True, play: str = "seam",
                         progress: Callable[[str, float, float], None] | None = None,
                         overrides: dict[str, dict] | None = None, law: str = "thetau",
                         ur_cycle_ms: float = UR_CYCLE_MS, rig_kind: str | None = None) -> TeachResult:
    """Run the job (module docstring) on ``world`` (default realistic) from ``rig`` (default
    the nominal one); ``stages`` default every one of :data:`STAGES`.  ``progress(stage,
    done, total)`` is called as each stage goes.  ``robot`` teaches and plays back:
    ``standin`` (default), ``ur`` (the simulated UR5e behind the gateway's RTDE link at
    ``ur_cycle_ms``, 2 or 8, mounted as the Puma is; its hand-eye calibrated on the
    stand-in, no arm stage: its kinematics are exact on the twin, the world's errors of the
    Puma's kinematics left out) or ``puma``: the simulated Puma behind the gateway and its
    ALTER line, mounted in the joint pose that keeps its wrist farthest from its singularity
    while it watches and welds the seam (:func:`humanpt.twin.system.puma_mount_joints`),
    the seam planned on it (:func:`humanpt.controller.playback.plan_on_arm`: a joint-space
    approach, the seam slowed where a joint would be too fast) or refused before any
    motion (``TeachResult.refused``).  ``overrides`` ({section: {key: value}}, as
    ``humanpt demo --set``) and the servo ``law`` configure the teach-and-play run (the
    operator's speed is ``operator.speed_mm_s``, the playback's
    ``controller.playback_speed_mm_s``, else ``playback_speed_mm_s``).  ``rig_kind``
    (default the rig's kind): "stereo" runs the job on an ordinary stereo pair
    (:func:`stereo_job`), its stereo stage in place of the camera and mirror stages."""
    t_start = time.perf_counter()
    world = World.realistic() if world is None else world
    ctl_kw: dict = {}
    if robot == "ur":  # the world's errors of the Puma's kinematics (issue 32.4) are not the UR5e's
        puma_only = {s.name for s in ERROR_SOURCES if s.robot == "puma"}
        world = World(world.name, tuple(s for s in world.sources if s not in puma_only), world.extra)
        if "recording_delay_cycles" not in ((overrides or {}).get("controller") or {}):
            # A path point as often as on the Puma (every 10 of its 28 ms cycles), not every 10 of
            # the UR's 2 ms: a point every 20 ms put 1485 on the trapezium (the Puma's 178), which
            # `path fit` made 61 pieces (an arc of 0.57 mm radius) and the playback refused.
            ctl_kw["recording_delay_cycles"] = max(1, round(
                ControllerConfig().recording_delay_cycles * PUMA_CYCLE_MS / ur_cycle_ms))
    op = operator_config(scenario, seed)
    rig = nominal_rig(op) if rig is None else rig
    kind = rig.kind if rig_kind is None else rig_kind
    if kind not in NOT_FOR_KIND:
        raise ValueError(f"rig kind {kind!r}: {' or '.join(NOT_FOR_KIND)}")
    if kind == "stereo":
        world, rig = stereo_job(world, rig)
    results = []
    names = tuple(n for n in STAGES if n not in NOT_FOR_KIND[kind]) if stages is None else stages
    mount = None
    if "arm" in names and robot == "puma":  # the arm stage mounts the Puma as the teach-and-play run will
        cfg0 = SystemConfig.for_scenario(scenario, seed, overrides, rig=rig, world=world,
                                         controller=ControllerConfig(playback_speed_mm_s=playback_speed_mm_s, law=law,
                                                                     **ctl_kw))
        from .cal_arm import fixture_at_seam_start

        _, m, j = mounting(cfg0, robot)
        mount = ((m, j), fixture_at_seam_start(cfg0.operator))
    for name in names:
        if name in NOT_FOR_KIND[kind]:
            results.append(StageResult(name, False, 0.0, skipped=f"not a stage of a {kind} rig"))
            continue
        rig, res = _run_stage(name, world, rig, seed,
                              (lambda done, total, _n=name: progress(_n, done, total)) if progress else None, robot,
                              mount)
        results.append(res)
    # -- teach
    cfg = SystemConfig.for_scenario(scenario, seed, overrides, rig=rig, world=world,
                                    controller=ControllerConfig(playback_speed_mm_s=playback_speed_mm_s, law=law,
                                                                **ctl_kw))
    playback_speed_mm_s = cfg.controller.playback_speed_mm_s
    # The Puma is mounted so that both where it watches the seam (the camera d_z from the
    # target) and where its torch welds it (the tool on the seam) are comfortably in reach:
    # around the flange pose half way between the two, over the middle of the seam.
    seam = _seam(cfg.operator)
    design = polyline_seam(seam)  # the seam as designed, to compare against
    view, mount, mount_joints = mounting(cfg, robot)
    # ``ur``: the simulated UR5e behind the gateway's RTDE link at the e-Series' 2 ms (build_system's
    # arm behind a link, mounted as the Puma is, in its own comfortable joint pose there).
    w = build_system(cfg.operator, seed=seed, controller=cfg.controller, robot="puma" if robot == "ur" else robot,
                     rig=cfg.rig, sim_camera=cfg.sim_camera, perception=cfg.perception, pose_filter=cfg.pose_filter,
                     run_dir=run_dir, keep_outputs=True, digest=False, robot_overrides=cfg.robot_overrides,
                     mount_world_T_flange_mm=mount if robot in ("puma", "ur") else None, mount_joints_deg=mount_joints,
                     ur_cycle_ms=ur_cycle_ms if robot == "ur" else None)
    teach_s = cfg.default_duration_s()
    try:
        w.run_until(round(cfg.operator.start_delay_s * 1e9))
        w.lockstep.inject(w.now_ns, "controller", "console/command",
                          pb.Command(header=header(w.now_ns), component="controller", verb="record_start"))
        step = 1.0
        while w.now_ns < teach_s * 1e9:
            w.run_for(step)
            if progress:
                progress("teach", w.now_ns / 1e9, teach_s)
        w.lockstep.inject(w.now_ns, "controller", "console/command",
                          pb.Command(header=header(w.now_ns), component="controller", verb="record_stop"))
        w.run_for(0.1)
        start_ns = evaluate.scenario_start_ns(w)
        stamps, x_g, x_tip = evaluate.path_points(w)
        _, err, _ = evaluate.path_truth_errors(w, after_ns=start_ns)
        taught = x_tip if x_tip is not None else x_g
        arm = _arm(w, cfg.rig)
        seam_arm, arm_note = None, ""
        if arm is not None and arm.true_arm is not None:
            seam_arm, arm_note = _seam_in_arm_frame(seam, arm, cfg)
        if arm is not None and arm.true_arm is not None and len(taught):
            # The pipeline placed each point with the flange the robot reported (its nominal
            # model): move it to where the calibrated arm had the flange (issue 32.4).
            moved = _corrected(w, arm, taught, stamps)
            shift = moved - taught  # ... and its errors against the truth with it
            shift[:, 3:] = evaluate.wrap_deg(shift[:, 3:])
            err = err + shift[stamps >= start_ns]
            taught = moved
        taught_p = transform_from_x(np.asarray(taught, dtype=float).reshape(-1, 6))[:, :3, 3]
        taught_mm = distance_to_seam(design, taught_p) if len(taught_p) else np.zeros(0)
        # -- play back: the tool follows the recorded path; judge the tool's TRUE path
        ctl = next(c for c in w.extra if isinstance(c, ControllerCore))
        tool_mm = to_mm(ctl.flange_T_tool)
        truth_topic = "sim_robot/truth"  # the stand-in publishes its truth there too
        n_before = len(w.outputs(truth_topic))
        n_states = len(w.outputs("robot_gateway/robot_state"))
        # As a welder would (`humanpt path smooth`): the recorded path RTS-smoothed first, so
        # that the hand's tremor is not played back.
        points = smooth(np.asarray(taught, dtype=float), stamps) if smooth_path else np.asarray(taught, dtype=float)
        smoothed_p = transform_from_x(np.asarray(points, dtype=float).reshape(-1, 6))[:, :3, 3]
        smoothed_mm = distance_to_seam(design, smoothed_p) if len(smoothed_p) else np.zeros(0)
        # ... and as lines and arcs (`humanpt path fit`): the seam the hand meant.
        fitted = fit_path(np.asarray(taught, dtype=float), stamps,
                          meta={"point": "tip" if x_tip is not None else "G", "frame": "world"})
        fitted_p = np.vstack([sample_segment(sg, 0.5) for sg in fitted.segments])
        fitted_mm = distance_to_seam(design, fitted_p)
        refused = ""
        if play == "seam":  # `humanpt path play`: the fitted seam, re-timed, a stop at each corner
            # as the console does: re-timed for the tool, at most the controller's points;
            # on the Puma planned on the arm (a joint-space approach, the seam slowed where a
            # joint would be too fast), or refused before anything moves
            try:
                args = seam_command(fitted, playback_speed_mm_s, cfg.controller.flange_T_tool_x, arm=arm)
            except PlaybackError as e:
                refused, args = str(e), None
        else:
            args = {"speed_mm_s": playback_speed_mm_s, "points": points.round(4).tolist()}
        if args is not None:
            w.lockstep.inject(w.now_ns, "controller", "console/command",
                              pb.Command(header=header(w.now_ns), component="controller", verb="playback",
                                         args_json=json.dumps(args)))
        length_mm = float(np.sum(np.linalg.norm(np.diff(seam, axis=0), axis=1)))
        times = args.get("times_s") if args else None
        play_s = 15.0 + (times[-1] if times else length_mm / playback_speed_mm_s)
        t_play0 = w.now_ns
        done = args is None
        seen = len(w.lockstep.outputs)
        while not done and w.now_ns - t_play0 < play_s * 1e9:
            w.run_for(1.0)
            if progress:
                progress("play back", (w.now_ns - t_play0) / 1e9, play_s)
            new, seen = w.lockstep.outputs[seen:], len(w.lockstep.outputs)  # only what came since
            done = any(o.topic == "controller/events" and pb.Event.FromString(o.data).code == "playback_done"
                       for o in new)
        truths = w.truths(truth_topic)[n_before:]
        tools = np.array([r["world_T_flange"] @ tool_mm for _, r in truths]).reshape(-1, 4, 4)
        tips = tools[:, :3, 3]
        # from the first time the tool reaches the path's start (after the approach)
        first = np.array([fitted.segments[0].start_mm if play == "seam" else transform_from_x(taught[0])[:3, 3]])
        # the approach ends within 0.2 mm of the start (the controller's criterion): count from
        # there, as the robot reports its flange (an arm with kinematic errors puts the true
        # torch ~1 mm away from where it believes it is: that is what is measured, after)
        states = [pb.RobotState.FromString(o.data) for o in w.outputs("robot_gateway/robot_state")[n_states:]]
        flanges = np.array([to_mm(from_pose(st.world_T_flange)) for st in states]).reshape(-1, 4, 4)
        if len(flanges) and arm is not None and arm.true_arm is not None:
            # on a calibrated arm the commands are off the seam by its errors: where the
            # calibrated arm has the flange, at the joints the robot reports
            from humanpt.calibration.arm import true_world_T_flange

            flanges = true_world_T_flange(arm.true_arm, flanges, arm.world_T_base_mm, arm.kinematics, arm.joints_rad)
        believed = (flanges @ tool_mm)[:, :3, 3].reshape(-1, 3)
        at = np.nonzero(np.linalg.norm(believed - first, axis=1) < 0.25)[0]
        stamps_t = np.array([st for st, _ in truths], dtype=np.int64)
        near = (np.nonzero(stamps_t >= states[at[0]].header.stamp_ns)[0] if len(at)
                else np.zeros(0, dtype=np.int64))
        tips = tips[near[0]:] if len(near) else tips[:0]
        played_x = x_from_transform(tools[near[0]:]) if len(near) else np.zeros((0, 6))
        played_mm = distance_to_seam(design, tips) if len(tips) else np.zeros(0)
        compared = {k: c for k, c in (("taught", _compare(design, taught_p, "taught points")),
                                      ("smoothed", _compare(design, smoothed_p, "smoothed points")),
                                      ("fitted", _compare(design, fitted_p, "fitted seam, every 0.5 mm")),
                                      ("played", _compare(design, tips, "played torch, every cycle")))
                    if c is not None}
        if play == "seam" and len(tips):  # the playback alone: the torch against the seam it was given
            compared["played_fitted"] = compare_points(fitted, tips, approach_mm=None, window="played torch")
        warnings = [f"{e.source}: {e.code}" for e in (pb.Event.FromString(o.data) for o in w.outputs()
                                                      if o.topic.endswith("/events")) if e.severity >= 3]
        if refused:
            warnings.append(f"playback refused: {refused}")
        elif not done:
            warnings.append(f"controller: playback not done after {play_s:.0f} s")
        step_deg = limit_deg = None
        if arm is not None and len(truths) > 1:
            # The arm's joints each cycle of the playback: the world's flange (sim_robot/truth,
            # every cycle) through the robot's kinematics, the closest branch from its joints
            # at the start (the robot publishes no joints).
            flanges = np.array([r["world_T_flange"] for _, r in truths])
            joints = follow(arm.kinematics, invert_transform(arm.world_T_base_mm) @ flanges, arm.joints_rad)
            step_deg = float(np.degrees(np.abs(np.diff(joints, axis=0)).max()))
            limit_deg = arm.max_joint_speed_deg_s * arm.cycle_s
    finally:
        w.close()
    stats = evaluate.Stats.of(err) if len(err) else None
    taught_p = np.array([transform_from_x(x)[:3, 3] for x in taught]).reshape(-1, 3)
    fitted_p = np.vstack([sample_segment(sg, 0.5) for sg in fitted.segments])
    checks = _job_checks(cfg, mount, np.asarray(taught, dtype=float), tool_mm, rig, mount_joints, view, robot)
    return TeachResult(results, rig, taught_mm, smoothed_mm, played_mm, stats, warnings,
                       Path(run_dir) if run_dir else None, time.perf_counter() - t_start, fitted_mm, fitted, play,
                       compared, seam_mm=seam, seam_arm_frame_mm=seam_arm, arm_frame_note=arm_note, taught_path_mm=taught_p, fitted_path_mm=fitted_p, played_path_mm=tips,
                       checks=checks, max_joint_step_deg=step_deg, joint_step_limit_deg=limit_deg, refused=refused,
                       played_x=played_x, taught_x=np.asarray(taught, dtype=float).reshape(-1, 6))


# A source of error this large or larger is calibrated or warned of (issue 32.4).
SOURCE_LIMIT_MM = 0.1


def _seam_in_arm_frame(seam: np.ndarray, arm: RobotArm, cfg: SystemConfig) -> tuple[np.ndarray, str]:
    """The seam (K, 3) mm in the frame the calibrated arm defines: the world turned about
    joint 1's axis by minus the world's joint-1 zero offset (read from the twin's truth,
    only to judge), and a line saying so."""
    from humanpt.geometry.transforms import make_transform, matrix_from_rotvec, transform_points

    offsets = (cfg.robot_overrides.get("sim_robot") or {}).get("joint_offsets_deg") or (0.0,) * 6
    d1 = float(offsets[0])
    W = np.asarray(arm.world_T_base_mm, dtype=float)
    G = W @ make_transform(matrix_from_rotvec([0.0, 0.0, -np.radians(d1)]), np.zeros(3)) @ invert_transform(W)
    shift = float(np.sqrt(np.mean(np.sum((transform_points(G, seam) - seam) ** 2, axis=1))))
    return transform_points(G, seam), (
        f"taught and fitted seams against the seam in the calibrated arm's frame: the world turned by the arm's "
        f"joint-1 zero offset ({d1:+.4f} deg, {shift:.3f} mm RMS here), which no camera on the flange can see; "
        "taught and played in that frame, the torch is judged in the world's")


def _corrected(w, arm: RobotArm, taught: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """The taught points (N, 6) moved by the calibrated arm (humanpt.calibration.arm
    .correct_path) with the robot states the gateway published (the reported flanges)."""
    from humanpt.calibration.arm import correct_path

    states = [pb.RobotState.FromString(o.data) for o in w.outputs("robot_gateway/robot_state")]
    rs = np.array([st.header.stamp_ns for st in states], dtype=np.int64)
    R = np.array([to_mm(from_pose(st.world_T_flange)) for st in states]).reshape(-1, 4, 4)
    return correct_path(taught, stamps, rs, R, arm.true_arm, arm.world_T_base_mm, arm.kinematics, arm.joints_rad)


def _job_checks(cfg: SystemConfig, mount: np.ndarray, taught_x: np.ndarray, tool_mm: np.ndarray, rig: Rig,
                mount_joints=None, view: np.ndarray | None = None, robot: str = "standin") -> list:
    """The job's own checks: on the stand-in, the Puma's absolute kinematic error along the
    taught seam (the world's arm against its nominal model, as the job mounts it: what a
    cell playing on its arm would meet); on the Puma, the arm's share of the played-back
    error (the world's arm teaching the seam from where it watches it and playing it, both
    through the rig's hand-eye and arm model: :func:`humanpt.twin.report.arm_share_mm`),
    after the arm's calibration when the rig has one (the nominal arm's figure beside it),
    each against the played-back tolerance; the camera-to-robot time offset the rig says, at
    the taught speed, against SOURCE_LIMIT_MM."""
    from .report import SEAM_TOLERANCES_MM, Check, arm_error_mm

    checks = []
    if len(taught_x) and (robot != "puma" or view is None):
        err = arm_error_mm(cfg.robot_overrides, mount, transform_from_x(taught_x[:: max(1, len(taught_x) // 200)]),
                           tool_mm)
        if len(err):
            checks.append(Check("arm", "the Puma's absolute kinematic error along the seam, RMS",
                                float(np.sqrt(np.mean(err ** 2))), SEAM_TOLERANCES_MM["played"], "mm"))
    elif len(taught_x):
        nominal, after = arm_share(cfg, rig, view, mount, mount_joints)
        if rig.arm.present:
            checks.append(Check("arm", f"the arm's share of the played-back error after its calibration, RMS "
                                f"(the same hand-eye on the nominal arm: {nominal:.3f} mm)", after, SEAM_TOLERANCES_MM["played"], "mm"))
        else:
            checks.append(Check("arm", "the arm's share of the played-back error (its nominal model; no arm "
                                "calibrated), RMS", nominal, SEAM_TOLERANCES_MM["played"], "mm"))
    if rig.timing.calibration.method != "nominal":
        # the pose filter places each image at its stamp minus the offset: what is left is
        # the offset's own uncertainty
        speed = float(cfg.operator.speed_mm_s or DEFAULT_SPEED_MM_S)
        sigma_ms = rig.timing.calibration.sigma.get("camera_time_offset_ms", abs(rig.timing.camera_time_offset_ms))
        checks.append(Check("timing", f"the time offset's 1-sigma at {speed:g} mm/s (the offset itself, "
                            f"{rig.timing.camera_time_offset_ms:+.2f} ms, is corrected by the pose filter)",
                            abs(sigma_ms) * 1e-3 * speed, SOURCE_LIMIT_MM, "mm"))
    return checks
