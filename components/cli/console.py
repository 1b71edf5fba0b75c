"""``humanpt console``: the operator console's command line (the paper's GUI, Fig. 5, as
CLI verbs).  It parses and prints; the client is :mod:`humanpt.console.client`.  Without a
verb it reads verbs from stdin, one per line (an interactive prompt on a terminal).
"""

from __future__ import annotations

import argparse
import shlex
import sys

DESCRIPTION = """\
The operator console: the options of the paper's GUI (Fig. 5) and its buttons, from either
machine. Options (set NAME=VALUE) go to the live parameters of the components that own
them; commands go to the controller on console/command and wait for its answer.
Without a verb: read verbs from stdin, one per line ('help' lists them, 'quit' ends)."""


# -- argument parsing ------------------------------------------------------------------------------------
def _common_after_action(q: argparse.ArgumentParser) -> None:
    """--config/--cell/--connect/--timeout after the action too (``console set X=1 --connect ...``);
    SUPPRESS keeps a value given before the action."""
    q.add_argument(
        "--config", "-c", metavar="FILE", default=argparse.SUPPRESS, help="TOML config file"
    )
    q.add_argument("--cell", default=argparse.SUPPRESS, help="cell name; overrides [runtime] cell")
    q.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        default=argparse.SUPPRESS,
        help="router endpoint (repeatable); overrides [runtime] connect",
    )
    q.add_argument(
        "--timeout", type=float, default=argparse.SUPPRESS, help="seconds to wait for an answer"
    )


def _add_actions(asub) -> dict[str, str]:
    """Add the console's actions to the sub-parsers ``asub``; {action: its one-line help}."""
    from humanpt.console.client import OPTIONS

    helps: dict[str, str] = {}

    def action(verb: str, **kw) -> argparse.ArgumentParser:
        helps[verb] = kw["help"]
        return asub.add_parser(verb, **kw)

    q = action(
        "status",
        help="mode, visible sources, error, cycle misses, recording",
        description="Print the live status once (or a line every --interval with --follow): "
        "controller mode, visible sources, |G-D| error (mm, deg), missed ALTER cycles, recording "
        "and path points, from controller/status, robot_gateway/robot_state and perception/tob; with "
        "--follow also each warning or error event of a component or the router as it comes.",
    )
    q.add_argument(
        "--follow", "-f", action="store_true", help="a line every --interval until Ctrl-C"
    )
    q.add_argument(
        "--interval",
        type=float,
        default=0.5,
        help="seconds between lines with --follow (default 0.5)",
    )
    q.add_argument("--duration", type=float, help="stop following after this many seconds")
    q = action(
        "events",
        help="follow the components' and the router's warnings and errors (access_denied...)",
        description="Print each event of every component and of the router (humanpt/<cell>/*/events) "
        "as it arrives, warnings and errors by default: under mTLS the router reports what its access "
        "control refused as access_denied warnings on router/events (the 1st, 10th, 100th... per "
        "identity, message and key). status --follow prints the same between its lines.",
    )
    q.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    q.add_argument("--all", action="store_true", help="info events too")
    q = action(
        "show",
        help="the GUI options' current values",
        description="Ask perception and the controller for the current values of the GUI's options.",
    )
    q = action(
        "set",
        help="set GUI options: threshold, invert, mask, delay, dz, stop-on-current-location, ...",
        description="Set the paper's GUI options on the running components (their live "
        "parameters; each change is recorded in the component's MCAP):\n"
        + "\n".join(f"  {k:26s} {c}.{p}: {h}" for k, (c, p, h) in OPTIONS.items())
        + "\nCOMPONENT.KEY=VALUE sets any other live parameter (VALUE is JSON).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    q.add_argument("assignments", nargs="+", metavar="NAME=VALUE")
    q = action(
        "record",
        help="start or stop recording the path",
        description="Start recording the path (a new path file under the controller's run "
        "directory, a point every `delay` cycles) or stop it.",
    )
    q.add_argument("action", choices=["start", "stop"])
    q = action(
        "save",
        help="save the recorded path under a name in the run's paths/ directory",
        description="Copy the current path file (CSV, mm and degrees) to NAME in the run's "
        "paths/ directory, on the controller's machine (NAME is a plain file name: letters, "
        "digits, '.', '_', '-'; '.csv' is added when it has no suffix). An existing file is "
        "replaced only with --overwrite.",
    )
    q.add_argument("file", metavar="NAME")
    q.add_argument("--overwrite", action="store_true", help="replace an existing file of that name")
    action(
        "reset-fault",
        help="clear the robot gateway's latched fault (the operator's decision, logged by name)",
        description="Clear the gateway's latched fault (missed cycles, a lost controller...): "
        "corrections flow again once the controller commands. The gateway logs who asked "
        "(user@host of this console).",
    )
    q = action(
        "alter",
        help="switch the simulated robot's ALTER mode on or off (logged by name)",
        description="ALTER on or off at the twin's robot controller (sim_robot); on a real Puma "
        "this is done at the robot's terminal. Logged with who asked.",
    )
    q.add_argument("state", choices=["on", "off"])
    q = action(
        "calibrate",
        help="calibrate the driver tip (N samples pivoting on it)",
        description="Start the driver-tip calibration (paper §4.1): track while collecting N "
        "distinct poses of the target pivoting on its tip. With --pivot (the point P' in world "
        "mm, eq. 10-11) the paper's eq. 12-13 are solved as well.",
    )
    q.add_argument("--samples", type=int, help="N (default: the controller's calib-samples option)")
    q.add_argument("--pivot", metavar="X,Y,Z", help="P' in the world frame, mm")
    q = action(
        "capture",
        help="camera calibration: capture the next frame (humanpt calibrate camera --live)",
        description="Tell a running `humanpt calibrate camera --live` to capture the camera's next "
        "frame as a calibration view (as Enter at its terminal does); --finish ends the capture "
        "and calibrates (as q does).",
    )
    q.add_argument("--finish", action="store_true", help="end the capture and calibrate")
    q = action(
        "playback",
        help="replay the recorded path (or a path file, or a seam) with the tool",
        description="The tool tip follows the path just recorded, or the path in FILE (a path "
        "CSV written while recording, mm and degrees), or the seam in FILE (a .json seam file "
        "from `humanpt path fit`: re-timed at --speed with a stop at each corner, see "
        "`humanpt path retime`). pause, resume and rate act on a running playback.",
    )
    q.add_argument("file", nargs="?", metavar="FILE.csv|SEAM.json")
    q.add_argument("--speed", type=float, help="tool speed (a seam's feed), mm/s (default: the controller's; "
                   "a seam's 20)")
    q.add_argument(
        "--point",
        choices=["auto", "G", "tip"],
        default="auto",
        help="which point of FILE (default: the tip when recorded)",
    )
    action("pause", help="pause a running playback (the tool stands on the path)",
           description="Controller command: pause the playback; resume goes on from there.")
    action("resume", help="resume a paused playback", description="Controller command: resume the playback.")
    q = action("rate", help="play back faster or slower (0.05-2 x the playback's speed)",
               description="Controller command: scale the running playback's speed (its timing, for a seam).")
    q.add_argument("rate", type=float, help="factor, 0.05 to 2 (1: as planned)")
    for verb, text in (
        ("hold", "stop on the current location"),
        ("track", "track the target (visual servo)"),
        ("return", "return to the start pose"),
    ):
        action(verb, help=text, description=f"Controller command: {text}.")
    for q in asub.choices.values():
        _common_after_action(q)
    return helps


HELP = "operator console: GUI options, record/save/calibrate/playback, live status"


def add_parser(sub, add_common) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "console",
        help=HELP,
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  humanpt console status --follow\n"
        "  humanpt console set threshold=70 invert=false delay=10 dz=600 stop-on-current-location=true\n"
        "  humanpt console record start\n  humanpt console save weld-1\n"
        "  humanpt console --connect tcp/192.168.1.10:7447      (from the other machine)",
    )
    add_common(p)
    p.add_argument(
        "--timeout", type=float, default=5.0, help="seconds to wait for an answer (default 5)"
    )
    _add_actions(p.add_subparsers(dest="console_verb", metavar="ACTION"))
    return p


def _do(con, a) -> int:
    """Console ``con``'s call for parsed action ``a``."""
    from humanpt.console.client import ConsoleError, check_envelope, operator_name
    from humanpt.schemas import humanpt_pb2 as pb

    v = a.console_verb
    if v == "status":
        return con.status(follow=a.follow, interval_s=a.interval, duration_s=a.duration)
    if v == "events":
        return con.events(a.duration, pb.SEVERITY_INFO if a.all else pb.SEVERITY_WARNING)
    if v == "show":
        return con.show()
    if v == "set":
        return con.set(a.assignments)
    if v == "record":
        return con.command("record_start" if a.action == "start" else "record_stop")
    if v == "save":
        return con.command("save", {"file": a.file, "overwrite": a.overwrite})
    if v == "calibrate":
        args: dict = {}
        if a.samples is not None:
            args["samples"] = a.samples
        if a.pivot:
            try:
                args["pivot_mm"] = [float(x) for x in a.pivot.split(",")]
            except ValueError:
                raise ConsoleError(f"--pivot {a.pivot!r}: give X,Y,Z in mm") from None
            if len(args["pivot_mm"]) != 3:
                raise ConsoleError(f"--pivot {a.pivot!r}: give X,Y,Z in mm")
        return con.command("calibrate", args)
    if v == "playback":
        args = getattr(a, "playback_args", None)
        if args is None:
            args = _playback_args(a, con.cfg)
        check_envelope(con, args, a.file or "playback")
        return con.command("playback", args)
    if v in ("pause", "resume"):
        return con.command(f"playback_{v}")
    if v == "rate":
        return con.command("playback_rate", {"rate": a.rate})
    if v == "capture":
        return con.tell("finish" if a.finish else "capture", component="calibrate")
    if v == "reset-fault":
        return con.command("reset_fault", {"operator": operator_name()}, component="robot_gateway")
    if v == "alter":
        return con.command(f"alter_{a.state}", {"operator": operator_name()}, component="sim_robot")
    if v in ("hold", "track", "return"):
        return con.command(v)
    raise ConsoleError(f"unknown action {v!r}")


def _playback_args(a, cfg=None) -> dict:
    """The playback's arguments; a seam re-timed for the cell's tool (``[controller]
    flange_T_tool_x`` of the config, the controller's default without one)."""
    from humanpt.console.client import playback_args
    from humanpt.controller.config import ControllerConfig

    tool = None if cfg is None else cfg.component("controller", ControllerConfig).flange_T_tool_x
    return playback_args(a.file, a.speed, getattr(a, "point", "auto"), flange_T_tool_x=tool)


def _interactive(con, stream=None) -> int:
    from humanpt.console.client import ConsoleError

    stream = sys.stdin if stream is None else stream  # (the stdin of the call, not of the import)
    ap = argparse.ArgumentParser(prog="", add_help=False, exit_on_error=False)
    asub = ap.add_subparsers(dest="console_verb", metavar="ACTION")
    helps = _add_actions(asub)
    verbs = "verbs ('VERB --help' for its options; 'quit' ends):\n" + "\n".join(
        f"  {v:10s} {h}" for v, h in helps.items()
    )
    tty = stream.isatty()
    if tty:
        con.say(
            f"humanpt console, cell {con.cell}: {', '.join(con.alive()) or 'no components'} up. "
            "'help' lists the verbs, 'quit' ends."
        )
    rc = 0
    while True:
        if tty:
            print("humanpt> ", end="", flush=True, file=con.out)
        line = stream.readline()
        if not line:
            return rc
        words = shlex.split(line, comments=True)
        if not words:
            continue
        if words[0] in ("quit", "exit"):
            return rc
        if words[0] in ("help", "?"):
            con.say(verbs)
            continue
        try:
            a = ap.parse_args(words)
            rc = _do(con, a) or rc
        except SystemExit as e:  # argparse printed a verb's help, or why an argument is bad
            rc = rc if e.code == 0 else 1
        except (argparse.ArgumentError, ConsoleError, ValueError, OSError) as e:
            con.say(f"error: {e}")
            rc = 1


def run(args) -> int:
    from humanpt.cli.commands import load_cfg
    from humanpt.console.client import Console, ConsoleError

    cfg = load_cfg(args)
    prog = "path play" if getattr(args, "verb", None) == "path" else "console"
    try:
        if args.console_verb == "playback":  # the heavy part and its refusals before connecting
            args.playback_args = _playback_args(args, cfg)
        con = Console(cfg, timeout_s=args.timeout)
    except ConsoleError as e:
        print(f"humanpt {prog}: {e}", file=sys.stderr)
        return 1
    try:
        if not args.console_verb:
            return _interactive(con)
        return _do(con, args)
    except ConsoleError as e:
        print(f"humanpt {prog}: {e}", file=sys.stderr)
        return 1
    finally:
        con.close()
