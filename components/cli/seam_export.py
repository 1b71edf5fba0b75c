"""``humanpt path export``: a seam file (``humanpt path fit``) as a robot program.  Parses
and writes; the programs are :mod:`humanpt.seam.export`."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from humanpt.cli.commands import check_output
from humanpt.runtime.files import write_atomic


def _feed_mm_s(raw: dict) -> float | None:
    """The seam's own feed (mm/s) if it has one: ``retime.speed_mm_s`` or ``feed_mm_s``."""
    for v in ((raw.get("retime") or {}).get("speed_mm_s") if isinstance(raw.get("retime"), dict) else None,
              raw.get("feed_mm_s")):
        if isinstance(v, (int, float)) and math.isfinite(v) and v > 0:
            return float(v)
    return None


def _timed(raw: dict) -> list[tuple[float, np.ndarray]] | None:
    """A retimed seam's samples: ``retime.samples`` = [{"t_s": .., "x": [x, y, z, psi,
    theta, phi]}, ...] (mm, deg), else None."""
    rt = raw.get("retime")
    if not isinstance(rt, dict) or not isinstance(rt.get("samples"), list):
        return None
    out = []
    for i, s in enumerate(rt["samples"]):
        try:
            x = np.asarray(s["x"], dtype=float)
            t = float(s["t_s"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"retime.samples[{i}]: needs t_s and x (6 numbers)") from None
        if x.shape != (6,) or not np.all(np.isfinite(x)) or not math.isfinite(t):
            raise ValueError(f"retime.samples[{i}]: needs t_s and x (6 finite numbers)")
        out.append((t, x))
    return out


def path_export(args) -> int:
    from humanpt.seam import seamfile
    from humanpt.seam.export import SUFFIXES, ExportOptions, export, program_name

    src = Path(args.input)
    stem = src.name.removesuffix(".json").removesuffix(".seam")
    # KRL: the .src file is named as its DEF (KRL names have no '-'), so the default file
    # is the program's name, and the default name the file's.
    if args.output:
        out = Path(args.output)
    else:
        out = src.with_name((program_name(args.name or stem) if args.format == "krl" else stem)
                            + SUFFIXES[args.format])
    name = args.name or (out.stem if args.format == "krl" else stem)
    check_output(out, src, args.overwrite)
    seam = seamfile.read(src)
    raw = json.loads(src.read_text())
    seam_point = seam.meta.get("point")
    point = args.point if args.point != "auto" else (seam_point or "tip")
    if seam_point and point != seam_point:
        raise ValueError(f"{src}: the seam is of {seam_point}, not {point}; fit the path of {point} "
                         f"(humanpt path fit --point {point})")
    from humanpt.controller.config import ControllerConfig
    from humanpt.geometry.transforms import transform_from_x

    if args.tool:
        try:
            tool_x = [float(v) for v in args.tool.split(",")]
        except ValueError:
            tool_x = []
        if len(tool_x) != 6 or not all(np.isfinite(tool_x)):
            raise ValueError(f"--tool {args.tool!r}: give X,Y,Z,PSI,THETA,PHI (mm, deg), six finite numbers")
    else:
        tool_x = ControllerConfig().flange_T_tool_x  # the torch humanpt's own playback uses
    tool = transform_from_x(np.asarray(tool_x, dtype=float))
    timed_csv = None
    if getattr(args, "timed", None):  # humanpt path retime's samples (the feed, and the JSON's times)
        from humanpt.seam.retime import read_csv

        timed_csv = read_csv(args.timed)
    feed = timed_csv.feeds_mm_s[0] if timed_csv is not None else _feed_mm_s(raw)
    speed = args.speed if args.speed is not None else (feed or 20.0)
    opts = ExportOptions(speed_mm_s=speed, zone_mm=args.zone, corner_zone_mm=args.corner_zone,
                         name=name, point=point,
                         flange_T_tool_mm=tuple(map(tuple, tool)), accel_mm_s2=args.accel, dwells=args.dwells,
                         source=src.name)
    timed = list(zip(timed_csv.t_s, timed_csv.x, strict=True)) if timed_csv is not None else _timed(raw)
    text = export(seam, args.format, opts, timed=timed if args.format == "json" else None)
    write_atomic(out, text)  # all or nothing, never through a planted link: a crash leaves no half program
    if args.format == "krl" and program_name(name) != out.stem:
        print(f"humanpt path export: note: KRL wants the file named as its program: "
              f"{program_name(name)}.src", file=sys.stderr)
    n = len(seam.segments)
    print(f"humanpt path export: {n} segments ({sum(s.kind == 'arc' for s in seam.segments)} arcs), "
          f"{len(seam.corners)} corners of the {point} -> {args.format} at {speed:g} mm/s: {out}")
    return 0
