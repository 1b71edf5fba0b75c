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
from humanpt.geometry.transforms import transform_from_x, x_from_transform
from humanpt.geometry.units import to_mm
from humanpt.operator import OperatorConfig
from humanpt.perception.config import PerceptionConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose

from . import evaluate
from .run import SystemConfig, run, scenario_duration_s
from .system import link_cycle_ms

__all__ = ["EXPERIMENTS", "STATIC_VECTORS", "PAPER", "TABLE", "STATS", "KINDS", "ExperimentResult", "run_experiment",
           "against_known_path", "ideal_path", "raw_path_points", "over_seeds", "PlaybackResult", "run_playback",
           "playback_report", "plot_playback"]

EXPERIMENTS = ("static", "arc", "trapezium")
# The static experiment records 106 vectors (paper, Section 6) at 10 cycles each.
STATIC_VECTORS = 106

# The paper's published Tables 1-3 (mm, deg); Table 2 and 3 have no SD row.
PAPER = {
    "static": {"ME": [1.13e-13, -4.3e-15, 2.44e-14, -6.1e-16, 1.0e-15, -8.8e-15],
               "MAE": [0.0089, 0.0412, 0.0949, 0.0056, 0.0026, 0.0039],
               "MaxE": [0.0369, 0.1403, 0.352, 0.2972, 0.1401, 0.2041],
               "SD": [0.0116, 0.0508, 0.1170, 0.0290, 0.0137, 0.0199]},
    "arc": {"ME": [0.0436, 0.1093, -0.294, 0.1795, -0.0472, -0.1662],
            "MAE": [0.2466, 0.4843, 0.3048, 0.6212, 0.4581, 0.4313],
            "MaxE": [1.1477, 1.7052, 1.0210, 1.8740, 1.7380, 0.8604]},
    "trapezium": {"ME": [0.1376, -0.428, -4e-4, 0.0007, -7e-4, 0.0008],
                  "MAE": [0.9949, 0.7873, 0.392, 0.822, 0.8333, 1.0736],
                  "MaxE": [3.934, 3.8898, 1.344, 3.181, 2.588, 3.276]},
}
TABLE = {"static": 1, "arc": 2, "trapezium": 3}
STATS = ("ME", "MAE", "MaxE", "SD")
# Errors as the paper computed them ("paper") and against ground truth ("truth").
# Errors as the paper computed them and against ground truth, of the filtered path and of
# the raw state vectors (step 10's X_WG before the filter: the paper's method as published).
KINDS = ("paper", "truth", "paper_raw", "truth_raw")


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


def over_seeds(per_seed: list[ExperimentResult]) -> dict:
    """One experiment's runs over seeds summarised as ``humanpt experiment --seeds N`` reports
    them: {kind: {stat: (6,) median over the seeds}} for each of :data:`KINDS` and
    :data:`STATS`, ``spread`` {kind: {stat: [min (6,), max (6,)]}}, ``n`` (vectors per seed),
    ``which``, ``x`` (the first seed's path), ``wall_s``, ``twin_s`` (sums)."""
    stats = {kind: [dict(evaluate.Stats.of(getattr(r, f"err_{kind}")).rows()) for r in per_seed] for kind in KINDS}
    per = {kind: {stat: np.array([st[stat] for st in stats[kind]]) for stat in STATS} for kind in KINDS}
    return {"x": per_seed[0].x, "which": per_seed[0].which,
            "wall_s": sum(r.wall_s for r in per_seed), "twin_s": sum(r.twin_s for r in per_seed),
            "n": [evaluate.Stats.of(r.err_paper).n for r in per_seed],
            "n_raw": [evaluate.Stats.of(r.err_paper_raw).n for r in per_seed],
            **{kind: {stat: np.median(a, axis=0) for stat, a in per[kind].items()} for kind in KINDS},
            "spread": {kind: {stat: [a.min(axis=0).tolist(), a.max(axis=0).tolist()]
                              for stat, a in per[kind].items()} for kind in KINDS}}


@dataclass
class PlaybackResult:
    """Figure 9b-d's run (issue 33.3): the seam taught on the twin, fitted and played back on
    the simulated Puma (:func:`humanpt.twin.teach.calibrate_then_teach`)."""

    scenario: str
    robot: str
    seam_mm: np.ndarray  # (K, 3) the seam as designed
    taught_x: np.ndarray  # (N, 6) the taught path (mm, deg)
    played_x: np.ndarray  # (M, 6) the torch's true poses every cycle from the path's start
    against_seam: object  # seam.compare.Comparison of the played torch against the seam
    against_taught: object  # ... against the taught path (a polyline through its points)
    max_joint_step_deg: float | None
    joint_step_limit_deg: float | None
    warnings: list
    refused: str
    wall_s: float


def run_playback(scenario: str = "trapezium", seed: int = 0, world: str = "ideal", robot: str = "puma",
                 run_dir: str | Path | None = None) -> PlaybackResult:
    """The paper's real-time implementation (Section 6, Figure 9b-d): teach ``scenario`` on
    the twin, fit it (``humanpt path fit``) and play it back on ``robot`` (the simulated Puma
    behind the gateway and ALTER); the played torch's true path against the seam and against
    the taught path (:func:`humanpt.seam.compare.compare_points`)."""
    from humanpt.seam.compare import compare_points, polyline_seam

    from . import teach
    from .worlds import World

    res = teach.calibrate_then_teach(scenario, World.named(world), seed, stages=(), robot=robot, run_dir=run_dir)
    op = SystemConfig.for_scenario(scenario, seed).operator
    seam = teach._seam(op)
    played = res.played_x if res.played_x is not None else np.zeros((0, 6))
    taught = res.taught_x if res.taught_x is not None else np.zeros((0, 6))
    taught_p = transform_from_x(taught)[:, :3, 3] if len(taught) else np.zeros((0, 3))
    vs_taught = (compare_points(polyline_seam(taught_p), played[:, :3], approach_mm=None, window="played torch")
                 if len(played) and len(taught_p) > 1 else None)
    return PlaybackResult(scenario, robot, seam, taught, played, res.compared.get("played"), vs_taught,
                          res.max_joint_step_deg, res.joint_step_limit_deg, list(res.warnings), res.refused,
                          res.seconds)


def _unwrapped_deg(angles_deg: np.ndarray) -> np.ndarray:
    """(N, 3) angles (deg) without the 360 deg jumps between samples."""
    return np.degrees(np.unwrap(np.radians(np.asarray(angles_deg, dtype=float)), axis=0))


def playback_report(r: PlaybackResult) -> str:
    """The run's statistics, one line each."""
    lines = [f"{r.scenario} taught on the twin and played back on {r.robot}: {len(r.taught_x)} taught points, "
             f"{len(r.played_x)} played torch poses (one per cycle)"]
    if r.refused:
        lines.append(f"  REFUSED before any motion: {r.refused}")
    for name, c in (("played torch against the seam", r.against_seam),
                    ("played torch against the taught path", r.against_taught)):
        if c is None:
            lines.append(f"  {name}: no points")
        else:
            lines.append(f"  {name:40s} RMS {c.rms_mm:.3f} mm, mean {c.mean_mm:.3f}, max {c.max_mm:.3f}, "
                         f"covered {100 * c.covered:.1f} %")
    if len(r.played_x):
        angles = _unwrapped_deg(r.played_x[:, 3:])  # (phi near +-180 deg is one angle, not two)
        mean = (angles.mean(axis=0) + 180.0) % 360.0 - 180.0
        lines.append("  played torch angles: psi/theta/phi mean " + " / ".join(f"{v:.2f}" for v in mean)
                     + " deg, sd " + " / ".join(f"{v:.2f}" for v in angles.std(axis=0)))
    if r.max_joint_step_deg is not None:
        lines.append(f"  largest joint step of a cycle {r.max_joint_step_deg:.2f} deg "
                     f"(limit {r.joint_step_limit_deg:.2f})")
    if r.warnings:
        lines.append("  warnings: " + "; ".join(r.warnings))
    return "\n".join(lines)


def plot_playback(r: PlaybackResult, path: Path, title: str = "") -> Path:
    """Figure 9b-d as the paper drew them: (b) y vs x, (c) z vs y of the seam, the taught
    path and the played torch; (d) the played torch's angles per sample."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.5))
    for a, (i, j, name) in zip(ax[:2], ((0, 1, "(b) y vs x"), (1, 2, "(c) z vs y")), strict=True):
        a.plot(r.seam_mm[:, i], r.seam_mm[:, j], "k-", lw=1, label="seam")
        if len(r.taught_x):
            a.plot(r.taught_x[:, i], r.taught_x[:, j], ".", ms=2, color="tab:blue", label="taught")
        if len(r.played_x):
            a.plot(r.played_x[:, i], r.played_x[:, j], "-", lw=0.8, color="tab:red", label="played (Puma)")
        a.set_xlabel("xyz"[i] + " (mm)")
        a.set_ylabel("xyz"[j] + " (mm)")
        a.set_title(name)
        a.legend(fontsize=8)
        if i == 0:
            a.set_aspect("equal", adjustable="datalim")
    for k, name in enumerate(("psi", "theta", "phi")):
        if len(r.played_x):
            ax[2].plot(_unwrapped_deg(r.played_x[:, 3:])[:, k], lw=0.8, label=name)
    ax[2].set_xlabel("sample (cycle)")
    ax[2].set_ylabel("deg")
    ax[2].set_title("(d) played torch's angles")
    ax[2].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
