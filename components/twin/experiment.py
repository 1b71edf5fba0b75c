"""The paper's Section 6 experiments (static, arc, trapezium) on the lock-step twin.

Each runs the closed loop (:func:`humanpt.twin.run.run`), records the path as the paper
did (one state vector every 10 cycles) and gives its errors

* as the paper computed them: against the mean (static, Table 1) or the known path (arc,
  Table 2: the circle; trapezium, Table 3: the edges), taking for each recorded point the
  nearest point of the ideal path;
* against ground truth at the same instant (what the paper could not measure);

and the same for the paper's raw state vector (step 10: the perception's own X_WG of each
recorded image, before the Kalman filter; ``[controller] record_raw``), the paper's method
without the filter, so that each comparison with the paper's tables is like for like.

``humanpt experiment`` prints them beside the paper's published tables.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.controller.config import ControllerConfig
from humanpt.geometry.transforms import x_from_transform
from humanpt.geometry.units import to_mm
from humanpt.operator import OperatorConfig
from humanpt.perception.config import PerceptionConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose

from . import evaluate
from .run import SystemConfig, run, scenario_duration_s
from .system import link_cycle_ms

__all__ = ["EXPERIMENTS", "STATIC_VECTORS", "ExperimentResult", "run_experiment", "against_known_path",
           "ideal_path", "raw_path_points"]

EXPERIMENTS = ("static", "arc", "trapezium")
# The static experiment records 106 vectors (paper, Section 6) at 10 cycles each.
STATIC_VECTORS = 106


def ideal_path(op: OperatorConfig, n: int = 4000) -> np.ndarray:
    """(n, 6) X (mm, deg) of the ideal path (the scenario without tremor): the tip's for a
    tip path."""
    from humanpt.operator.scenario import Trajectory

    traj = Trajectory(op.build_scenario())
    ts = np.linspace(0.0, max(traj.duration_s, 1e-9), n)
    return np.array([x_from_transform(traj.path_pose(t)) for t in ts])


def against_known_path(x: np.ndarray, ideal: np.ndarray) -> np.ndarray:
    """Errors (N, 6) of recorded X against the nearest (in position) point of the ideal path."""
    d = np.linalg.norm(x[:, None, :3] - ideal[None, :, :3], axis=2)
    near = ideal[np.argmin(d, axis=1)]
    err = x - near
    err[:, 3:] = evaluate.wrap_deg(err[:, 3:])
    return err


def raw_path_points(src) -> tuple[np.ndarray, np.ndarray]:
    """The recorded path's raw state vectors (``PathPoint.world_T_tob_raw``, or the tip's
    through it): (index into the recorded points (M,), X mm/deg (M, 6)) of the points that
    carry one (a position-only measurement has none)."""
    pts = [pb.PathPoint.FromString(o.data) for o in src.outputs("controller/path")]
    keep = [i for i, p in enumerate(pts) if p.HasField("world_T_tob_raw")]
    field = "world_T_tip_raw" if pts and pts[0].has_tip else "world_T_tob_raw"
    x = np.array([x_from_transform(to_mm(from_pose(getattr(pts[i], field)))) for i in keep]).reshape(-1, 6)
    return np.array(keep, dtype=np.int64), x


@dataclass
class ExperimentResult:
    """One experiment with one perception method."""

    x: np.ndarray  # (N, 6) the recorded path, X (mm, deg): the tip's for a tip path, else G's
    err_paper: np.ndarray  # (N, 6) errors as the paper computed them
    err_truth: np.ndarray  # (N, 6) errors against ground truth at the same instant
    which: str  # the point recorded ("G" or "tip")
    wall_s: float
    twin_s: float
    # The same for the raw state vectors (before the filter) of the points that have one.
    x_raw: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 6)))
    err_paper_raw: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 6)))
    err_truth_raw: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 6)))


def run_experiment(name: str, method: str, seed: int = 0, robot: str = "puma", run_dir: str | Path | None = None,
                   vectors: int = STATIC_VECTORS, speed_scale: float = 1.0,
                   overrides: dict[str, dict] | None = None, rsi_cycle_ms: float | None = None) -> ExperimentResult:
    """Experiment ``name`` (one of :data:`EXPERIMENTS`) with perception ``method``.
    ``overrides``: {section: {key: value}} for sim_camera, perception, pose_filter,
    controller (OverrideError on a bad key or value). Static: ``vectors`` recorded once
    the servo has settled on the still target; arc, trapezium: the scenario at
    ``speed_scale`` times its speed, recorded from its start. ``rsi_cycle_ms`` (4 or 12):
    the simulated Puma over the RSI link instead of ALTER (:func:`humanpt.twin.run.run`)."""
    cfg = SystemConfig.for_scenario(name, seed, overrides,
                                    controller=ControllerConfig(recording_delay_cycles=10, record_raw=True),
                                    perception=PerceptionConfig(method=method))
    op = cfg.operator
    if name == "static":
        op = dataclasses.replace(op, start_delay_s=3.0)
        record_from_s = 3.0
        duration = 3.0 + vectors * 10 * link_cycle_ms(rsi_cycle_ms) * 1e-3 + 0.2
    else:
        op = dataclasses.replace(op, speed_scale=speed_scale)
        record_from_s, duration = op.start_delay_s, op.start_delay_s + scenario_duration_s(op) / speed_scale
    res = run(dataclasses.replace(cfg, operator=op), robot=robot, duration_s=duration, record_from_s=record_from_s,
              run_dir=run_dir, rsi_cycle_ms=rsi_cycle_ms)
    which, err_truth, _ = res.path_truth_errors()
    stamps, xg, xt = res.path_points()
    x = xt if xt is not None else xg
    keep, x_raw = raw_path_points(res.world)
    if name == "static":
        x = x[:vectors]
        err_truth = err_truth[:vectors]
        x_raw = x_raw[keep < vectors]
        keep = keep[keep < vectors]
    truth = np.array([x_from_transform(T) for T in evaluate.truth_at(
        res.world, stamps[keep], field="world_T_tip" if which == "tip" else "world_T_tob")]).reshape(-1, 6)
    err_truth_raw = x_raw - truth
    err_truth_raw[:, 3:] = evaluate.wrap_deg(err_truth_raw[:, 3:])
    return ExperimentResult(x, _err_paper(name, x, op), err_truth, which, res.wall_s, duration,
                            x_raw, _err_paper(name, x_raw, op), err_truth_raw)


def _err_paper(name: str, x: np.ndarray, op: OperatorConfig) -> np.ndarray:
    """Errors (N, 6) as the paper computed them: against the mean (static) or the nearest
    point of the known path."""
    if not len(x):
        return np.zeros((0, 6))
    if name == "static":
        err = x - x.mean(0)
        err[:, 3:] = evaluate.wrap_deg(err[:, 3:])
        return err
    return against_known_path(x, ideal_path(op))
