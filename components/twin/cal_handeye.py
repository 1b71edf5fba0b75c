"""Hand-eye calibration (AX = YB) observed on the lock-step twin.

The twin's world (:class:`humanpt.twin.worlds.World`) with the simulated Puma behind the
ALTER link (sim_robot + robot_gateway), the TOB on a fixture (the static scenario, without
the operator's tremor: nobody holds it) and the pipeline (perception, pose filter,
controller) on the given rig. The robot moves itself through poses planned around the
target (:func:`humanpt.calibration.handeye.plan_poses`) with the controller's ``playback``
verb, waits still, and averages perception's ``camera_T_tob`` and the gateway's robot
state (:class:`humanpt.calibration.handeye.PoseCollector`). The estimate uses only what a
real cell has (robot states, measurements, the rig); the world's true hand-eye is read
only to report the error against it.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable

import numpy as np

from humanpt.calibration.handeye import (
    CollectorSettings,
    HandEyeError,
    HandEyeResult,
    PoseCollector,
    plan_poses,
    pose_difference,
    puma_move_check,
    solve_ax_yb,
)
from humanpt.calibration.timing import TimeOffsetError, estimate_time_offset
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import transform_from_x, x_from_transform
from humanpt.geometry.units import to_mm
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header

from .cal_stereo import true_flange_T_camera
from .report import Check, TruthLines
from .run import SystemConfig
from .system import build_system
from .worlds import World

__all__ = ["calibrate_hand_eye_on_twin", "collect_on_twin", "Collected", "DEFAULT_POSES"]

DEFAULT_POSES = 12
# The TOB sits on a fixture: no hand holds it (whatever the world's operator does).
FIXTURE = {"operator": {"tremor_mm": 0.0, "tremor_deg": 0.0}}
STEP_S = 0.05  # how often the collector is asked for its next command (twin time)


@dataclasses.dataclass
class Collected:
    """What :func:`collect_on_twin` gathered: the pairs (A = world_T_flange (N, 4, 4) mm as
    the robot reports it, B = camera_T_target (N, 4, 4) mm), the samples, the poses planned,
    the notes (what was skipped and why), the run's motion (for the time offset), the
    twin and wall time; and, of the robot, what a cell knows: its gateway's mounting
    (``world_T_base_mm``, None on the stand-in), its joints at the start; and the world's
    truth (only to report against): the camera's config and the sim_robot's config."""

    A: np.ndarray
    B: np.ndarray
    samples: list
    poses: np.ndarray
    notes: list[str]
    plan_notes: list[str]
    motion: _Motion
    twin_s: float
    wall_s: float
    world_T_base_mm: np.ndarray | None
    start_joints_rad: np.ndarray | None
    camera_truth: object
    robot_truth: object


def collect_on_twin(world: World, rig: Rig, seed: int, progress: Callable[[int, int], None] | None = None,
                    *, n_poses: int = DEFAULT_POSES, settings: CollectorSettings | None = None,
                    max_twin_s: float = 240.0, world_overrides: dict | None = None, robot: str = "puma",
                    plan: dict | None = None, mount: tuple | None = None, scenario="static") -> Collected:
    """The robot moves itself through ``n_poses`` poses planned around the TOB on its
    fixture (:func:`plan_poses`, with ``plan``'s extra keywords: wider tilts for the arm's
    calibration) and the (A, B) pairs are collected (module doc); the arguments as
    :func:`calibrate_hand_eye_on_twin`'s; ``mount``: (flange pose (4, 4) mm, joints deg)
    where the Puma is mounted around (:func:`humanpt.twin.teach.mounting`: as the job
    mounts it), default around the start pose; ``scenario``: where the TOB is held still
    (a built-in name or an OperatorConfig; default the paper's static pose, seen from below).  Raises :class:`HandEyeError` when the robot faults
    first or the collection stops."""
    from humanpt.twin.worlds import merge_overrides

    cfg = SystemConfig.for_scenario(scenario, seed=seed, overrides=merge_overrides(FIXTURE, world_overrides or {}),
                                    rig=rig, world=world)
    sys_ = build_system(cfg.operator, seed=seed, controller=cfg.controller, robot=robot, rig=rig,
                        sim_camera=cfg.sim_camera, perception=cfg.perception, pose_filter=cfg.pose_filter,
                        keep_outputs=True, digest=False, robot_overrides=cfg.robot_overrides,
                        **({} if mount is None else {"mount_world_T_flange_mm": mount[0], "mount_joints_deg": mount[1]}))
    ls = sys_.lockstep
    t_wall = time.perf_counter()
    world_T_base = start_joints = robot_truth = None
    try:
        # Let the servo settle on the target, then plan from where the robot says it is.
        sys_.run_for(1.0)
        start = None
        for o in ls.outputs:
            if o.topic == "robot_gateway/robot_state":
                start = to_mm(from_pose(pb.RobotState.FromString(o.data).world_T_flange))
            elif o.topic == "robot_gateway/events" and pb.Event.FromString(o.data).code == "robot_fault":
                raise HandEyeError(f"the robot faulted before the calibration could start "
                                   f"({pb.Event.FromString(o.data).text}); nothing written")
        ls.outputs.clear()
        if start is None:
            raise HandEyeError("no robot state from the gateway in the first second: is the robot up?")
        if robot == "puma":
            gateway = next(c for c in ls.cores if c.name == "robot_gateway").config
            box = (gateway.envelope_min_mm, gateway.envelope_max_mm)
            check = puma_move_check(gateway.world_T_base_mm_deg)
            world_T_base = transform_from_x(np.asarray(gateway.world_T_base_mm_deg, dtype=float))
            from humanpt.sim_robot.core import SimRobotCore

            sim = next(c for c in ls.cores if isinstance(c, SimRobotCore))
            start_joints, robot_truth = np.asarray(sim.q_setpoint_rad, dtype=float).copy(), sim.config
        else:  # the stand-in: no joints; the demo's envelope around the start
            box = (tuple(float(v) for v in start[:3, 3] - 900.0), tuple(float(v) for v in start[:3, 3] + 900.0))
            check = None
        poses, plan_notes = plan_poses(start, rig.hand_eye.flange_T_camera_mm(), cfg.controller.dz_mm,
                                       n_poses=n_poses, envelope_min_mm=box[0], envelope_max_mm=box[1],
                                       check=check, seed=seed, **(plan or {}))
        collector = PoseCollector(poses, transform_from_x(np.asarray(cfg.controller.flange_T_tool_x)), settings)
        cmd = collector.start(ls.now_ns)
        end_ns = ls.now_ns + round(max_twin_s * 1e9)
        finished = 0
        motion = _Motion()  # measurements and robot states all along: the time offset's data
        while True:
            if cmd is not None:
                ls.inject(ls.now_ns, "controller", "console/command",
                          pb.Command(header=header(ls.now_ns), component="controller", verb=cmd[0],
                                     args_json=json.dumps(cmd[1])))
            if collector.done:
                break
            if ls.now_ns >= end_ns:
                collector.stop(f"out of time ({max_twin_s:g} s of twin time)")
                continue
            sys_.run_for(STEP_S)
            _feed(collector, ls.outputs)
            motion.feed(ls.outputs)
            ls.outputs.clear()  # the images are not needed once measured
            cmd = collector.poll(ls.now_ns)
            if progress is not None and collector.progress()[0] != finished:
                finished = collector.progress()[0]
                progress(*collector.progress())
        twin_s = ls.now_ns * 1e-9
    finally:
        sys_.close()
    wall_s = time.perf_counter() - t_wall
    notes = plan_notes + collector.notes
    if collector.aborted:
        raise HandEyeError(f"collection stopped: {collector.aborted}; nothing written")
    samples = collector.samples
    A = np.array([s.world_T_flange_mm for s in samples]).reshape(-1, 4, 4)
    B = np.array([s.camera_T_target_mm for s in samples]).reshape(-1, 4, 4)
    return Collected(A, B, samples, poses, notes, plan_notes, motion, twin_s, wall_s, world_T_base, start_joints,
                     sys_.camera.config, robot_truth)


def calibrate_hand_eye_on_twin(world: World, rig: Rig, seed: int, progress: Callable[[int, int], None] | None = None,
                               *, n_poses: int = DEFAULT_POSES, settings: CollectorSettings | None = None,
                               max_twin_s: float = 240.0, world_overrides: dict | None = None,
                               pairs_out: str | None = None, robot: str = "puma"
                               ) -> tuple[HandEyeResult, list[str], list[str]]:
    """Calibrate the hand-eye transform on the twin: ``world`` (the truth), ``rig`` (what
    the pipeline believes; its hand-eye is only the planning guess), ``seed`` (camera
    noise). ``progress(poses done, poses planned)`` after each pose. ``n_poses``: poses
    planned (the start pose included). ``world_overrides``: extra {section: {key: value}}
    of the twin (tests: a robot that cannot reach). ``robot``: ``puma`` (the simulated Puma
    behind the ALTER gateway, with the world's kinematics) or ``standin`` (exact kinematics,
    no joints: the robot the teach-and-play run uses). ``pairs_out``: also write the collected
    pairs there (JSON, what ``humanpt calibrate hand-eye --pairs`` reads).

    Returns (result, report lines, truth lines: the estimate against the world's true
    ``flange_T_camera``). Raises :class:`HandEyeError` when too few poses were collected
    or the motion is degenerate; nothing is written anywhere."""
    got = collect_on_twin(world, rig, seed, progress, n_poses=n_poses, settings=settings, max_twin_s=max_twin_s,
                          world_overrides=world_overrides, robot=robot)
    samples, poses, notes, plan_notes = got.samples, got.poses, got.notes, got.plan_notes
    if len(samples) < 3:
        why = "; ".join(notes[-3:]) or "no pose measured"
        raise HandEyeError(f"too few poses collected: {len(samples)} of {len(poses)} ({why}); AX = YB needs at least "
                           "3 with rotations about two axes; nothing written")
    A, B = got.A, got.B
    if pairs_out:
        from pathlib import Path

        Path(pairs_out).write_text(json.dumps([{"world_T_flange": a.tolist(), "camera_T_target": b.tolist()}
                                               for a, b in zip(A, B, strict=True)], indent=1))
    result = solve_ax_yb(A, B)
    # The camera-to-robot time offset, from the robot's moves between the poses while the
    # camera watched the still target (its track must not move with the robot).
    try:
        offset = estimate_time_offset(*got.motion.arrays(), result.flange_T_camera_mm)
        result = dataclasses.replace(result, time_offset=offset)
    except TimeOffsetError as e:
        plan_notes = [*plan_notes, f"time offset not estimated: {e}"]
        notes = plan_notes + notes[len(got.plan_notes):]
    report = [f"hand-eye on the twin (world {world.name}, seed {seed}): {len(samples)} of {len(poses)} poses "
              f"collected in {got.twin_s:.1f} s of twin time ({got.wall_s:.1f} s wall)"]
    report += [f"  {n}" for n in notes]
    report += ["  pose  measurements  spread mm (camera_T_target about its mean)"]
    report += [f"  {s.index:4d}  {s.measurements:12d}  {s.spread_mm:.4f}" for s in samples]
    report += result.summary_lines()
    if result.time_offset is not None:
        report += result.time_offset.summary_lines()
    # the world's truth (of the rig's camera frame): reported, never estimated from
    truth = true_flange_T_camera(got.camera_truth, rig)
    return result, report, truth_lines(result, truth, rig, got.camera_truth.stamp_offset_ms)


# What the hand-eye estimate must meet (against the twin's truth) and the time offset (1 ms:
# 0.1 mm at 100 mm/s, the budget's threshold).
ACCEPT_MM, ACCEPT_DEG, ACCEPT_OFFSET_MS = 0.2, 0.05, 1.0


def truth_lines(result: HandEyeResult, true_flange_T_camera_mm: np.ndarray, rig: Rig,
                true_offset_ms: float | None = None) -> TruthLines:
    """The estimate and the rig's value against the twin's true hand-eye (and time offset),
    with the acceptance checks (:class:`humanpt.twin.report.Check`) as ``.checks``."""
    dt, da = pose_difference(result.flange_T_camera_mm, np.asarray(true_flange_T_camera_mm, dtype=float))
    dt0, da0 = pose_difference(rig.hand_eye.flange_T_camera_mm(), np.asarray(true_flange_T_camera_mm, dtype=float))
    x = x_from_transform(np.asarray(true_flange_T_camera_mm, dtype=float))
    lines = TruthLines([f"against the twin's truth: flange_T_camera true = [{', '.join(f'{v:.4f}' for v in x)}] "
                        "(mm, deg)",
                        f"  estimate off by {dt:.4f} mm, {da:.4f} deg (acceptance: {ACCEPT_MM:g} mm, "
                        f"{ACCEPT_DEG:g} deg); the rig before was off by {dt0:.4f} mm, {da0:.4f} deg"])
    lines.checks += [Check("hand-eye", "position off the truth", dt, ACCEPT_MM, "mm"),
                     Check("hand-eye", "rotation off the truth", da, ACCEPT_DEG, "deg")]
    if result.time_offset is not None and true_offset_ms is not None:
        off = abs(result.time_offset.offset_ms - true_offset_ms)
        lines.append(f"  time offset true {true_offset_ms:+.2f} ms (sim_camera.stamp_offset_ms), estimate off by "
                     f"{off:.2f} ms (acceptance: {ACCEPT_OFFSET_MS:g} ms)")
        lines.checks.append(Check("time offset", "off the truth", off, ACCEPT_OFFSET_MS, "ms"))
    return lines


class _Motion:
    """Every full measurement (its stamp, camera_T_tob mm) and robot state (stamp,
    world_T_flange mm) of the run, for :func:`estimate_time_offset`."""

    def __init__(self) -> None:
        self.meas: list[tuple[int, np.ndarray]] = []
        self.robot: list[tuple[int, np.ndarray]] = []

    def feed(self, outputs) -> None:
        for o in outputs:
            if o.topic == "robot_gateway/robot_state":
                msg = pb.RobotState.FromString(o.data)
                self.robot.append((msg.header.stamp_ns, to_mm(from_pose(msg.world_T_flange))))
            elif o.topic == "perception/tob":
                msg = pb.TobMeasurement.FromString(o.data)
                if msg.status == pb.TOB_STATUS_FULL:
                    self.meas.append((msg.header.stamp_ns, to_mm(from_pose(msg.camera_T_tob))))

    def arrays(self):
        def split(rows):
            if not rows:
                return np.zeros(0, dtype=np.int64), np.zeros((0, 4, 4))
            return np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows])
        (ms, mT), (rs, rT) = split(self.meas), split(self.robot)
        return ms, mT, rs, rT


def _feed(collector: PoseCollector, outputs) -> None:
    for o in outputs:
        if o.topic == "robot_gateway/robot_state":
            msg = pb.RobotState.FromString(o.data)
            collector.on_robot_state(o.t_ns, to_mm(from_pose(msg.world_T_flange)))
        elif o.topic == "perception/tob":
            msg = pb.TobMeasurement.FromString(o.data)
            full = msg.status == pb.TOB_STATUS_FULL
            collector.on_measurement(o.t_ns, to_mm(from_pose(msg.camera_T_tob)) if full else None)
        elif o.topic == "robot_gateway/events":
            msg = pb.Event.FromString(o.data)
            if msg.code == "robot_fault":
                collector.end(f"the robot faulted ({msg.text})")
        elif o.topic == "controller/events":
            msg = pb.Event.FromString(o.data)
            collector.on_controller_event(o.t_ns, msg.code, msg.text)
