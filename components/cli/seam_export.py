"""``humanpt path export``: a seam file (``humanpt path fit``) as a robot program.  Parses
and writes; the programs are :mod:`humanpt.seam.export`."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from humanpt.cli.commands import check_output
from humanpt.runtime.files import write_atomic
from humanpt.seam.sanitise import shown


def _floats(text: str, n: int, option: str, what: str) -> tuple[float, ...]:
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) != n or not all(np.isfinite(v)):
        raise ValueError(f"{option} {shown(text)}: give {what}, {({6: 'six'}).get(n, n)} finite numbers")
    return v


def path_export(args) -> int:
    from humanpt.seam import limits, seamfile
    from humanpt.seam.export import SUFFIXES, ExportError, ExportOptions, export, program_name

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
    sf = seamfile.read_file(src)  # every field checked: finite, bounded, arcs with a plane
    seam = sf.seam
    seam_point = seam.meta.get("point")
    point = args.point if args.point != "auto" else (seam_point or "tip")
    if seam_point and point != seam_point:
        raise ValueError(f"{shown(src)}: the seam is of {seam_point}, not {point}; fit the path of {point} "
                         f"(humanpt path fit --point {point})")
    from humanpt.controller.config import ControllerConfig
    from humanpt.geometry.transforms import transform_from_x

    if args.tool:
        tool_x = _floats(args.tool, 6, "--tool", "X,Y,Z,PSI,THETA,PHI (mm, deg)")
    else:
        tool_x = ControllerConfig().flange_T_tool_x  # the torch humanpt's own playback uses
    tool = transform_from_x(np.asarray(tool_x, dtype=float))
    timed_csv = None
    if getattr(args, "timed", None):  # humanpt path retime's samples (the feed, and the JSON's times)
        from humanpt.seam.retime import read_csv

        timed_csv = read_csv(args.timed)
    feed = timed_csv.feeds_mm_s[0] if timed_csv is not None else sf.feed_mm_s
    speed = args.speed if args.speed is not None else (feed or 20.0)
    max_speed = args.max_speed if args.max_speed is not None else limits.MAX_SPEED_MM_S
    if args.speed is None and feed is not None and feed > max_speed:
        given = f"{shown(args.timed)}: speed_mm_s" if timed_csv is not None else f"{shown(src)}: the seam's feed"
        raise ValueError(f"{given} {feed:g} mm/s is above the limit {max_speed:g} mm/s (--max-speed)")
    box = {}
    if args.envelope:
        v = _floats(args.envelope, 6, "--envelope", "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX (mm, world frame)")
        box = dict(envelope_min_mm=v[:3], envelope_max_mm=v[3:])
    try:
        opts = ExportOptions(speed_mm_s=speed, zone_mm=args.zone, corner_zone_mm=args.corner_zone,
                             name=name, point=point,
                             flange_T_tool_mm=tuple(map(tuple, tool)), accel_mm_s2=args.accel, dwells=args.dwells,
                             arc=getattr(args, "arc", "") or "",
                             source=src.name, max_speed_mm_s=max_speed, **box)
        timed = list(zip(timed_csv.t_s, timed_csv.x, strict=True)) if timed_csv is not None else sf.samples
        text = export(seam, args.format, opts, timed=timed if args.format == "json" else None)
    except ExportError as e:
        raise ValueError(f"{shown(src)}: {e}") from None
    write_atomic(out, text)  # all or nothing, never through a planted link: a crash leaves no half program
    if args.format == "krl" and program_name(name) != out.stem:
        print(f"humanpt path export: note: KRL wants the file named as its program: "
              f"{program_name(name)}.src", file=sys.stderr)
    n = len(seam.segments)
    print(f"humanpt path export: {n} segments ({sum(s.kind == 'arc' for s in seam.segments)} arcs), "
          f"{len(seam.corners)} corners of the {point} -> {args.format} at {speed:g} mm/s: {shown(out)}")
    return 0
