"""One way to run the whole system on the lock-step twin: build it from a
:class:`SystemConfig`, run it on virtual time, start the path recording when asked, and
judge the result against ground truth.  ``humanpt demo --lockstep``, ``humanpt
experiment``, ``humanpt bench`` and the tests call this; the CLI only parses and prints.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.geometry.rig import Rig, flange_T_desired
from humanpt.operator import OperatorConfig
from humanpt.perception.config import PerceptionConfig
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.runtime.config import ConfigError, RecordConfig, build, to_table
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from humanpt.sim_camera import SimCameraConfig

from . import evaluate
from .system import build_system, flange_T_desired_mm, nominal_rig, operator_config
from .world import TwinWorld
from .worlds import World, merge_overrides

__all__ = ["SECTIONS", "OverrideError", "SystemConfig", "RunResult", "Accuracy", "run", "accuracy", "scenario_duration_s",
           "flange_T_desired_mm"]

# The configuration sections of a twin run, in the order ``--set`` names them.
SECTIONS = ("operator", "sim_camera", "perception", "pose_filter", "controller", "sim_robot", "standin_robot")
# The robots' sections: their configs are made when the system is built (where the robot
# stands follows from the scenario), so their overrides are kept as tables until then.
ROBOT_SECTIONS = ("sim_robot", "standin_robot")


def scenario_duration_s(op: OperatorConfig) -> float:
    """How long the operator's scenario moves (s), without its start delay."""
    from humanpt.operator.scenario import Trajectory

    return Trajectory(op.build_scenario()).duration_s


def _robot_config(section: str):
    if section == "sim_robot":
        from humanpt.sim_robot.config import SimRobotConfig

        return SimRobotConfig()
    from .standin import StandInRobotConfig

    return StandInRobotConfig()


class OverrideError(ConfigError):
    """An override ({section: {key: value}}) names an unknown key or a bad value."""


def with_overrides(obj, overrides: dict[str, dict] | None, section: str):
    """``obj`` (a config dataclass) with ``overrides[section]`` ({key: value}, nested
    tables for nested configs) applied and validated; raises OverrideError."""
    if not (overrides or {}).get(section):
        return obj
    try:
        return build(type(obj), merge_overrides(to_table(obj), overrides[section]), source="--set", section=section)
    except ConfigError as e:
        raise OverrideError(str(e)) from None


@dataclass(frozen=True)
class SystemConfig:
    """Every configuration of a twin run: the operator's scenario and the cores', and the
    seed of the run (the operator's and the camera's noise)."""

    seed: int = 0
    operator: OperatorConfig = field(default_factory=OperatorConfig)
    sim_camera: SimCameraConfig = field(default_factory=SimCameraConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    pose_filter: PoseFilterConfig = field(default_factory=PoseFilterConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    # What the pipeline believes about the hardware (the twin's world may differ).
    rig: Rig = field(default_factory=Rig)
    # The twin's world (its name and error sources; the operator's and sim_camera's parts
    # are applied above, the robots' are ``robot_overrides``).
    world: World = field(default_factory=World)
    robot_overrides: dict[str, dict] = field(default_factory=dict)

    @classmethod
    def for_scenario(cls, scenario: str | OperatorConfig, seed: int = 0, overrides: dict[str, dict] | None = None,
                     rig: Rig | None = None, world: World | None = None, **base) -> SystemConfig:
        """The configs for ``scenario`` (a built-in name, a scenario file or an
        OperatorConfig) and ``seed`` (operator and camera): ``base`` configs by section
        name (sim_camera, perception, pose_filter, controller; defaults for the rest),
        then ``overrides`` ({section: {key: value}}, operator too) applied and validated
        (OverrideError). ``rig``: what the pipeline believes (None: :func:`nominal_rig`,
        the design values with the scenario's driver). ``world``: the twin's truth
        (:class:`humanpt.twin.worlds.World`, default ideal), applied under ``overrides``. A scenario with a driver makes the
        controller record the tip (``has_driver``) unless it already does."""
        unknown = set(base) - set(SECTIONS[1:5])
        if unknown:
            raise TypeError(f"SystemConfig.for_scenario: no base config {sorted(unknown)[0]!r}")
        world = World() if world is None else world
        overrides = merge_overrides(world.overrides(), overrides or {})
        op = with_overrides(operator_config(scenario, seed), overrides, "operator")
        cam = dataclasses.replace(base.pop("sim_camera", SimCameraConfig()), seed=seed)
        robots = {s: dict(overrides[s]) for s in ROBOT_SECTIONS if overrides.get(s)}
        for s, table in robots.items():  # a bad key fails now, not when the system is built
            with_overrides(_robot_config(s), {s: table}, s)
        cfg = cls(seed=seed, operator=op, sim_camera=cam, rig=nominal_rig(op) if rig is None else rig, world=world,
                  robot_overrides=robots, **base)
        cfg = dataclasses.replace(cfg, **{s: with_overrides(getattr(cfg, s), overrides, s) for s in SECTIONS[1:5]})
        driver = op.build_scenario().driver_mm
        if driver is not None and not cfg.controller.has_driver:
            cfg = dataclasses.replace(cfg, controller=dataclasses.replace(cfg.controller, has_driver=True))
        return cfg

    def robot_config(self, section: str, base=None):
        """The ``sim_robot`` / ``standin_robot`` config ``base`` (default: the defaults)
        with the world's and the user's overrides."""
        return with_overrides(base if base is not None else _robot_config(section), self.robot_overrides, section)

    def default_duration_s(self) -> float:
        """The operator's start delay, the scenario, and 1.5 s to settle (the demo's default)."""
        return self.operator.start_delay_s + scenario_duration_s(self.operator) + 1.5


@dataclass
class RunResult:
    """A finished (closed) lock-step run: the world (its outputs, unless the run kept
    none), its configs, and how long it took."""

    world: TwinWorld
    config: SystemConfig
    run_dir: Path | None
    wall_s: float  # wall time of the run, from the first step to the last (not the build)
    twin_s: float  # virtual time run
    close_s: float  # wall time of closing the world (the recordings' last writes)
    cpu_s: dict[str, float] | None = None  # where the CPU went (run(..., account=True)), seconds

    @property
    def speed(self) -> float:
        """Twin time per wall time, closing included (x real time)."""
        return self.twin_s / max(self.wall_s + self.close_s, 1e-9)

    def path_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The recorded path: (stamps ns (N,), X of G (N, 6), X of the tip (N, 6) or None)."""
        return evaluate.path_points(self.world)

    def path_truth_errors(self) -> tuple[str, np.ndarray, np.ndarray]:
        """The recorded path against ground truth at the same instant (evaluate.path_truth_errors)."""
        return evaluate.path_truth_errors(self.world)

    def write_path(self, path: str | Path) -> Path:
        """Write the recorded path as a path file (CSV, ``humanpt.controller.pathfile``)."""
        from humanpt.controller import pathfile

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        # With the held flags and the filter's covariances (issue 18), as the live shell writes.
        pts = [pb.PathPoint.FromString(o.data) for o in self.world.outputs("controller/path")]
        pathfile.write(path, pathfile.from_path_points(pts))
        return path


def run(config: SystemConfig, *, robot: str = "puma", duration_s: float | None = None,
        record_from_s: float | None = None, run_dir: str | Path | None = None, keep_outputs: bool = True,
        digest: bool = False, progress: Callable[[float, float], None] | None = None,
        rsi_cycle_ms: float | None = None, abb_cycle_ms: float | None = None,
        ur_cycle_ms: float | None = None, record: RecordConfig | None = None, account: bool = False) -> RunResult:
    """Build the closed loop (:func:`humanpt.twin.system.build_system`) and run it for
    ``duration_s`` of twin time (default :meth:`SystemConfig.default_duration_s`).

    ``record_from_s``: at this twin time the controller is told ``record_start`` (the path
    is recorded from then on); None: it is not told. ``run_dir``: every core records its
    MCAP there. ``progress(now_s, duration_s)`` is called about 20 times during the run.
    ``rsi_cycle_ms`` (4 or 12): the simulated Puma behind the RSI link instead of ALTER
    (``build_system``); ``abb_cycle_ms`` (4 or a multiple): the simulated ABB IRB 1600 behind
    the EGM link; ``ur_cycle_ms`` (2 or 8): the simulated UR5e behind the RTDE link.
    ``record``: how the recordings in ``run_dir`` are made (``[record]``, e.g. its
    ``snapshot_period_s``; default its defaults). ``account``: count where the CPU went
    (``RunResult.cpu_s``: :meth:`humanpt.runtime.lockstep.Lockstep.account`'s parts, and
    ``other threads``, the process's CPU beyond the loop's thread: the recorders' writers
    compressing, closing included). The world is closed on return."""
    duration_s = config.default_duration_s() if duration_s is None else float(duration_s)
    world = build_system(config.operator, seed=config.seed, controller=config.controller, robot=robot, rig=config.rig,
                         run_dir=run_dir, sim_camera=config.sim_camera, perception=config.perception,
                         pose_filter=config.pose_filter, keep_outputs=keep_outputs, digest=digest,
                         robot_overrides=config.robot_overrides, rsi_cycle_ms=rsi_cycle_ms,
                         abb_cycle_ms=abb_cycle_ms, ur_cycle_ms=ur_cycle_ms, record=record)
    cpu_s = world.lockstep.account() if account else None
    t0, cpu0, thread0 = time.perf_counter(), time.process_time(), time.thread_time()
    try:
        if record_from_s is not None:
            world.run_until(round(record_from_s * 1e9))
            world.lockstep.inject(world.now_ns, "controller", "console/command",
                                  pb.Command(header=header(world.now_ns), component="controller",
                                             verb="record_start"))
        end_ns = round(duration_s * 1e9)
        if progress is None:
            world.run_until(end_ns)
        else:
            step_ns = int(max(1.0, duration_s / 20) * 1e9)
            while world.now_ns < end_ns:
                world.run_until(min(end_ns, world.now_ns + step_ns))
                progress(world.now_ns / 1e9, duration_s)
    finally:
        t1 = time.perf_counter()
        world.close()  # also on an error: the recordings end readable
    if cpu_s is not None:
        cpu_s["other threads"] = max(0.0, (time.process_time() - cpu0) - (time.thread_time() - thread0))
    return RunResult(world, config, Path(run_dir) if run_dir is not None else None, t1 - t0, duration_s,
                     time.perf_counter() - t1, cpu_s)


@dataclass
class Accuracy:
    """A run judged against ground truth (lock-step or recorded)."""

    which: str  # "G" or "tip": which point the path recorded
    path: evaluate.Stats  # the recorded path against ground truth (mm, deg)
    servo_mm: np.ndarray  # |G - D| per robot cycle while the target moved (mm)
    servo_deg: np.ndarray  # the angle between G's and D's frames, same cycles (deg)
    warnings: list[pb.Event]  # warnings and errors during the run
    stopping: list[pb.Event]  # those stamped after ``stop_ns`` (the processes being stopped)


def accuracy(src, controller: ControllerConfig, flange_T_camera_mm: np.ndarray, stop_ns: int | None = None) -> Accuracy:
    """Judge ``src`` (a TwinWorld or a recorded run, :class:`evaluate.RunOutputs`) of a
    controller configured by ``controller`` on a camera truly at ``flange_T_camera_mm``
    (the world's, (4, 4) mm): the recorded path against ground truth, the servo error
    while the target moved (the target against the true desired point D), and the warnings
    (severity >= 3; those stamped after ``stop_ns`` apart)."""
    start = evaluate.scenario_start_ns(src)
    which, err, _ = evaluate.path_truth_errors(src, after_ns=start)
    t, e_mm, e_deg = evaluate.tracking_errors(src, flange_T_desired(flange_T_camera_mm, controller.dz_mm))
    moving = t >= start if start else np.ones_like(t, dtype=bool)
    events = [pb.Event.FromString(o.data) for o in src.outputs() if o.topic.endswith("/events")]
    warn = [e for e in events if e.severity >= 3]
    late = [e for e in warn if stop_ns is not None and e.header.stamp_ns >= stop_ns]
    warn = [e for e in warn if not (stop_ns is not None and e.header.stamp_ns >= stop_ns)]
    return Accuracy(which, evaluate.Stats.of(err), e_mm[moving], e_deg[moving], warn, late)
