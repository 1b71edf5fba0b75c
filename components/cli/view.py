"""``humanpt view RUN_DIR``: a recorded run in rerun, with the live view's blueprint."""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

DESCRIPTION = """\
Open a recorded run in rerun: every component recording's outputs, in time order,
drawn like the live view (3D world with the flange, camera frustum, target, virtual
point D, the recorded path and the twin's ground truth; the complex image with the
detected centres, pairs and expected positions; plots of tracking error, command and
loop latency; events). By default a viewer is spawned; --save writes an .rrd file
headless (open it later with `rerun FILE.rrd`); --serve keeps a gRPC server up for a
viewer on another machine (`rerun --connect rerun+http://HOST:PORT/proxy`) until Ctrl-C;
--viewer URL sends to a viewer already running there; --screenshot FILE.png saves a
picture of the run's end as the viewer draws it (needs a display, or xvfb-run and a Vulkan
driver: Debian's xvfb and mesa-vulkan-drivers). A progress line goes to stderr."""

EXAMPLES = """\
examples:
  humanpt view runs/20261121-101500-twin                  spawn a viewer
  humanpt view runs/20261121-101500-twin --save run.rrd   headless: write run.rrd
  humanpt view runs/20261121-101500-twin --serve --port 9877
  humanpt view runs/20261121-101500-twin --screenshot run.png --size 1600x900
"""


HELP = "open a recorded run in rerun (or write an .rrd headless)"


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "view",
        help=HELP,
        description=DESCRIPTION,
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "run_dir", metavar="RUN_DIR", help="a run directory (component .mcap recordings)"
    )
    out = p.add_mutually_exclusive_group()
    out.add_argument(
        "--save",
        metavar="FILE.rrd",
        help="write an .rrd file instead of spawning a viewer (headless)",
    )
    out.add_argument(
        "--serve",
        action="store_true",
        help="serve over gRPC until Ctrl-C (a viewer elsewhere connects)",
    )
    out.add_argument(
        "--screenshot",
        metavar="FILE.png",
        help="save a picture of the run's end as the viewer draws it (no window: xvfb-run and a Vulkan "
        "driver, Debian: apt install xvfb mesa-vulkan-drivers)",
    )
    out.add_argument(
        "--viewer",
        metavar="URL",
        help="send to a running viewer, e.g. rerun+http://HOST:9876/proxy",
    )
    p.add_argument(
        "--port",
        type=int,
        default=9876,
        help="gRPC port of the spawned viewer or of --serve (default 9876)",
    )
    p.add_argument("--size", default="1600x900", metavar="WxH",
                   help="the picture's size in px for --screenshot (default 1600x900)")
    p.add_argument(
        "--image-every",
        type=int,
        default=1,
        metavar="N",
        help="show every Nth camera image (default 1)",
    )
    p.add_argument("--seam", action="append", metavar="FILE.json",
                   help="also draw this seam file's segments and corners (humanpt path fit; repeatable; "
                   "default: every paths/*.seam.json of the run)")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    return p


def draw_seams(rec, files: list[Path]) -> int:
    """Draw each seam file beside the recorded path (static); how many were drawn."""
    import numpy as np

    from humanpt.seam import seamfile
    from humanpt.seam.fit import sample_segment
    from humanpt.viz.logger import log_seam

    for f in files:
        seam = seamfile.read(f)
        log_seam(rec, f.name.removesuffix(".json").replace(".", "_"), [sample_segment(s, 1.0) for s in seam.segments],
                 [s.kind for s in seam.segments], np.array([c.point_mm for c in seam.corners]).reshape(-1, 3),
                 [f"corner {c.angle_deg:.0f} deg" for c in seam.corners])
    return len(files)


def run(args) -> int:
    from humanpt.runtime.recording import RecordingError
    from humanpt.viz.config import VizConfig
    from humanpt.viz.convert import convert_run, run_files, viz_config_for_run
    from humanpt.viz.sink import close_stream, has_display, open_stream

    run_dir = Path(args.run_dir)
    run_files(run_dir)  # fail early, naming the problem
    if args.image_every < 1:
        raise ValueError("--image-every must be >= 1")
    if args.screenshot:
        from humanpt.viz.screenshot import parse_size

        size_px = parse_size(args.size)  # (a bad size stops here, before the run is drawn)
        if not args.screenshot.lower().endswith(".png"):
            raise ValueError(f"--screenshot {args.screenshot!r}: the picture is a .png file")
    if args.save or args.screenshot:
        mode = "save"
    elif args.serve:
        mode = "serve"
    elif args.viewer:
        mode = "connect"
    else:
        mode = "spawn"
        if not has_display():
            print(
                "humanpt view: no display here (DISPLAY/WAYLAND_DISPLAY unset): use --save FILE.rrd, or --serve "
                "for a viewer on another machine",
                file=sys.stderr,
            )
            return 2
    seams = [Path(f) for f in args.seam] if args.seam else sorted((run_dir / "paths").glob("*.seam.json"))
    for f in seams:
        if not f.exists():
            raise FileNotFoundError(f"{f}: no such seam file")
    base = VizConfig(grpc_port=args.port, **({"connect_url": args.viewer} if args.viewer else {}))
    cfg = viz_config_for_run(run_dir, base)
    if args.screenshot:
        import tempfile

        scratch = tempfile.TemporaryDirectory(prefix="humanpt-view-")
        rrd = str(Path(scratch.name) / "run.rrd")
    else:
        rrd = args.save or ""
    try:
        rec, where = open_stream(cfg, mode=mode, rrd_path=rrd, name=run_dir.name)
    except (RuntimeError, OSError, ValueError) as e:
        raise RecordingError(f"cannot open the rerun {mode} sink: {e}") from e
    from humanpt.runtime.progress import LineProgress

    progress = LineProgress(enabled=not args.no_progress)
    try:
        if seams:
            from humanpt.seam.seamfile import SeamFileError

            try:
                draw_seams(rec, seams)
            except SeamFileError as e:
                raise RecordingError(str(e)) from None
        stats = convert_run(
            run_dir, rec, config=cfg, image_every=args.image_every, progress=progress
        )
    finally:
        progress.end()
        if mode != "serve":
            close_stream(rec)
    for note in stats.notes:
        print(f"humanpt view: warning: {note}", file=sys.stderr)
    bad = sum(stats.errors.values())
    rate = stats.messages / stats.seconds if stats.seconds > 0 else 0.0
    if args.screenshot:
        from humanpt.viz.screenshot import ScreenshotError, screenshot

        try:
            where = f"the picture {screenshot(rrd, args.screenshot, application_id=cfg.application_id, size_px=size_px)}"
        except ScreenshotError as e:
            print(f"humanpt view: {e}", file=sys.stderr)
            return 1
        finally:
            scratch.cleanup()
    print(
        f"humanpt view: {stats.messages} messages from {stats.recordings} recordings ({stats.shown} shown"
        f"{f', {bad} not drawable' if bad else ''}) in {stats.seconds:.1f} s ({rate:.0f}/s) -> {where}",
        flush=True,
    )
    if mode == "serve":
        from humanpt.cli.commands import stop_on_signals

        stop = stop_on_signals(threading.Event())
        print("humanpt view: serving until Ctrl-C", flush=True)
        while not stop.wait(0.5):
            pass
        close_stream(rec, timeout_s=1.0)
    return 0
