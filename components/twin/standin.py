"""A stand-in robot: integrates flange commands on the ALTER cycle.

Until the simulated Puma controller (``sim_robot``, behind the ALTER link and the gateway)
exists, this core plays robot and gateway at once: it consumes ``controller/command``
(humanpt.FlangeCommand: per-cycle translation in m and rotation vector in rad, world frame)
and on every cycle (28 ms) applies the latest command - clipped to the paper's step-
controller limits, 100 mm/s and 60 deg/s - to the true flange pose, then publishes
``robot_gateway/robot_state`` (what the gateway would report) and ``sim_robot/truth``
(what the camera simulator needs): the pose at the cycle's stamp, reached by moving over
the cycle that ends there. No kinematics, no joint limits, no latency - unless
``lag_time_constant_ms`` > 0: then the commands move a setpoint and the flange follows it
with a first-order lag (the reported pose is the lagging flange, as encoders measure it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np

from humanpt.geometry import (
    DEFAULT_DZ_MM,
    DEFAULT_FLANGE_T_CAMERA_MM,
    apply_step,
    interpolate_transform,
    transform_from_x,
    viewing_world_T_flange,
    x_from_transform,
)
from humanpt.operator.scenario import BUILTIN_SCENARIOS, Scenario, Trajectory, builtin_scenario
from humanpt.runtime.config import Deg, Mm, Range
from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_vector3, pose
from humanpt.sim_robot.arm import lag_gain

__all__ = [
    "StandInRobotConfig",
    "StandInRobotCore",
    "DEFAULT_START_FLANGE_MM_DEG",
    "viewing_start_flange",
]



def viewing_start_flange(
    scenario: Scenario,
    dz_mm: float = DEFAULT_DZ_MM,
    flange_T_camera: np.ndarray = DEFAULT_FLANGE_T_CAMERA_MM,
) -> np.ndarray:
    """world_T_flange (4, 4), mm, that puts the scenario's first target pose (no tremor) on
    the camera's optical axis at ``dz_mm``, parallel to the camera: the paper's desired
    point D. A robot started there sees the target in its first image."""
    trajectory = Trajectory(scenario)
    path = trajectory.path_pose(0.0)
    world_T_tob = path @ trajectory.tip_T_tob if scenario.path == "tip" else path
    return viewing_world_T_flange(world_T_tob, dz_mm, flange_T_camera)


DEFAULT_START_FLANGE_MM_DEG: tuple[float, ...] = tuple(
    float(v) for v in x_from_transform(viewing_start_flange(builtin_scenario("static")))
)
"""Where the flange starts by default: the static (Table 1) target 600 mm ahead of the
camera on its optical axis, with the default hand-eye transform."""


@dataclass(frozen=True)
class StandInRobotConfig:
    """``cycle_ms``: the ALTER cycle. Start pose: ``start_flange_mm_deg`` (X of
    world_T_flange, mm, deg) when given, else the pose from which the camera (default
    hand-eye) sees the first target pose of the built-in scenario ``start_view`` at
    ``start_dz_mm`` on its axis. Per-cycle steps are clipped to ``max_speed_mm_s`` and
    ``max_rate_deg_s``. ``lag_time_constant_ms`` (default 0 = none; realistic ~10-30 ms):
    per cycle the flange covers 1 - exp(-cycle/tau) of the way to its setpoint (linear in
    translation, geodesic in rotation)."""

    cycle_ms: Annotated[float, Range(1, 1000, "ms")] = 28.0
    start_flange_mm_deg: tuple[Mm, Mm, Mm, Deg, Deg, Deg] | None = None
    start_view: Literal["static", "arc", "trapezium", "freehand", "scurve", "abrupt", "occluded", "partial"] = "static"
    start_dz_mm: Annotated[float, Range(10, 5000, "mm")] = DEFAULT_DZ_MM
    max_speed_mm_s: Annotated[float, Range(1e-3, 1000, "mm/s")] = 100.0
    max_rate_deg_s: Annotated[float, Range(1e-3, 1000, "deg/s")] = 60.0
    lag_time_constant_ms: Annotated[float, Range(0, 10000, "ms")] = 0.0

    def __post_init__(self) -> None:
        for name in ("cycle_ms", "max_speed_mm_s", "max_rate_deg_s", "start_dz_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"standin_robot.{name} must be finite and > 0, got {value}")
        if not (math.isfinite(self.lag_time_constant_ms) and 0 <= self.lag_time_constant_ms <= 10000):
            raise ValueError(
                f"standin_robot.lag_time_constant_ms must be within 0 and 10000, got {self.lag_time_constant_ms}"
            )
        if self.start_view not in BUILTIN_SCENARIOS:
            raise ValueError(
                f"standin_robot.start_view must be one of {', '.join(BUILTIN_SCENARIOS)}"
            )
        if self.start_flange_mm_deg is not None:
            x = np.asarray(self.start_flange_mm_deg, dtype=float)
            if x.shape != (6,) or not np.all(np.isfinite(x)):
                raise ValueError(
                    f"standin_robot.start_flange_mm_deg must be 6 finite numbers, got {x}"
                )

    @property
    def start_world_T_flange(self) -> np.ndarray:
        """The start pose (4, 4), mm."""
        if self.start_flange_mm_deg is not None:
            return transform_from_x(np.asarray(self.start_flange_mm_deg, dtype=float))
        return viewing_start_flange(builtin_scenario(self.start_view), self.start_dz_mm)


class StandInRobotCore(Core):
    """See the module docstring. Events: ``bad_command`` (non-finite values, ignored),
    ``step_clipped`` (a command beyond the limits, once per run of clipped cycles)."""

    name = "standin_robot"
    config_type = StandInRobotConfig
    ports = (
        Port("controller/command", pb.FlangeCommand, "_on_command"),
        Port("tick", pb.Tick, "_on_tick"),
    )

    def __init__(self, config: StandInRobotConfig):
        super().__init__(config)
        self.world_T_flange = config.start_world_T_flange  # mm, the true (and reported) flange
        self.setpoint = self.world_T_flange  # mm, where the commands put it
        # the first-order lag every simulated robot shares (humanpt.sim_robot.arm)
        self.lag_gain = lag_gain(config.cycle_ms, config.lag_time_constant_ms)
        self.cycle = 0
        self.pending: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.missed = 0
        self.clipping = False

    def tick_period_ns(self) -> int | None:
        return round(self.config.cycle_ms * 1e6)

    def _on_command(self, t_ns: int, msg: pb.FlangeCommand) -> list[Output]:
        d_t_mm = from_vector3(msg.d_translation_m) * 1000.0
        d_r = from_vector3(msg.d_rotation_rad)
        if not (np.all(np.isfinite(d_t_mm)) and np.all(np.isfinite(d_r))):
            return [
                self.event(
                    t_ns,
                    pb.SEVERITY_WARNING,
                    "bad_command",
                    f"ignored a command with non-finite values (cycle {msg.cycle})",
                )
            ]
        # Keyed by cycle, as a controller applies a correction: the command computed from
        # state c moves the flange during the next cycle (published as state c + 1); one
        # sent early for c + 1 (after a new image) waits its turn.
        self.pending[int(msg.cycle)] = (d_t_mm, d_r)
        return []

    def _on_tick(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        return self._cycle(t_ns)

    def _cycle(self, t_ns: int) -> list[Output]:
        out: list[Output] = []
        step = self.pending.pop(self.cycle - 1, None)
        for c in [c for c in self.pending if c < self.cycle - 1]:
            del self.pending[c]  # too late to apply
        if step is None:
            self.missed += 1
        else:
            d_t_mm, d_r = step
            self.missed = 0
            dt_s = self.config.cycle_ms / 1000.0
            max_t = self.config.max_speed_mm_s * dt_s
            max_r = math.radians(self.config.max_rate_deg_s) * dt_s
            n_t, n_r = float(np.linalg.norm(d_t_mm)), float(np.linalg.norm(d_r))
            clipped = n_t > max_t * (1 + 1e-9) or n_r > max_r * (1 + 1e-9)
            if n_t > max_t:
                d_t_mm = d_t_mm * (max_t / n_t)
            if n_r > max_r:
                d_r = d_r * (max_r / n_r)
            if clipped and not self.clipping:
                out.append(
                    self.event(
                        t_ns,
                        pb.SEVERITY_WARNING,
                        "step_clipped",
                        f"command of {n_t:.3f} mm / {math.degrees(n_r):.3f} deg per cycle "
                        f"clipped to {max_t:.3f} mm / {math.degrees(max_r):.3f} deg",
                    )
                )
            self.clipping = clipped
            self.setpoint = apply_step(self.setpoint, d_t_mm, d_r)
        if self.lag_gain == 1.0:
            self.world_T_flange = self.setpoint
        else:
            self.world_T_flange = interpolate_transform(self.world_T_flange, self.setpoint, self.lag_gain)
        world_T_flange_m = self.world_T_flange.copy()
        world_T_flange_m[:3, 3] /= 1000.0
        state = pb.RobotState(
            header=self.next_header("robot_gateway/robot_state", t_ns, "world"),
            cycle=self.cycle,
            missed_cycles=self.missed,
            status=pb.AlterStatus(alter_active=True, arm_power=True),
            cycle_period_ns=self.tick_period_ns(),  # the stand-in link's cycle (runtime/cycle.py)
        )
        state.world_T_flange.CopyFrom(pose(world_T_flange_m))
        truth = pb.Truth(header=self.next_header("sim_robot/truth", t_ns, "world"))
        truth.world_T_flange.CopyFrom(pose(world_T_flange_m))
        self.cycle += 1
        return [*out, ("robot_gateway/robot_state", state), ("sim_robot/truth", truth)]
