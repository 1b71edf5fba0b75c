"""``humanpt experiment static|arc|trapezium``: the paper's Section 6 on the twin.

Each experiment runs the closed loop in lock-step (the simulated Puma behind the ALTER
link), records the path as the paper did (one state vector every 10 cycles) and computes
the paper's statistics: ME, MAE, MaxE and SD of x, y, z, psi, theta, phi,

* as the paper did: against the mean (static, Table 1) or the known path (arc, Table 2:
  the circle; trapezium, Table 3: the edges), taking for each recorded point the nearest
  point of the ideal path;
* against ground truth at the same instant (what the paper could not measure);

with the paper's perception method and the default one side by side, beside the paper's
published tables.  Plots like Figures 7-9 are saved as PNG.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from humanpt.geometry.transforms import x_from_transform
from humanpt.twin import evaluate

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
# The static experiment records 106 vectors (paper, Section 6) at 10 cycles each.
STATIC_VECTORS = 106


def _ideal_path(op, n: int = 4000) -> np.ndarray:
    """(n, 6) X of the ideal path (the scenario without tremor): the tip's for a tip path."""
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


def run_one(name: str, method: str, seed: int, robot: str, run_dir: Path | None, vectors: int = STATIC_VECTORS,
            speed_scale: float = 1.0, overrides: dict[str, dict] | None = None):
    """One experiment with one perception method: (path X (N, 6), errors as the paper did,
    errors against ground truth, which point, wall seconds, twin seconds). ``overrides``:
    {section: {key: value}} for sim_camera, perception, pose_filter, controller."""
    from humanpt.cli.demo import scenario_duration_s, with_overrides
    from humanpt.controller.config import ControllerConfig
    from humanpt.perception.config import PerceptionConfig
    from humanpt.pose_filter.config import PoseFilterConfig
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas.convert import header
    from humanpt.sim_camera import SimCameraConfig
    from humanpt.twin.system import build_system, operator_config

    op = operator_config(name, seed)
    over = overrides or {}
    ctl = with_overrides(ControllerConfig(recording_delay_cycles=10), over, "controller")
    if name == "static":
        # Record 106 vectors once the servo has settled on the still target.
        op = dataclasses.replace(op, start_delay_s=3.0)
        record_from_s, duration = 3.0, 3.0 + vectors * 10 * ctl.cycle_period_ms * 1e-3 + 0.2
    else:
        op = dataclasses.replace(op, speed_scale=speed_scale)
        record_from_s, duration = op.start_delay_s, op.start_delay_s + scenario_duration_s(op) / speed_scale
    world = build_system(op, seed=seed, perception=with_overrides(PerceptionConfig(method=method), over, "perception"),
                         controller=ctl, robot=robot, run_dir=run_dir, digest=False,
                         pose_filter=with_overrides(PoseFilterConfig(), over, "pose_filter"),
                         sim_camera=with_overrides(SimCameraConfig(), over, "sim_camera"))
    t0 = time.perf_counter()
    world.run_until(round(record_from_s * 1e9))
    world.lockstep.inject(world.now_ns, "controller", "console/command",
                          pb.Command(header=header(world.now_ns), component="controller", verb="record_start"))
    world.run_until(round(duration * 1e9))
    wall = time.perf_counter() - t0
    world.close()
    which, err_truth, _ = evaluate.path_truth_errors(world)
    _, xg, xt = evaluate.path_points(world)
    x = xt if xt is not None else xg
    if name == "static":
        x = x[:vectors]
        err_truth = err_truth[:vectors]
        err_paper = x - x.mean(0)
        err_paper[:, 3:] = evaluate.wrap_deg(err_paper[:, 3:])
    else:
        err_paper = against_known_path(x, _ideal_path(op))
    return x, err_paper, err_truth, which, wall, duration


def _fmt_row(label: str, v) -> str:
    return f"{label:44s}" + "".join(f"{x:10.4f}" for x in v)


def plots(name: str, results: dict, out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = results["weighted"]["x"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    fig.suptitle(f"humanpt experiment {name} (twin; default perception)  -  cf. the paper's "
                 f"Figure {TABLE[name] + 6}")
    axes[0].plot(x[:, 0], x[:, 1], ".-", ms=3)
    axes[0].set_xlabel("x (mm)")
    axes[0].set_ylabel("y (mm)")
    axes[0].set_title("y versus x")
    axes[0].axis("equal")
    axes[1].plot(x[:, 1], x[:, 2], ".-", ms=3)
    axes[1].set_xlabel("y (mm)")
    axes[1].set_ylabel("z (mm)")
    axes[1].set_title("z versus y")
    for k, lab in zip(range(3, 6), ("psi", "theta", "phi"), strict=True):
        # Unwrapped, so a roll near 180 deg does not jump between +-180.
        axes[2].plot(np.degrees(np.unwrap(np.radians(x[:, k]))), label=lab)
    axes[2].set_xlabel("recorded sample")
    axes[2].set_ylabel("angle (deg)")
    axes[2].set_title("rotation angles")
    axes[2].legend()
    fig.tight_layout()
    path = out / f"figure-{name}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def experiment(args) -> int:
    from humanpt.cli.commands import run_stamp
    from humanpt.cli.demo import parse_overrides

    over = parse_overrides(getattr(args, "set", None))
    unknown = set(over) - {"sim_camera", "perception", "pose_filter", "controller"}
    if unknown:
        raise ValueError(f"--set: no section {', '.join(sorted(unknown))} "
                         "(sim_camera, perception, pose_filter, controller)")

    out = Path(args.out) if args.out else Path("runs") / f"{run_stamp()}-experiment-{args.name}"
    out.mkdir(parents=True, exist_ok=True)
    methods = ["paper", "weighted"] if args.method == "both" else [args.method]
    results = {}
    for m in methods:
        run_dir = out / f"run-{m}" if args.record else None
        x, ep, et, which, wall, dur = run_one(args.name, m, args.seed, args.robot, run_dir, args.vectors,
                                              args.speed_scale, over)
        results[m] = {"x": x, "paper": evaluate.Stats.of(ep), "truth": evaluate.Stats.of(et), "which": which,
                      "wall_s": wall, "twin_s": dur}
        print(f"  {m} perception: {len(x)} vectors of {which}, {dur:.1f} s of twin time in {wall:.1f} s", flush=True)
    how = "against the mean" if args.name == "static" else "against the known path"
    lines = [f"humanpt experiment {args.name}: the paper's Table {TABLE[args.name]} on the twin "
             f"(mm, deg; errors {how} as the paper computed them, and against ground truth)", "",
             f"{'':44s}" + "".join(f"{c:>10s}" for c in evaluate.COORDS)]
    names = {"paper": "paper's perception", "weighted": "default perception"}
    for stat in ("ME", "MAE", "MaxE", "SD"):
        if stat in PAPER[args.name]:
            lines.append(_fmt_row(f"{stat}  paper, Table {TABLE[args.name]} (published)", PAPER[args.name][stat]))
        for m in methods:
            lines.append(_fmt_row(f"{stat}  twin, {names[m]}, {how}", dict(results[m]["paper"].rows())[stat]))
        for m in methods:
            lines.append(_fmt_row(f"{stat}  twin, {names[m]}, vs ground truth", dict(results[m]["truth"].rows())[stat]))
        lines.append("")
    text = "\n".join(lines)
    print(text)
    (out / "table.txt").write_text(text + "\n")
    summary = {m: {"which": r["which"], "n": r["paper"].n, "wall_s": r["wall_s"], "twin_s": r["twin_s"],
                   **{f"{kind}_{stat}": dict(r[kind].rows())[stat].tolist() for kind in ("paper", "truth")
                      for stat in ("ME", "MAE", "MaxE", "SD")}} for m, r in results.items()}
    (out / "results.json").write_text(json.dumps({"experiment": args.name, "seed": args.seed,
                                                   "published": PAPER[args.name], "twin": summary}, indent=1))
    if "weighted" in results and not args.no_plots:
        print(f"figure: {plots(args.name, results, out)}")
    print(f"results: {out / 'table.txt'}, {out / 'results.json'}")
    return 0
