"""The operator as a component core: moves the target along a scenario and publishes the
truth (world_T_tob, and world_T_tip with a driver, and the scenario's covers of the
sources) on ``operator/truth`` at a fixed rate."""

from __future__ import annotations

import math

from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import pose_from_mm

from .config import OperatorConfig
from .scenario import Trajectory

__all__ = ["OperatorCore"]


class OperatorCore(Core):
    """On every tick: advance scenario time by the tick's duration x ``speed_scale`` (after
    ``start_delay_s``), publish the pose there. Events: ``scenario_started`` (at the first
    tick after the start delay: the target starts to move),
    ``scenario_done`` (when the last segment ends; the target then holds still)."""

    name = "operator"
    config_type = OperatorConfig
    ports = (Port("tick", pb.Tick, "_on_tick"),)

    def __init__(self, config: OperatorConfig):
        super().__init__(config)
        self.scenario = config.build_scenario()
        self.trajectory = Trajectory(self.scenario, config.hand_tremor())
        self.first_ns: int | None = None
        self.last_ns = 0
        self.scenario_t_s = 0.0
        self.done = False
        self.started = False

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def _on_tick(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        out: list[Output] = []
        if self.first_ns is None:
            self.first_ns = self.last_ns = t_ns
        if not self.started and t_ns - self.first_ns >= self.config.start_delay_s * 1e9:
            # When the target starts to move (after the start delay), not when the operator
            # came up: what "while the target moved" is measured from.
            self.started = True
            s = self.scenario
            out.append(
                self.event(
                    t_ns,
                    pb.SEVERITY_INFO,
                    "scenario_started",
                    f"scenario {s.name}: {len(s.segments)} segments, "
                    f"{self.trajectory.duration_s:.2f} s at pace 1, path {s.path}, "
                    f"driver {'none' if s.driver_mm is None else s.driver_mm}",
                )
            )
        dt_s = max(t_ns - self.last_ns, 0) / 1e9
        self.last_ns = t_ns
        elapsed_s = (t_ns - self.first_ns) / 1e9
        moving_s = min(dt_s, max(elapsed_s - self.config.start_delay_s, 0.0))
        self.scenario_t_s += moving_s * self.config.speed_scale
        world_T_tob, world_T_tip = self.trajectory.pose(self.scenario_t_s, tremor_t_s=elapsed_s)
        truth = pb.Truth(header=self.next_header("operator/truth", t_ns, "world"))
        truth.world_T_tob.CopyFrom(pose_from_mm(world_T_tob))
        if world_T_tip is not None:
            truth.has_tip = True
            truth.world_T_tip.CopyFrom(pose_from_mm(world_T_tip))
        cover = self.trajectory.cover(self.scenario_t_s)
        if cover is not None:  # (only scenarios with covers: the others' truth is unchanged)
            truth.cover_fraction.extend(cover[0])
            truth.cover_angle_rad.extend(math.radians(a) for a in cover[1])
        out.append(("operator/truth", truth))
        if (
            not self.done
            and self.scenario_t_s >= self.trajectory.duration_s
            and (self.trajectory.duration_s > 0 or elapsed_s >= self.config.start_delay_s)
        ):
            self.done = True
            out.append(
                self.event(
                    t_ns,
                    pb.SEVERITY_INFO,
                    "scenario_done",
                    f"scenario {self.scenario.name} done after {elapsed_s:.3f} s; holding",
                )
            )
        return out
