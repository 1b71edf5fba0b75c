"""``humanpt experiment static|arc|trapezium``: the paper's Section 6 on the twin.

Each experiment (:func:`humanpt.twin.experiment.run_experiment`: the closed loop in
lock-step, the simulated Puma behind the ALTER link, the path recorded as the paper did)
gives the paper's statistics: ME, MAE, MaxE and SD of x, y, z, psi, theta, phi, as the
paper computed them and against ground truth, with the paper's perception method and the
default one side by side, beside the paper's published tables; each also without the
filter (the raw state vectors of step 10, as the paper stored them: like for like).  Plots like Figures 7-9
are saved as PNG.

``humanpt experiment budget``: the error budget of the twin's world (issue 16,
:mod:`humanpt.twin.budget`): the scenario on the ideal world, with each error source
alone, then with all of them; a table, ``budget.csv`` and ``budget.png``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from humanpt.runtime import tables
from humanpt.twin import evaluate
from humanpt.twin import experiment as experiment_mod

# The paper's published tables and the statistics (humanpt.twin.experiment, which the results
# page's generator shares).
PAPER, TABLE, STATS, KINDS = experiment_mod.PAPER, experiment_mod.TABLE, experiment_mod.STATS, experiment_mod.KINDS


def rsi_cycle_ms(args) -> float | None:
    """``--link rsi [--cycle-ms]`` -> the RSI cycle (4 or 12); None over ALTER. ValueError
    for a cycle the link does not have (``--link alter --cycle-ms 4``)."""
    from humanpt.twin.live import link_cycle_ms

    cycle = link_cycle_ms(args.link, args.cycle_ms)
    if args.link == "rsi" and args.robot != "puma":
        raise ValueError("--link rsi drives the simulated Puma (--robot puma)")
    return None if args.link == "alter" else cycle


def _row(label: str, v) -> list[str]:
    return [label, *(tables.number(float(x)) for x in v)]


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


def budget(args) -> int:
    """``humanpt experiment budget``: run :func:`humanpt.twin.budget.run_budget`, print its
    table, save ``budget.csv``, ``budget.txt`` and (unless ``--no-plots``) ``budget.png``."""
    import sys

    from humanpt.cli.commands import run_stamp
    from humanpt.runtime.config import ConfigError
    from humanpt.twin import budget as bud

    args.scenario = args.scenario or "arc"
    for flag in ("set", "record", "speeds", "world"):
        if getattr(args, flag, None):
            raise ValueError(f"--{flag} does not apply to the budget (its worlds are the error sources; "
                             "the rig stays nominal)")
    only = [n.strip() for n in args.only.split(",") if n.strip()] if args.only else None
    todo = bud.plan(args.robot, only)  # ValueError naming an unknown source, before anything runs
    try:  # a bad scenario is the user's mistake: say so once, not as a failed row per source
        from humanpt.twin.run import SystemConfig

        SystemConfig.for_scenario(args.scenario, args.seed)
    except (ConfigError, OSError, ValueError) as e:
        raise SystemExit(f"humanpt: --scenario {args.scenario}: {e}") from None
    if args.duration is not None and args.duration <= 0:
        raise ValueError(f"--duration must be > 0, got {args.duration}")
    out = Path(args.out) if args.out else Path("runs") / f"{run_stamp()}-experiment-budget"
    out.mkdir(parents=True, exist_ok=True)
    for s, skip in todo:
        if skip:
            print(f"  {s.name}: {skip} (--robot {args.robot})", file=sys.stderr, flush=True)

    def progress(i: int, n: int, row) -> None:
        what = row.status if not row.ran or not row.n else (
            f"|ME xyz| {float(np.linalg.norm(row.me[:3])):.3f} mm, RMS xyz {float(np.linalg.norm(row.rms[:3])):.3f} mm"
            + (f", warned: {', '.join(row.warnings)}" if row.warnings else ""))
        print(f"  [{i}/{n}] {row.source}: {what} ({row.wall_s:.1f} s)", file=sys.stderr, flush=True)

    kind = getattr(args, "rig_kind", "psvs")
    rows = bud.run_budget(args.scenario, args.seed, args.robot, only, args.duration, progress,
                          rsi_cycle_ms=rsi_cycle_ms(args), rig_kind=kind)
    text = bud.format_table(rows, args.scenario, args.seed, args.robot, kind)
    print(text)
    (out / "budget.txt").write_text(text + "\n")
    files = [bud.write_csv(rows, out / "budget.csv")]
    if not args.no_plots:
        files.append(bud.plot(rows, out / "budget.png", f"humanpt experiment budget: {args.scenario}, seed "
                              f"{args.seed}, robot {args.robot}" + (", stereo pair" if kind == "stereo" else "")
                              + " (recorded path against ground truth)"))
    print(f"results: {', '.join(str(f) for f in files)}")
    return 0


def hard(args) -> int:
    """``humanpt experiment hard``: :func:`humanpt.twin.hard.run_cases`, its table on stdout
    and in ``hard.txt``; exit status 1 when a case fails issue 18's acceptance."""
    import sys

    from humanpt.cli.commands import run_stamp
    from humanpt.cli.demo import parse_overrides
    from humanpt.runtime.config import ConfigError
    from humanpt.twin import hard as hc
    from humanpt.twin.run import SystemConfig
    from humanpt.twin.worlds import World

    scenarios = [s.strip() for s in args.scenario.split(",") if s.strip()] if args.scenario else hc.HARD_SCENARIOS
    try:
        speeds = ([float(v) for v in args.speeds.split(",") if v.strip()] if args.speeds
                  else list(hc.HARD_SPEEDS_MM_S))
    except ValueError:
        raise SystemExit(f"humanpt: --speeds: numbers (mm/s) separated by commas, got {args.speeds!r}") from None
    if not speeds or not all(0 < v <= 1000 for v in speeds):
        raise SystemExit(f"humanpt: --speeds: each within (0, 1000] mm/s, got {args.speeds!r}")
    over = parse_overrides(getattr(args, "set", None))
    try:
        world = World.named(args.world or "ideal")
        for s in scenarios:  # a bad scenario or key is the user's mistake: said once, before any run
            SystemConfig.for_scenario(s, args.seed, over, world=world)
    except (ConfigError, OSError, ValueError) as e:
        raise SystemExit(f"humanpt: {e}") from None
    out = Path(args.out) if args.out else Path("runs") / f"{run_stamp()}-experiment-hard"
    out.mkdir(parents=True, exist_ok=True)

    def progress(i: int, n: int, label: str) -> None:
        print(f"  [{i}/{n}] {label} done", file=sys.stderr, flush=True)

    cases = hc.run_cases(scenarios, speeds, args.seed, world, args.robot, over, progress,
                         rsi_cycle_ms=rsi_cycle_ms(args))
    text = (f"humanpt experiment hard: world {world.name}, seed {args.seed}, robot {args.robot}\n"
            + hc.format_cases(cases))
    print(text)
    (out / "hard.txt").write_text(text + "\n")
    print(f"results: {out / 'hard.txt'}")
    return 0 if all(c.passes() for c in cases) else 1


def playback(args) -> int:
    """``humanpt experiment playback``: Figure 9b-d (issue 33.3): the seam (``--scenario``,
    default the trapezium) taught on the twin and played back on the robot (default the
    simulated Puma); its statistics on stdout and in ``playback.txt``, the three panels in
    ``figure9bcd.png``."""
    from humanpt.cli.commands import run_stamp
    from humanpt.twin.experiment import playback_report, plot_playback, run_playback

    scenario = args.scenario or "trapezium"
    world = args.world or "ideal"
    out = Path(args.out) if args.out else Path("runs") / f"{run_stamp()}-experiment-playback"
    out.mkdir(parents=True, exist_ok=True)
    print(f"humanpt experiment playback: {scenario}, world {world}, seed {args.seed}, robot {args.robot}", flush=True)
    r = run_playback(scenario, args.seed, world, args.robot, run_dir=out / "run" if args.record else None)
    text = playback_report(r)
    print(text)
    (out / "playback.txt").write_text(text + "\n")
    if not args.no_plots:
        png = plot_playback(r, out / "figure9bcd.png", f"humanpt experiment playback: {scenario} on {args.robot}, "
                            f"world {world}, seed {args.seed}")
        print(f"figure: {png}")
    return 1 if r.refused or any("fault" in w or "not done" in w for w in r.warnings) else 0


def experiment(args) -> int:
    if args.name != "budget" and getattr(args, "rig_kind", "psvs") != "psvs":
        raise SystemExit(f"humanpt: --rig-kind applies to experiment budget, not {args.name} "
                         "(demo --rig-kind stereo runs a scenario on the pair)")
    if args.name == "playback":
        return playback(args)
    if args.name == "budget":
        return budget(args)
    if args.name == "hard":
        return hard(args)
    for flag in ("scenario", "speeds", "world"):
        if getattr(args, flag, None):
            raise SystemExit(f"humanpt: --{flag} applies to experiment budget or hard, not {args.name}")
    from humanpt.cli.commands import run_stamp
    from humanpt.cli.demo import parse_overrides
    from humanpt.twin.experiment import run_experiment
    from humanpt.twin.run import OverrideError

    over = parse_overrides(getattr(args, "set", None))
    unknown = set(over) - {"sim_camera", "perception", "pose_filter", "controller"}
    if unknown:
        raise ValueError(f"--set: no section {', '.join(sorted(unknown))} "
                         "(sim_camera, perception, pose_filter, controller)")

    if args.seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
    rsi = rsi_cycle_ms(args)  # a bad link or cycle fails before anything is made
    out = Path(args.out) if args.out else Path("runs") / f"{run_stamp()}-experiment-{args.name}"
    made = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    methods = ["paper", "weighted"] if args.method == "both" else [args.method]
    seeds = list(range(args.seed, args.seed + args.seeds))
    results = {}
    for m in methods:
        per_seed = []
        for seed in seeds:
            run_dir = (out / f"run-{m}" if len(seeds) == 1 else out / f"run-{m}-seed{seed}") if args.record else None
            try:
                r = run_experiment(args.name, m, seed, args.robot, run_dir, args.vectors, args.speed_scale, over,
                                   rsi_cycle_ms=rsi)
            except OverrideError as e:
                if made and not any(out.iterdir()):
                    out.rmdir()  # nothing was run: leave no empty run directory behind
                raise SystemExit(f"humanpt: {e}") from None
            per_seed.append(r)
            print(f"  {m} perception, seed {seed}: {len(r.x)} vectors of {r.which}, {r.twin_s:.1f} s of twin "
                  f"time in {r.wall_s:.1f} s", flush=True)
        # (seeds, 6) per statistic and kind, once: the median is reported, min-max kept.
        results[m] = experiment_mod.over_seeds(per_seed)
    how = "against the mean" if args.name == "static" else "against the known path"
    over_seeds = (f"; median over seeds {seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else f"; seed {seeds[0]}")
    if rsi:
        over_seeds += f"; the robot over RSI at {rsi:g} ms"
    title = (f"humanpt experiment {args.name}: the paper's Table {TABLE[args.name]} on the twin "
             f"(mm, deg; errors {how} as the paper computed them, and against ground truth{over_seeds})")
    names = {"paper": "paper's perception", "weighted": "default perception"}
    rows: list = []
    for stat in ("ME", "MAE", "MaxE", "SD"):
        if stat in PAPER[args.name]:
            rows.append(_row(f"{stat}  paper, Table {TABLE[args.name]} (published)", PAPER[args.name][stat]))
        for m in methods:
            rows.append(_row(f"{stat}  twin, {names[m]}, {how}", results[m]["paper"][stat]))
        for m in methods:
            rows.append(_row(f"{stat}  twin, {names[m]}, vs ground truth", results[m]["truth"][stat]))
        for m in methods:  # like for like with the paper: its raw state vectors, no filter
            rows.append(_row(f"{stat}  twin, {names[m]}, no filter, {how}", results[m]["paper_raw"][stat]))
        for m in methods:
            rows.append(_row(f"{stat}  twin, {names[m]}, no filter, vs ground truth", results[m]["truth_raw"][stat]))
        rows.append(())
    lines = [title, "", tables.render(["", *evaluate.COORDS], rows[:-1])]
    text = "\n".join(lines)
    print(text)
    (out / "table.txt").write_text(text + "\n")
    summary = {m: {"which": r["which"], "n": r["n"], "n_raw": r["n_raw"], "wall_s": r["wall_s"], "twin_s": r["twin_s"],
                   **{f"{kind}_{stat}": np.asarray(r[kind][stat]).tolist() for kind in KINDS
                      for stat in ("ME", "MAE", "MaxE", "SD")},
                   "spread_min_max": r["spread"]} for m, r in results.items()}
    (out / "results.json").write_text(json.dumps({"experiment": args.name, "seed": args.seed, "seeds": seeds,
                                                   "published": PAPER[args.name], "twin": summary}, indent=1))
    if "weighted" in results and not args.no_plots:
        print(f"figure: {plots(args.name, results, out)}")
    print(f"results: {out / 'table.txt'}, {out / 'results.json'}")
    return 0
