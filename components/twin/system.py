"""The whole closed loop on the lock-step twin: operator, robot, sim_camera, perception,
pose_filter and controller on virtual time, and how to judge it against ground truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry.transforms import x_from_transform
from humanpt.operator import BUILTIN_SCENARIOS, OperatorConfig
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.core import PerceptionCore
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose
from humanpt.sim_camera import SimCameraConfig
from humanpt.sim_camera.core import interpolate_pose

from .standin import StandInRobotConfig
from .world import TwinWorld, build_world, start_flange_for

__all__ = ["build_system", "operator_config", "tracking_errors", "path_points", "truth_at"]


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
                 run_dir: str | Path | None = None, keep_outputs: bool = True) -> TwinWorld:
    """The closed loop on the twin.  The robot starts viewing the scenario's first pose
    (the desired point D on G), moved by ``start_offset_mm_deg`` (X, applied in the world
    frame), so the servo has something to converge from.  With a driver in the scenario the
    controller records the tip too."""
    op = operator_config(scenario, seed)
    cam = sim_camera or SimCameraConfig()
    ctl = controller or ControllerConfig()
    driver = op.build_scenario().driver_mm
    if driver is not None and not ctl.has_driver:
        ctl = dataclasses.replace(ctl, has_driver=True,
                                  tob_t_tip_mm=tuple(float(v) for v in driver))
    robot = None
    if robot_cores is None:
        start = start_flange_for(op, ctl.dz_mm, cam.flange_T_camera)
        off = np.asarray(start_offset_mm_deg, dtype=float)
        from humanpt.geometry.transforms import transform_from_x

        D = transform_from_x(np.r_[0.0, 0.0, 0.0, off[3:]])
        start = start.copy()
        start[:3, :3] = D[:3, :3] @ start[:3, :3]
        start[:3, 3] += off[:3]
        robot = StandInRobotConfig(start_flange_mm_deg=tuple(float(v) for v in x_from_transform(start)))
    cores = [PerceptionCore(perception or PerceptionConfig()), PoseFilterCore(pose_filter or PoseFilterConfig()),
             ControllerCore(ctl)]
    return build_world(op, seed=seed, sim_camera=cam, robot=robot, robot_cores=robot_cores, extra_cores=cores,
                       dz_mm=ctl.dz_mm, run_dir=run_dir, keep_outputs=keep_outputs)


def truth_at(world: TwinWorld, stamps_ns, field: str = "world_T_tob", topic: str = "operator/truth") -> np.ndarray:
    """(N, 4, 4) mm: a truth stream interpolated at the stamps."""
    samples = world.truths(topic)
    t = np.array([s for s, _ in samples], dtype=np.int64)
    out = []
    for ts in np.asarray(stamps_ns, dtype=np.int64):
        i = int(np.clip(np.searchsorted(t, ts), 1, len(t) - 1))
        (t0, a), (t1, b) = samples[i - 1], samples[i]
        out.append(interpolate_pose(int(ts), t0, a[field], t1, b[field], 0))
    return np.array(out)


def tracking_errors(world: TwinWorld) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True servo error per robot cycle: (stamps ns, |G - D| mm, angle(G, D) deg), from
    the robot's true flange and the operator's true target."""
    ctl = next(c for c in world.extra if isinstance(c, ControllerCore))
    flange_T_desired_mm = ctl.flange_T_desired.copy()
    flange_T_desired_mm[:3, 3] *= 1e3
    robot = world.truths("sim_robot/truth")
    stamps = np.array([s for s, _ in robot], dtype=np.int64)
    tobs = truth_at(world, stamps)
    e_mm, e_deg = [], []
    from scipy.spatial.transform import Rotation

    for (_, r), G in zip(robot, tobs, strict=True):
        D = r["world_T_flange"] @ flange_T_desired_mm
        e_mm.append(np.linalg.norm(G[:3, 3] - D[:3, 3]))
        e_deg.append(np.degrees(Rotation.from_matrix(G[:3, :3] @ D[:3, :3].T).magnitude()))
    return stamps, np.array(e_mm), np.array(e_deg)


def path_points(world: TwinWorld) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The recorded path: (stamps ns, X of G (N, 6) mm/deg, X of the tip or None)."""
    pts = [pb.PathPoint.FromString(o.data) for o in world.outputs("controller/path")]
    if not pts:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 6)), None

    def X(p):
        T = from_pose(p)
        T[:3, 3] *= 1e3
        return x_from_transform(T)

    stamps = np.array([p.header.stamp_ns for p in pts], dtype=np.int64)
    xg = np.array([X(p.world_T_tob) for p in pts])
    xt = np.array([X(p.world_T_tip) for p in pts]) if pts[0].has_tip else None
    return stamps, xg, xt
