"""The whole closed loop on the lock-step twin: operator, robot, sim_camera, perception,
pose_filter and controller on virtual time, and how to judge it against ground truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore, flange_T_desired_mm
from humanpt.geometry.rig import Calibration, Rig, Tip, flange_T_desired
from humanpt.geometry.transforms import transform_from_x, x_from_transform
from humanpt.operator import BUILTIN_SCENARIOS, OperatorConfig
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.core import PerceptionCore
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.runtime.config import RecordConfig
from humanpt.scene.config import SceneConfig
from humanpt.scene.core import SceneCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.sim_camera import SimCameraConfig

from . import evaluate
from .evaluate import path_points, truth_at
from .standin import StandInRobotConfig
from .world import TwinWorld, build_world, start_flange_for

__all__ = ["arm_cores", "arm_mount_joints", "arm_placement", "build_system", "flange_T_desired_mm", "nominal_rig",
           "operator_config", "puma_placement", "puma_mount_joints", "puma_cores", "tracking_errors", "path_points",
           "truth_at", "ur_link"]

# The lock-step twin carries RTDE's TCP stream between the gateway and the simulated UR as a
# byte stream this fast (bits/s, 10 bits a byte): 1 us for a 10-byte request, ~25 us for a
# data package; loopback or a switched LAN.
RTDE_STREAM_BAUD = 100_000_000


def arm_placement(world_T_flange_start_mm: np.ndarray, model: str = "puma762",
                  joints_deg: tuple[float, ...] | None = None) -> tuple[float, ...]:
    """Where the twin mounts the simulated arm ``model`` (humanpt.geometry.arms):
    ``world_T_base`` (X, mm/deg) such that the robot starts at ``world_T_flange_start_mm`` in
    its default, comfortable joint pose (the arm's ``home_joints_deg``: flange pointing along
    -z of the base, far from singularities and limits), or in ``joints_deg``
    (:func:`arm_mount_joints`).  A target seen from below (the paper's Table 1 angles) gives
    a ceiling-mounted robot."""
    from humanpt.geometry.transforms import invert_transform
    from humanpt.sim_robot.config import SimRobotConfig

    cfg = SimRobotConfig(model=model)
    q = cfg.start_joints_rad() if joints_deg is None else np.radians(np.asarray(joints_deg, dtype=float))
    base_T_flange = cfg.kinematics().forward(q)
    world_T_base = np.asarray(world_T_flange_start_mm, dtype=float) @ invert_transform(base_T_flange)
    return tuple(float(v) for v in x_from_transform(world_T_base))


def puma_placement(world_T_flange_start_mm: np.ndarray, model: str = "puma762",
                   joints_deg: tuple[float, ...] | None = None) -> tuple[float, ...]:
    """:func:`arm_placement` of a Puma (the name the calibration and teach code know)."""
    return arm_placement(world_T_flange_start_mm, model, joints_deg)


# The wrist poses arm_mount_joints tries at the mounting pose (deg): joint 4, joint 5 (both
# sides of the wrist singularity) and joint 6 (the arm turned about the torch's axis).
MOUNT_Q4_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)
MOUNT_Q5_DEG = (-60.0, -40.0, -25.0, 25.0, 40.0, 60.0)
MOUNT_Q6_DEG = (-180.0, -90.0, 0.0, 90.0)


def arm_mount_joints(world_T_flange_mount_mm: np.ndarray, paths_world_T_flange_mm: list[np.ndarray],
                     model: str = "puma762") -> tuple[tuple[float, ...], float]:
    """The arm's joint pose at its mounting pose (deg, (6,)) that keeps the wrist farthest
    from its singularity (and every joint from its limits) along every path of flange poses
    the job needs (each (N, 4, 4) mm, world: watching the seam, welding it), each followed
    as the robot's controller would (closest solution, from the one nearest the mounting
    pose); with the score: the least |asin(sin q5)| and joint-limit margin (deg) along them.
    Any arm of humanpt.geometry.arms (``model``): each has its wrist singularity at
    sin q5 = 0 (the Puma's and the IRB's joints 4 and 6 coaxial, the UR's wrist 1 and 3).

    A general placement (issue 33.1): the arm's default pose's wrist is tried with others
    (its joints 1-3 with :data:`MOUNT_Q4_DEG` x :data:`MOUNT_Q5_DEG` x :data:`MOUNT_Q6_DEG`)
    and the best taken (the default when nothing is better); no mounting is tuned by hand."""
    from humanpt.geometry.puma import UnreachableError, follow
    from humanpt.geometry.transforms import invert_transform
    from humanpt.sim_robot.config import SimRobotConfig

    cfg = SimRobotConfig(model=model)
    kin = cfg.kinematics()
    home = np.degrees(cfg.start_joints_rad())
    lo, hi = kin.limits_rad[:, 0], kin.limits_rad[:, 1]
    mount = np.asarray(world_T_flange_mount_mm, dtype=float)

    def score(q_deg: np.ndarray) -> float:
        q_mount = np.radians(q_deg)
        if not kin.within_limits(q_mount):
            return -np.inf
        base_T_world = invert_transform(mount @ invert_transform(kin.forward(q_mount)))
        worst = np.inf
        for path in paths_world_T_flange_mm:
            T = base_T_world @ np.asarray(path, dtype=float).reshape(-1, 4, 4)
            try:
                q0 = kin.inverse(T[0], q_mount)
                q = follow(kin, T, q0)
            except UnreachableError:
                return -np.inf
            if np.abs(np.diff(q, axis=0)).max(initial=0.0) > np.radians(20.0):
                return -np.inf  # a branch jump between samples: the wrist flips on the way
            wrist = np.degrees(np.abs(np.arcsin(np.clip(np.sin(q[:, 4]), -1, 1)))).min()
            margin = np.degrees(np.minimum(q - lo, hi - q)).min()
            worst = min(worst, wrist, margin)
        return float(worst)

    best, best_score = home, score(home)
    for q4 in MOUNT_Q4_DEG:
        for q5 in MOUNT_Q5_DEG:
            for q6 in MOUNT_Q6_DEG:
                q = np.r_[home[:3], q4, q5, q6]
                sc = score(q)
                if sc > best_score + 1e-9:
                    best, best_score = q, sc
    return tuple(float(v) for v in best), best_score


def puma_mount_joints(world_T_flange_mount_mm: np.ndarray, paths_world_T_flange_mm: list[np.ndarray],
                      model: str = "puma762") -> tuple[tuple[float, ...], float]:
    """:func:`arm_mount_joints` of a Puma (the teach-and-play job's name)."""
    return arm_mount_joints(world_T_flange_mount_mm, paths_world_T_flange_mm, model)


def arm_cores(world_T_flange_start_mm: np.ndarray, *, model: str = "puma762", envelope_mm: float = 900.0,
              baud: int = 38_400, joints_deg: tuple[float, ...] | None = None):
    """(sim_robot config, robot_gateway config over ALTER) for the arm ``model`` on the twin
    starting at the given flange pose (in ``joints_deg`` there, default its comfortable
    pose), with a workspace envelope of +-``envelope_mm`` around it. The other links take
    the pair from here (:func:`rsi_link`, :func:`abb_link`, :func:`ur_link`)."""
    from humanpt.robot_gateway.links.alter.config import AlterConfig
    from humanpt.sim_robot.config import SimRobotConfig

    base = arm_placement(world_T_flange_start_mm, model, joints_deg=joints_deg)
    p = np.asarray(world_T_flange_start_mm)[:3, 3]
    robot = SimRobotConfig(model=model, world_T_base_mm_deg=base) if joints_deg is None else SimRobotConfig(
        model=model, world_T_base_mm_deg=base, start_joints_deg=tuple(float(v) for v in joints_deg))
    # A STATUS frame (41 bytes, 8N1) takes this long on the line: the robot state is about
    # the pose at the frame's start, not at its reception.
    status_delay_ms = 41 * 10 / baud * 1e3
    gateway = AlterConfig(world_T_base_mm_deg=base, baud=baud, status_delay_ms=status_delay_ms,
                          envelope_min_mm=tuple(float(v) for v in p - envelope_mm),
                          envelope_max_mm=tuple(float(v) for v in p + envelope_mm))
    return robot, gateway


def puma_cores(world_T_flange_start_mm: np.ndarray, *, envelope_mm: float = 900.0, baud: int = 38_400,
               joints_deg: tuple[float, ...] | None = None):
    """(sim_robot config, robot_gateway config) for a Puma 762 twin (:func:`arm_cores`)."""
    return arm_cores(world_T_flange_start_mm, model="puma762", envelope_mm=envelope_mm, baud=baud,
                     joints_deg=joints_deg)


# The gateway's safety values that stay when the link changes (the rest are the link's).
SAFETY_KEYS = ("max_speed_mm_s", "max_angular_speed_deg_s", "envelope_min_mm", "envelope_max_mm", "stale_cycles",
               "alter_off_on_fault", "world_T_base_mm_deg", "event_interval_ms", "stamp_tolerance_ms",
               "conflict_hold_ms")


def rsi_link(robot, gateway, cycle_ms: float, udp_bind: str = "127.0.0.1:49152"):
    """(sim_robot config, RsiConfig) over RSI at ``cycle_ms`` (4 or 12) from the ALTER
    pair of :func:`puma_cores`: the gateway keeps ``SAFETY_KEYS``, the rest RSI's defaults;
    RKorr in the frame the robot applies corrections in (``alter_mode``)."""
    from humanpt.robot_gateway.links.rsi.config import RsiConfig

    rsi_gateway = RsiConfig(**{k: getattr(gateway, k) for k in SAFETY_KEYS}, cycle_period_ms=cycle_ms,
                            udp_bind=udp_bind, udp_robot=udp_bind.rpartition(":")[0],
                            correction_frame="tool" if robot.alter_mode == "tool" else "base")
    # The robot runs its link's cycle (runtime/cycle.py): from the gateway's config.
    return (dataclasses.replace(robot, protocol="rsi", cycle_period_ns=rsi_gateway.cycle_period_ns,
                                rsi_gateway=udp_bind), rsi_gateway)


def abb_link(robot, gateway, cycle_ms: float = 4.0, udp_bind: str = "127.0.0.1:6510"):
    """(sim_robot config, AbbConfig) over ABB EGM at ``cycle_ms`` (4 or a multiple) from the
    ALTER pair of :func:`puma_cores`, as :func:`rsi_link`: the gateway keeps ``SAFETY_KEYS``,
    the rest EGM's defaults; the steps in the frame the robot applies corrections in."""
    from humanpt.robot_gateway.links.abb.config import AbbConfig

    abb_gateway = AbbConfig(**{k: getattr(gateway, k) for k in SAFETY_KEYS}, cycle_period_ms=cycle_ms,
                            udp_bind=udp_bind, udp_robot=udp_bind.rpartition(":")[0],
                            correction_frame="tool" if robot.alter_mode == "tool" else "base")
    return (dataclasses.replace(robot, protocol="egm", cycle_period_ns=abb_gateway.cycle_period_ns,
                                egm_gateway=udp_bind), abb_gateway)


def ur_link(robot, gateway, cycle_ms: float = 2.0, rtde_address: str = "127.0.0.1:30004"):
    """(sim_robot config, UrConfig) over UR RTDE at ``cycle_ms`` (2: e-Series, 8: CB3) from
    the ALTER pair of :func:`arm_cores`, as :func:`rsi_link`: the gateway keeps
    ``SAFETY_KEYS``, the rest RTDE's defaults; the steps in the frame the robot applies
    corrections in; the controller's RTDE server at ``rtde_address``."""
    from humanpt.robot_gateway.links.ur.config import UrConfig

    # (not ALTER's stale_cycles: over UR the bound is stale_ms, time, whatever the cycle)
    ur_gateway = UrConfig(**{k: getattr(gateway, k) for k in SAFETY_KEYS if k != "stale_cycles"}, cycle_period_ms=cycle_ms,
                          rtde_address=rtde_address, correction_frame="tool" if robot.alter_mode == "tool" else "base")
    return dataclasses.replace(robot, protocol="rtde", cycle_period_ns=ur_gateway.cycle_period_ns), ur_gateway


def link_cycle_ms(rsi_cycle_ms: float | None = None) -> float:
    """The twin cell's one cycle (ms): its robot link's (runtime/cycle.py), RSI's
    ``rsi_cycle_ms`` or else ALTER's (the paper's 28 ms, the gateway's default link)."""
    from humanpt.robot_gateway.links import gateway_config

    return float(rsi_cycle_ms) if rsi_cycle_ms else gateway_config("alter").cycle_period_ms


def operator_config(scenario: str | OperatorConfig, seed: int = 0) -> OperatorConfig:
    """A built-in name, a scenario file path or an OperatorConfig -> OperatorConfig."""
    if isinstance(scenario, OperatorConfig):
        return dataclasses.replace(scenario, seed=seed)
    if scenario in BUILTIN_SCENARIOS:
        return OperatorConfig(scenario=scenario, seed=seed)
    return OperatorConfig(scenario_file=str(scenario), seed=seed)


def build_system(scenario: str | OperatorConfig = "static", *, seed: int = 0,
                 perception: PerceptionConfig | None = None, pose_filter: PoseFilterConfig | None = None,
                 controller: ControllerConfig | None = None, sim_camera: SimCameraConfig | None = None,
                 start_offset_mm_deg=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), robot_cores=None,
                 robot: str = "standin", run_dir: str | Path | None = None, keep_outputs: bool = True,
                 digest: bool = True, rig: Rig | None = None,
                 robot_overrides: dict[str, dict] | None = None,
                 mount_world_T_flange_mm: np.ndarray | None = None,
                 rsi_cycle_ms: float | None = None, abb_cycle_ms: float | None = None,
                 mount_joints_deg: tuple[float, ...] | None = None, ur_cycle_ms: float | None = None,
                 record: RecordConfig | None = None) -> TwinWorld:
    """The closed loop on the twin.  The robot starts viewing the scenario's first pose
    (the desired point D on G), moved by ``start_offset_mm_deg`` (X, applied in the world
    frame), so the servo has something to converge from.  With a driver in the scenario the
    controller records the tip too.  ``rig``: what the pipeline believes (None: the
    nominal rig with the scenario's driver, :func:`nominal_rig`).  ``robot_overrides``:
    {``sim_robot`` | ``standin_robot``: {key: value}} of the world's robot.
    ``mount_world_T_flange_mm``: the Puma's comfortable flange pose (4, 4) mm, where it is
    mounted around (default: the start pose).  ``robot``: ``standin`` (integrates commands) or
    ``puma`` (sim_robot + robot_gateway over a simulated 38 400 baud ALTER line).
    ``digest=False``: no output hash (faster; for runs nobody compares).  ``rsi_cycle_ms``
    (4 or 12; ``puma`` only): the Puma behind the RSI link instead (UDP paths with 0.1 ms
    delivery); the controller and the pose filter's prediction follow the link's cycle,
    which every robot state carries (runtime/cycle.py).  ``abb_cycle_ms`` (4 or a multiple;
    ``puma`` only): the simulated ABB IRB 1600 behind the EGM link instead, the same way;
    ``ur_cycle_ms`` (2 or 8): the simulated UR5e behind the RTDE link (its TCP stream as a
    fast byte stream, :data:`RTDE_STREAM_BAUD`). Each arm is mounted by the same rule
    (:func:`arm_cores`).  ``record``: how ``run_dir``'s recordings are made (``[record]``;
    default its defaults)."""
    if sum(c is not None for c in (rsi_cycle_ms, abb_cycle_ms, ur_cycle_ms)) > 1:
        raise ValueError("one robot link: rsi_cycle_ms, abb_cycle_ms or ur_cycle_ms, not more")
    op = operator_config(scenario, seed)
    cam = sim_camera or SimCameraConfig()
    ctl = controller or ControllerConfig()
    rig = nominal_rig(op) if rig is None else rig
    if op.build_scenario().driver_mm is not None and not ctl.has_driver:
        ctl = dataclasses.replace(ctl, has_driver=True)
    standin = None
    wire = False
    if robot_cores is None:
        start = start_flange_for(op, ctl.dz_mm, cam.flange_T_camera)
        off = np.asarray(start_offset_mm_deg, dtype=float)
        D = transform_from_x(np.r_[0.0, 0.0, 0.0, off[3:]])
        start = start.copy()
        start[:3, :3] = D[:3, :3] @ start[:3, :3]
        start[:3, 3] += off[:3]
        if robot == "puma":
            from humanpt.robot_gateway.core import GatewayCore
            from humanpt.sim_robot.core import SimRobotCore

            # The robot is mounted so that it starts where the camera sees the target (or
            # around ``mount_world_T_flange_mm``, e.g. between viewing and welding the seam).
            mount = (start_flange_for(op, ctl.dz_mm, cam.flange_T_camera) if mount_world_T_flange_mm is None
                     else np.asarray(mount_world_T_flange_mm, dtype=float))
            model = "irb1600" if abb_cycle_ms is not None else "ur5e" if ur_cycle_ms is not None else "puma762"
            rcfg, gcfg = arm_cores(transform_from_x(np.asarray(x_from_transform(mount))), model=model,
                                   joints_deg=mount_joints_deg)
            start_in_base = np.linalg.inv(transform_from_x(np.asarray(rcfg.world_T_base_mm_deg))) @ start
            rcfg = dataclasses.replace(rcfg, start_pose_mm_deg=tuple(float(v) for v in x_from_transform(start_in_base)))
            rcfg = _with_robot_overrides(rcfg, robot_overrides, "sim_robot")
            if rsi_cycle_ms is not None:
                # The controller and the pose filter take the cycle from the robot states.
                rcfg, gcfg = rsi_link(rcfg, gcfg, float(rsi_cycle_ms))
            elif abb_cycle_ms is not None:
                rcfg, gcfg = abb_link(rcfg, gcfg, float(abb_cycle_ms))
            elif ur_cycle_ms is not None:
                rcfg, gcfg = ur_link(rcfg, gcfg, float(ur_cycle_ms))
            robot_cores = [SimRobotCore.create(rcfg), GatewayCore.create(gcfg)]
            wire = True
        elif robot == "standin":
            standin = StandInRobotConfig(start_flange_mm_deg=tuple(float(v) for v in x_from_transform(start)))
            standin = _with_robot_overrides(standin, robot_overrides, "standin_robot")
        else:
            raise ValueError(f"robot must be 'standin' or 'puma', got {robot!r}")
    cores = [PerceptionCore(perception or PerceptionConfig(), rig), PoseFilterCore(pose_filter or PoseFilterConfig(), rig),
             ControllerCore(ctl, rig)]
    # Foxglove's own types beside ours (humanpt.scene); the base where the gateway puts it.
    cores.append(SceneCore(SceneConfig(dz_mm=ctl.dz_mm, world_T_base_mm_deg=tuple(
        robot_cores[1].config.world_T_base_mm_deg) if wire else (0.0,) * 6), rig))
    world = build_world(op, seed=seed, sim_camera=cam, robot=standin, robot_cores=robot_cores, extra_cores=cores,
                        dz_mm=ctl.dz_mm, run_dir=run_dir, keep_outputs=keep_outputs, digest=digest, record=record)
    if wire and (rsi_cycle_ms is not None or abb_cycle_ms is not None):
        world.lockstep.connect_udp("sim_robot", "robot_gateway")
    elif wire and ur_cycle_ms is not None:
        # RTDE: a TCP stream; the gateway's adapter marks the connection with an empty chunk.
        world.lockstep.connect_serial("robot_gateway", "sim_robot", baud=RTDE_STREAM_BAUD)
        world.lockstep.inject(world.lockstep.now_ns, "robot_gateway", "serial_rx",
                              pb.SerialChunk(header=header(world.lockstep.now_ns, frame_id="sim_robot"), data=b""))
    elif wire:
        world.lockstep.connect_serial("robot_gateway", "sim_robot", baud=robot_cores[1].config.baud)
    return world


def _with_robot_overrides(cfg, overrides: dict[str, dict] | None, section: str):
    from humanpt.runtime.config import build, to_table

    from .worlds import merge_overrides

    table = (overrides or {}).get(section)
    if not table:
        return cfg
    return build(type(cfg), merge_overrides(to_table(cfg), table), source="world/--set", section=section)


def tracking_errors(world: TwinWorld) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True servo error per robot cycle of a built system (see evaluate.tracking_errors):
    the target against the desired point D of the world's true camera."""
    ctl = next(c for c in world.extra if isinstance(c, ControllerCore))
    return evaluate.tracking_errors(world, flange_T_desired(world.camera.config.flange_T_camera, ctl.config.dz_mm))


def nominal_rig(operator: OperatorConfig) -> Rig:
    """What the twin's pipeline believes when nobody calibrated: the design values
    (:class:`Rig`'s defaults, which the ideal world makes true) with the driver tip of the
    tool the scenario's operator holds (its design length)."""
    driver = operator.design_scenario().driver_mm
    if driver is None:
        return Rig()
    return dataclasses.replace(Rig(), tip=Tip(tob_t_tip_mm=tuple(float(v) for v in driver),
                                              calibration=Calibration(method="nominal", note="the scenario's driver")))


