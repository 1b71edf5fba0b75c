"""``humanpt path fit``: the taught path as lines and arcs (humanpt.seam), a seam file and
a picture.  Parses and prints; the work is :func:`humanpt.seam.fit.fit_path`."""

from __future__ import annotations

from pathlib import Path

from humanpt.cli.commands import check_output
from humanpt.runtime import tables


def path_fit(args) -> int:
    from humanpt.controller import pathfile
    from humanpt.seam import seamfile
    from humanpt.seam.fit import FitConfig, fit_path

    src = Path(args.input)
    out = Path(args.output) if args.output else src.with_suffix(".seam.json")
    png = Path(args.plot) if args.plot else out.with_name(out.name.removesuffix(".json") + ".png")
    for f in (out, png):
        check_output(f, src, args.overwrite)
    p = pathfile.read(src)
    which = args.point
    if which == "auto":
        which = "tip" if p.x_tip is not None else "G"
    x = p.points(which)
    cov = p.cov_tip_mm2 if which == "tip" else p.cov_g_mm2
    cfg = FitConfig(tolerance_mm=args.tolerance, corner_deg=args.corner_deg)
    seam = fit_path(x, p.stamp_ns, cov, cfg, meta={"path": str(src), "point": which, "frame": "world"})
    seamfile.write(out, seam, overwrite=args.overwrite)
    rows = []
    for i, s in enumerate(seam.segments):
        shape = (f"r {s.radius_mm:.2f} mm, {s.sweep_deg:.1f} deg" if s.kind == "arc" else "")
        rows.append([i, s.kind, f"{s.first}-{s.last}", f"{s.length_mm:.1f}", shape, f"{s.residual_rms_mm:.3f}",
                     f"{s.residual_max_mm:.3f}", len(s.outliers)])
    print(f"humanpt path fit: {len(x)} points of {which} -> {len(seam.segments)} segments, {len(seam.corners)} "
          f"corners, {len(seam.dwells)} dwells, {len(seam.outliers)} outliers; residual RMS "
          f"{seam.residual_rms_mm:.3f} mm (path noise {seam.noise_mm:.3f} mm, tolerance {cfg.tolerance_mm:g} mm)")
    print(tables.render(["#", "kind", "points", "length mm", "shape", "RMS mm", "max mm", "outliers"], rows,
                        align="rllrlrrr"))
    if seam.corners:
        print(tables.render(["corner", "x mm", "y mm", "z mm", "turn deg"],
                            [[f"{c.before}/{c.after}", *(f"{v:.2f}" for v in c.point_mm), f"{c.angle_deg:.1f}"]
                             for c in seam.corners]))
    if not args.no_plot:
        from humanpt.seam.plot import plot_seam

        plot_seam(seam, x[:, :3], png, title=f"{src.name}: {which}")
        print(f"plot: {png}")
    print(f"seam: {out}")
    if seam.doubts:  # written, each doubted segment marked (its "doubt"); exit code 3 says so
        import sys

        for line in seam.doubts:
            print(f"humanpt path fit: WARNING: {line}", file=sys.stderr)
        print(f"humanpt path fit: WARNING: {len(seam.doubts)} of {len(seam.segments)} segments doubted (marked "
              f"in {out}): record the path again (denser, steadier) or fit with a wider --tolerance",
              file=sys.stderr)
        return 3
    return 0


def path_retime(args) -> int:
    from humanpt.seam import seamfile
    from humanpt.seam.retime import RetimeConfig, peaks, retime, write_csv

    src = Path(args.seam)
    out = Path(args.output) if args.output else src.with_name(src.name.removesuffix(".json") + ".timed.csv")
    check_output(out, src, args.overwrite)
    seam = seamfile.read(src)
    limits = {k: v for k, v in (("max_speed_mm_s", args.max_speed), ("max_angular_deg_s", args.max_angular))
              if v is not None}  # else RetimeConfig's: humanpt.seam.limits
    cfg = RetimeConfig(speed_mm_s=args.speed, accel_mm_s2=args.accel, jerk_mm_s3=args.jerk, cycle_ms=args.cycle_ms,
                       dwells=not args.no_dwells, **limits)
    timed = retime(seam, cfg)
    write_csv(out, timed, overwrite=args.overwrite)
    pk = peaks(timed)
    print(f"humanpt path retime: {len(seam.segments)} segments in {len(timed.feeds_mm_s)} runs (a stop at each "
          f"corner), {len(timed.t_s)} samples every {cfg.cycle_ms:g} ms, {timed.duration_s:.2f} s")
    print(tables.render(["", "limit", "planned (samples)"], [
        ["feed mm/s", f"{cfg.speed_mm_s:g}", ", ".join(f"{v:.2f}" for v in timed.feeds_mm_s)],
        ["speed mm/s", f"{cfg.max_speed_mm_s:g}", f"{pk['speed_mm_s']:.2f}"],
        ["acceleration mm/s^2", f"{cfg.accel_mm_s2:g}", f"{pk['accel_mm_s2']:.1f}"],
        ["jerk mm/s^3", f"{cfg.jerk_mm_s3:g}", f"{pk['jerk_mm_s3']:.0f}"],
        ["angular speed deg/s", f"{cfg.max_angular_deg_s:g}", f"{pk['angular_deg_s']:.2f}"]], align="lrl"))
    print(f"timed path: {out}")
    return 0


def path_play(args) -> int:
    """The seam played by the running cell's controller, as `humanpt console playback SEAM`."""
    from humanpt.cli import console as console_cli

    if not Path(args.seam).exists():
        raise FileNotFoundError(f"{args.seam}: no such seam file")
    args.console_verb, args.file, args.point = "playback", args.seam, "auto"
    if not args.seam.endswith(".json"):
        raise ValueError(f"{args.seam}: give a seam file (.json, from humanpt path fit)")
    return console_cli.run(args)


def path_compare(args) -> int:
    """The robot's reported tool path against a seam (:mod:`humanpt.seam.compare`)."""
    from humanpt.seam import seamfile
    from humanpt.seam.compare import compare, played_tool_path

    seam = seamfile.read(args.seam)
    played = played_tool_path(args.run)
    c = compare(seam, played, cover_mm=args.cover_mm, gap_mm=args.gap_mm)
    print(f"humanpt path compare: the tool's path as the robot reported it ({c.window}; {c.n} states) "
          f"against {args.seam} ({c.length_mm:.1f} mm)")
    print(tables.render(["", "mm"], [
        ["RMS distance to the seam", f"{c.rms_mm:.3f}"], ["95th percentile", f"{c.p95_mm:.3f}"],
        ["max", f"{c.max_mm:.3f} at ({', '.join(f'{v:.1f}' for v in c.worst_mm)})"],
        [f"seam covered within {c.cover_mm:g} mm", f"{100 * c.covered:.1f} %"],
        ["largest stretch not covered", f"{c.largest_gap_mm:.1f} ({c.gap_from_mm:.1f} to {c.gap_to_mm:.1f} along "
                                        "the seam)"]]))
    return 0
