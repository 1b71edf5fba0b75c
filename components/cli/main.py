"""The ``humanpt`` command line.  ``humanpt --help`` lists the verbs; each has ``--help``."""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys

from humanpt import __version__
from humanpt.runtime.registry import COMPONENTS, PROFILES

# A verb's module (and what it imports: numpy, scipy, OpenCV, zenoh...) is imported when
# that verb runs, never to list the verbs: ``humanpt --help`` imports only the registry.

# Components that exist for the tests (the runtime's self-test pair): runnable as
# ``humanpt pinger`` and through ``python -m humanpt.runtime.run``, not listed as verbs.
TEST_ONLY_COMPONENTS = frozenset({"pinger", "ponger"})

EPILOG = """\
examples:
  humanpt demo                                    the whole system on the digital twin (live)
  humanpt demo --lockstep --scenario trapezium    the same in one process on virtual time
  humanpt up --profile selftest --duration 5     router + two components, recorded under runs/
  humanpt router --listen tcp/0.0.0.0:7447        the Zenoh router of an installation
  humanpt topics                                  what is being published now
  humanpt echo ponger/pong --count 3              print decoded messages
  humanpt replay runs/<run> --component ponger    re-run a component on its recorded inputs
  humanpt view runs/<run> --save run.rrd          a recorded run as a rerun .rrd (or spawn a viewer)
  humanpt console status --follow                 the operator console: status, options, record, save
  humanpt bench runtime                           latency and recording throughput
  humanpt bench alter                             ALTER link cycles on time, shortest cycle
  humanpt bench rsi                               RSI link (UDP): cycles on time, late replies, gateway us
  humanpt bench ur                                UR link (RTDE over TCP): cycles answered in time, 125 and 500 Hz
  humanpt bench perception                        perception images/s and accuracy
  humanpt bench render                            frames per second of the simulated camera
  humanpt bench faults                            the attacks of issue 14 against a live twin
  humanpt pki init && humanpt pki show            the cell's CA and certificates ([runtime] security = "mtls")
"""


# Verbs whose options may come anywhere among their positionals (main() re-reads them with
# that verb's parser's parse_intermixed_args).
INTERMIXED: dict[str, argparse.ArgumentParser] = {}


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", "-c", metavar="FILE", help="TOML config file (default: built-in defaults)")
    p.add_argument("--cell", help="cell name (one robot with its sensors); overrides [runtime] cell")
    p.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="router endpoint, e.g. tcp/192.168.1.10:7447 (repeatable); overrides [runtime] connect")
    p.add_argument("--as", dest="identity", metavar="NAME",
                   help="under mTLS, the certificate a tool presents (default [runtime] identity, else tool: "
                   "read-only; an operator's may command)")


def _seconds(text: str) -> float:
    """A duration argument: a finite number of seconds >= 0."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds >= 0")
    return v


def _duration(text: str) -> float:
    """A --duration argument: a finite number of seconds > 0."""
    v = _seconds(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a duration: give a number of seconds > 0")
    return v


def _first_word(argv: list[str]) -> str | None:
    """The verb of a command line: its first word that is not an option (top-level options
    take no value)."""
    return next((w for w in argv if not w.startswith("-")), None)


def build_parser(verb: str | None = None) -> argparse.ArgumentParser:
    """The whole parser; with ``verb``, that verb's in full and the others only as their line
    of the verb list (whose modules are then not imported)."""

    def full(name: str) -> bool:
        return verb is None or verb == name

    ap = argparse.ArgumentParser(
        prog="humanpt", description="humanpt: teach a welding robot its path by showing it "
        "(pseudo stereo visual servo middleware over Zenoh, recorded to MCAP).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"humanpt {__version__}")
    ap.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = ap.add_subparsers(dest="verb", metavar="VERB")

    p = sub.add_parser("demo", help="the whole system on the digital twin, with its accuracy against ground truth",
                       description="Run the whole system on the digital twin: an operator moves the target along "
                       "a scenario, the simulated PSVS camera sees it, perception, the pose filter and the visual "
                       "servo track it, the simulated Puma (behind a pty, through the ALTER gateway) follows, and the "
                       "path is recorded. Live by default (every component a process over Zenoh); --lockstep runs "
                       "the same cores in one process on virtual time. Prints where the recordings and the path "
                       "file are, and an accuracy table against ground truth.")
    if full("demo"):
        from humanpt.operator.scenario import BUILTIN_SCENARIOS

        scenarios = ", ".join(BUILTIN_SCENARIOS)
    else:
        scenarios = "a built-in scenario"
    p.add_argument("--scenario", "-s",
                   help=f"{scenarios}, or a scenario file (default arc; with --calibrate "
                   "trapezium)")
    p.add_argument("--speed", type=float, metavar="MM_S",
                   help="the operator's speed along a built-in scenario, mm/s (default: the scenario's, 20; "
                   "issue 18's hard cases are meant for 20 and 60); refused with a scenario file, which sets its "
                   "own ('speed' lines; --set operator.speed_scale=K scales its pace)")
    p.add_argument("--lockstep", action="store_true", help="one process on virtual time (fast, deterministic)")
    p.add_argument("--viewer", action="store_true", help="also run the rerun viewer component (live only)")
    p.add_argument("--duration", type=_duration, help="seconds of twin time (default: the scenario's length + 3.5 s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the camera noise and the freehand shape (default 0)")
    p.add_argument("--law", choices=["thetau", "paper"], default="thetau", help="servo law (default thetau)")
    p.add_argument("--robot", choices=["puma", "standin", "alter", "rsi", "abb", "ur"],
                   help="lock-step robot: the simulated Puma behind the ALTER link (default; with --calibrate "
                   "the stand-in) or a stand-in; "
                   "alter or rsi: the simulated Puma over that link (--robot rsi = --link rsi); abb: the "
                   "simulated ABB IRB 1600 over EGM; ur: the simulated UR5e over RTDE")
    p.add_argument("--link", choices=["alter", "rsi", "abb", "ur"], default="alter",
                   help="the robot link: the Puma's serial ALTER line at 28 ms (default), a KUKA "
                   "RSI-style UDP link (the simulated RSI controller; see components/rsi/README.md), ABB EGM "
                   "over UDP (the simulated EGM controller, 4 ms; components/robot_gateway/links/abb/README.md) "
                   "or UR RTDE over TCP (the simulated UR controller, 2 ms; components/robot_gateway/links/ur/README.md)")
    p.add_argument("--cycle-ms", type=float, choices=[2.0, 4.0, 8.0, 12.0], metavar="2|4|8|12",
                   help="with --link rsi: RSI's cycle, 4 or 12 ms (default 12); with --link abb: EGM's, 4 "
                   "(default) or 12; with --link ur: RTDE's, 2 (e-Series, default) or 8 (CB3); the gateway, "
                   "the simulated controller, the controller and the pose filter's prediction all take it")
    p.add_argument("--run-dir", help="record here (default runs/<time>-demo-<scenario>)")
    p.add_argument("--port", type=int, help="router port for the live demo (default: a free one)")
    p.add_argument("--secure", action="store_true",
                   help="live only: under mTLS ([runtime] security = \"mtls\") with a throwaway PKI in the run "
                   "directory's pki/; every process a client of the router, which enforces the access control")
    p.add_argument("--world", metavar="ideal|realistic|FILE",
                   help="the twin's truth, which the pipeline does not know: ideal (default; with --calibrate "
                   "realistic; the hardware is "
                   "exactly as the rig says), realistic (every error source of a real cell of the paper's era: "
                   "mirrors, intrinsics, hand-eye, sensor, timing, robot, tremor), ideal+SOURCE+... (only "
                   "those error sources, e.g. ideal+focal+stamp_offset), or a world file (TOML; "
                   "humanpt.twin.worlds)")
    p.add_argument("--rig", metavar="FILE",
                   help="what the pipeline believes about the hardware (a rig file, `humanpt rig init`); "
                   "default: the nominal design values")
    p.add_argument("--rig-kind", choices=("psvs", "stereo"), default="psvs",
                   help="psvs (default: one camera, four mirrors, the complex image) or stereo: an ordinary "
                   "stereo pair, the PSVS's two virtual cameras rendered apart and side by side, the "
                   "pipeline's rig the same pair (perception on pairs); with --calibrate the job on the pair "
                   "(its stereo stage in place of the camera and mirror stages)")
    p.add_argument("--calibrate", action="store_true",
                   help="the welder's whole job, lock-step: calibrate the camera, the PSVS and mirrors (with "
                   "--rig-kind stereo: the stereo pair), hand-eye, the arm and the tip against the twin (its truth "
                   "hidden), teach the seam, play the path back on the "
                   "robot; prints each calibrated value against the twin's truth, the taught path and the "
                   "played-back tool path against the seam (default scenario trapezium, world realistic)")
    p.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                   help="override a config key of operator, sim_camera, perception, pose_filter, controller, "
                   "sim_robot or standin_robot (VALUE in TOML; repeatable; over the world's), e.g. "
                   "--set sim_camera.fps=15 --set sim_camera.psvs.a_u=1003")

    p = sub.add_parser("experiment", help="the paper's Section 6 experiments on the twin, with its Tables 1-3; "
                       "the error budget",
                       description="Reproduce the paper's experiments on the digital twin in lock-step: static "
                       "(Table 1, Figure 7), arc (the rotating base, Table 2, Figure 8), trapezium (the needle "
                       "along a trapezium's edges, Table 3, Figure 9). Prints ME, MAE, MaxE, SD of x, y, z, psi, "
                       "theta, phi computed as the paper did and against ground truth, for the paper's perception "
                       "method and the default one, beside the published tables; saves a figure as PNG. budget: the error "
                       "budget of the twin's world (each error source alone, then all together).")
    p.add_argument("name", choices=["static", "arc", "trapezium", "budget", "hard", "playback"],
                   help="budget: the error budget (issue 16): --scenario once on the ideal world, once per "
                        "error source of the twin's world alone, then all together, the rig nominal; prints "
                        "each one's effect on the recorded path and saves budget.csv and budget.png. "
                        "hard: issue 18's abrupt, occluded and fast cases (scurve, abrupt, occluded, partial at "
                        "20 and 60 mm/s, or --scenario/--speeds), judged against ground truth; saves hard.txt. "
                        "playback: Figure 9b-d, --scenario (default trapezium) taught and played back on "
                        "--robot (default the simulated Puma); the torch against the seam and the taught path; "
                        "saves playback.txt and figure9bcd.png")
    p.add_argument("--method", choices=["both", "paper", "weighted"], default="both",
                   help="perception method(s) (default both, side by side)")
    p.add_argument("--seed", type=int, default=0, help="the twin's seed (noise, operator tremor)")
    p.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="run seeds SEED..SEED+N-1 and report each statistic's median over them "
                        "(one seed's figures move with any arithmetic change: the rendered noise "
                        "is drawn per pixel)")
    p.add_argument("--robot", choices=["puma", "standin"], default="puma")
    p.add_argument("--link", choices=["alter", "rsi"], default="alter",
                   help="the simulated Puma's link: ALTER at 28 ms (default, the paper's) or RSI (UDP/XML; "
                   "--cycle-ms 4|12, default 12); the controller and the filter take the link's cycle")
    p.add_argument("--cycle-ms", type=float, choices=[4.0, 12.0], metavar="4|12", help="with --link rsi: 4 or 12")
    p.add_argument("--out", help="output directory (default runs/<time>-experiment-<name>)")
    p.add_argument("--record", action="store_true", help="also record every component's MCAP")
    p.add_argument("--no-plots", action="store_true")
    p.add_argument("--vectors", type=int, default=106, help="static: vectors recorded (default 106, the paper's)")
    p.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                   help="override a setting of sim_camera, perception, pose_filter or controller "
                        "(repeatable), e.g. --set pose_filter.still_detect=false")
    p.add_argument("--speed-scale", type=float, default=1.0,
                   help="arc/trapezium: pace of the operator (default 1; the paper's speeds)")
    p.add_argument("--scenario",
                   help="budget, playback: the scenario (a built-in name or a scenario file; default arc, playback trapezium); hard: "
                        "comma-separated scenarios (default scurve,abrupt,occluded,partial)")
    p.add_argument("--speeds", metavar="V,V,...", help="hard: the operator's speeds, mm/s (default 20,60)")
    p.add_argument("--world", metavar="ideal|realistic|FILE",
                   help="hard, playback: the twin's world (default ideal, as issue 18's acceptance)")
    p.add_argument("--only", metavar="A,B,...",
                   help="budget: just these error sources (names as in humanpt.twin.worlds.ERROR_SOURCES)")
    p.add_argument("--duration", type=_duration,
                   help="budget: seconds of twin time per run (default: the scenario's, as the demo)")
    p.add_argument("--rig-kind", choices=("psvs", "stereo"), default="psvs",
                   help="budget: the camera, the PSVS (default) or an ordinary stereo pair (the world's PSVS's "
                        "virtual cameras apart, as demo --rig-kind stereo)")

    p = sub.add_parser("router", help="run the Zenoh router (a Python session in router mode)",
                       description="Run the Zenoh router that joins the machines of an installation. "
                       "Components connect to it as clients.")
    _add_common(p)
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable; default [runtime] listen)")

    p = sub.add_parser("up", help="start the router and a set of components as child processes",
                       description="Start a profile: the router (if the profile has one) and its components, "
                       "each a child process, recording to one run directory. Ctrl-C stops all cleanly; the "
                       "exit status is non-zero if a child died.",
                       epilog="profiles:\n" + "\n".join(f"  {k:10s} {v['doc']} ({', '.join(v['components'])})"
                                                      for k, v in PROFILES.items()),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(p)
    p.add_argument("--profile", "-p", default=None, help="a profile (see below) or a name under [profiles] "
                   "in the config; default: loop")
    p.add_argument("--components", help="comma-separated components instead of a profile")
    p.add_argument("--no-router", action="store_true", help="do not start a router (one runs elsewhere)")
    p.add_argument("--run-dir", help="record into this directory (default: [runtime] run_dir/<time>-<profile>)")
    p.add_argument("--duration", type=_duration, help="stop everything after this many seconds, counted from when "
                   "every component is up (its liveliness token; under mTLS watched as the tool identity)")

    old_names: dict[str, str] = {}
    if verb != "":  # a verb runs (not the verb list): the old names are verbs too (robot_gateway's)
        from humanpt.runtime.config import RENAMED_COMPONENTS

        old_names = {new: old for old, new in RENAMED_COMPONENTS.items()}
    for name in sorted(COMPONENTS):
        listed = {} if name in TEST_ONLY_COMPONENTS else {"help": f"run the {name} component alone"}
        p = sub.add_parser(name, **listed,
                           aliases=[old_names[name]] if name in old_names else [],
                           description=f"Run the {name} component alone, as a client of the router.")
        _add_common(p)
        p.add_argument("--run-dir", help="record into this directory (default: [runtime] run_dir/<time>-<name>)")
        p.add_argument("--duration", type=_duration, help="stop after this many seconds")
        p.set_defaults(component=name)

    p = sub.add_parser("topics", help="list live topics (or the topic table) and running components",
                       description="Listen for a while and print every topic seen with its type, publisher, "
                       "message count and rate, and the components whose liveliness tokens are up.")
    _add_common(p)
    p.add_argument("--duration", type=_duration, help="seconds to listen (default 2; with --hz: "
                   "until Ctrl-C unless given)")
    p.add_argument("--table", action="store_true", help="print the static topic table and exit (no network)")
    p.add_argument("--hz", action="store_true",
                   help="continuously: rate (Hz) and bandwidth (kB/s) per key over each --interval, like "
                   "ros2 topic hz/bw (a table refreshed in place on a terminal, a block per interval in a pipe)")
    p.add_argument("--interval", type=float, default=1.0, metavar="S", help="--hz: seconds per refresh (default 1)")
    p.add_argument("--json", action="store_true",
                   help="the static topic table as JSON (schemas/topics.json: keys, protobuf types, .proto "
                   "files, publishers), no network")

    p = sub.add_parser("echo", help="print decoded messages of a topic",
                       description="Subscribe to KEY and print each message decoded (like ros2 topic echo). "
                       "KEY is a short topic (perception/tob), a full key (humanpt/cell0/perception/tob) "
                       "or a wildcard (humanpt/cell0/**).")
    _add_common(p)
    p.add_argument("key")
    p.add_argument("--count", "-n", type=int, help="stop after N messages")
    p.add_argument("--duration", type=_duration, help="stop after this many seconds")
    p.add_argument("--full", action="store_true", help="print image bytes too (default: summarised)")
    p.add_argument("--field", "-f", action="append", metavar="PATH",
                   help="print only this field, one line per message with its stamp (repeatable; dotted, "
                        "lists indexed: world_T_tob.translation.x, pairs[0].residual_px, status)")
    p.add_argument("--csv", action="store_true",
                   help="with --field: CSV on stdout (stamp_ns, key, each field), e.g. > tob.csv")

    p = sub.add_parser("param", help="show, set, dump or load a running component's live parameters",
                       usage="humanpt param [options] COMPONENT [KEY=VALUE ...]\n"
                       "       humanpt param [options] dump COMPONENT [FILE]\n"
                       "       humanpt param [options] load COMPONENT FILE",
                       description="COMPONENT alone: print its live parameters and counters. With KEY=VALUE (VALUE "
                       "is JSON; a bare word is taken as a string): set them. dump: the live parameters as TOML "
                       "(a [COMPONENT] section) on stdout or into FILE. load: set every parameter of FILE (what "
                       "dump writes, or bare KEY = VALUE lines), all or none: an unknown, non-live or out-of-range "
                       "key is refused before anything is sent, and keys the component refuses roll back the "
                       "others. Options may come anywhere.",
                       epilog="examples:\n  humanpt param controller gain_translation_1_s=2 dz_mm=300 --timeout 2\n"
                       "  humanpt param dump controller controller.toml\n"
                       "  humanpt param load controller controller.toml",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(p)
    p.add_argument("component", help=argparse.SUPPRESS)
    p.add_argument("assignments", nargs="*", help=argparse.SUPPRESS)
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the component (default 5)")
    p.add_argument("--overwrite", action="store_true", help="dump: replace FILE if it exists")
    INTERMIXED["param"] = p

    p = sub.add_parser("replay", help="re-run a component on its recorded inputs and compare outputs",
                       description="Rebuild the component from its recording (core class and config), feed it "
                       "every recorded input and say whether its outputs match the recorded ones exactly, "
                       "showing the first divergence when they do not. A recording that cannot be read in full "
                       "(cut, never closed, a damaged or implausible chunk) is compared up to the damage and "
                       "is never a match (the report says how much was read). An image recorded as a reference "
                       "takes its pixels from the producer's recording in the same directory; an input whose "
                       "pixels the run did not keep ([record] images) ends the comparison there, as damage "
                       "does. Exit status: 0 match, "
                       "1 mismatch, 2 a recording cannot be read (missing, not MCAP, not humanpt, no "
                       "message readable, the producer recording its images refer to is missing), 3 nothing compared (no inputs recorded, or none left before "
                       "the damage), 4 incomplete (identical as far as read, but not read in full); with several "
                       "recordings, the worst in that order (2, 1, 4, 3).")
    p.add_argument("run", help="a run directory (with --component) or one component's .mcap file")
    p.add_argument("--component", help="component name (default: every recording in the run)")
    start = p.add_mutually_exclusive_group()
    start.add_argument("--last", type=_seconds, metavar="SECONDS",
                       help="replay only the end: start from the core's last snapshot ([record] "
                       "snapshot_period_s) at least SECONDS of input time before the last input, and compare "
                       "the outputs after it (no snapshot there: from the start, and said so)")
    start.add_argument("--from", dest="from_s", type=_seconds, metavar="SECONDS",
                       help="start from the core's last snapshot at most SECONDS of input time after its first "
                       "input (as --last)")

    from humanpt.cli import console as console_cli
    from humanpt.cli import pki as pki_cli
    from humanpt.cli import view as view_cli

    for name, add in (("view", lambda: view_cli.add_parser(sub)),
                      ("console", lambda: console_cli.add_parser(sub, _add_common)),
                      ("pki", lambda: pki_cli.add_parser(sub, _add_common))):
        if full(name):
            add()
        else:  # its line in the verb list only: the module's imports wait until it runs
            sub.add_parser(name, help={"view": view_cli, "console": console_cli, "pki": pki_cli}[name].HELP)

    p = sub.add_parser("runs", help="work with recorded runs (info, list, merge, play, rerecord)")
    rsub = p.add_subparsers(dest="runs_verb", metavar="ACTION")
    q = rsub.add_parser("merge", help="write one MCAP of every component's outputs, for viewing",
                        description="Merge the outputs of every component recording of RUN_DIR into OUT.mcap "
                        "(topics as full Zenoh keys, time order), for Foxglove or rerun; OUT an existing folder: "
                        "OUT/<run>.mcap. The run's metadata the recordings share (rig, cell, world...) goes into "
                        "the file's humanpt.merged metadata record.")
    q.add_argument("run_dir")
    q.add_argument("out")
    q = rsub.add_parser("info", help="what a run holds: components, topics, counts, rates, missed messages, "
                        "duration, size, rig, warnings",
                        description="Per component recording of RUN_DIR (or of the one .mcap given): duration, size, messages per topic in "
                        "and out with their rates, and the messages it never received (gaps in each input "
                        "topic's sequence numbers: a partition, a full queue), plus damage and restarts; then the run "
                        "as a whole: duration, size and MB per minute, the rig it ran with, the warnings and "
                        "errors its components published (by code) and the messages the shells dropped. Exit 1 "
                        "when any input was missed or a file is damaged.")
    q.add_argument("run_dir")
    q = rsub.add_parser("play", help="re-publish a recording onto the live bus at its recorded timing",
                        description="Put every component's recorded outputs on bus topics (never local ones: "
                        "serial bytes, ticks) onto the live cell (--cell or [runtime] cell) at their recorded "
                        "timing, scaled by --rate, so that humanpt echo, console status, topics and the viewer "
                        "work on an old run (like ros2 bag play). Needs a router (--connect). Prints a progress "
                        "line on stderr; Ctrl-C stops cleanly. Exit 1 when there was nothing to play.",
                        epilog="example: humanpt runs play runs/<run> --rate 2 --topics controller/status,"
                        "perception/tob --clock")
    _add_common(q)
    q.add_argument("run", help="a run directory or one component's .mcap file")
    q.add_argument("--rate", "-r", type=float, default=1.0, help="speed factor (default 1: recorded timing)")
    q.add_argument("--loop", "-l", action="store_true", help="start again at the end (until Ctrl-C)")
    q.add_argument("--topics", metavar="T,...", help="only these short topics, comma-separated "
                   "(e.g. controller/status,perception/tob; default: every bus topic recorded)")
    q.add_argument("--clock", action="store_true", help="also publish the recording's time on player/clock "
                   "(a Tick; header.stamp_ns = recorded time)")
    q.add_argument("--clock-period", type=float, default=0.1, metavar="S",
                   help="recorded seconds between clock ticks (default 0.1)")
    q = rsub.add_parser("list", help="list runs and their recordings")
    q.add_argument("dir", nargs="?", default="runs")
    q = rsub.add_parser("rerecord", help="re-record the reference runs (recordings/) live; show what changed",
                        description="Record every reference run of recordings/runs.toml live on the digital twin "
                        "(humanpt demo) into a temporary directory; check that each new recording replays exactly; "
                        "print, per run and component, what this build does to the old run's inputs (identical, within "
                        "tolerance or changed) and "
                        "how the new live run compares with the old (per topic: messages added or removed, the "
                        "largest difference per field); then replace the reference runs and the table in "
                        "recordings/README.md, unless --dry-run. Exit 1 (nothing replaced) when a run fails.")
    q.add_argument("--only", action="append", metavar="NAME", help="only this run (repeatable)")
    q.add_argument("--dry-run", action="store_true", help="record and compare, but leave recordings/ unchanged")
    q.add_argument("--dir", help="the reference runs' directory (default: recordings/ of the source tree)")
    q.add_argument("--out", help="where the new runs are recorded (default: a temporary directory)")
    q.add_argument("--fields", type=int, default=6, metavar="N",
                   help="fields shown per changed topic (default 6; -1: all)")
    q.add_argument("--timeout", type=float, default=180.0, metavar="S",
                   help="seconds a run may take beyond its twin time (default 180)")

    p = sub.add_parser("path", help="recorded paths: smooth, fit lines and arcs, retime, play, compare, export "
                       "(VAL II, KRL, RAPID, URScript, JSON)",
                       description="Work on path files written while recording (CSV in mm and degrees: "
                       "<run dir>/paths/path-<n>.csv) and on the seams fitted to them (JSON): fit -> retime | "
                       "export | play -> compare.",
                       epilog="a welder's sequence:\n"
                       "  humanpt path fit RUN/paths/path-1.csv                    # -> path-1.seam.json, .png\n"
                       "  humanpt path export RUN/paths/path-1.seam.json --format krl\n"
                       "  humanpt path play RUN/paths/path-1.seam.json --speed 20  # on the running cell\n"
                       "  humanpt path compare RUN/paths/path-1.seam.json RUN2\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    psub = p.add_subparsers(dest="path_verb", metavar="ACTION")
    q = psub.add_parser("smooth", help="Rauch-Tung-Striebel smoothing of a path file",
                        description="Smooth every coordinate of G (and of the tip) with a constant-velocity "
                        "Kalman filter forward and the RTS smoother backward; write a new path file.")
    q.add_argument("input")
    q.add_argument("output")
    q.add_argument("--accel", type=float, default=200.0, help="process noise, mm/s^2 (deg/s^2) (default 200)")
    q.add_argument("--sigma", type=float, default=0.3, help="measurement noise, mm (deg) (default 0.3)")
    q.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists (never the input)")
    q = psub.add_parser("val", help="export a path as a VAL II program for the Puma",
                        description="Write a VAL II program (.PROGRAM with SET/TRANS and MOVES) through the "
                        "path's points: the driver tip's if recorded, else G's.")
    q.add_argument("input")
    q.add_argument("output")
    q.add_argument("--name", default="path", help="program name (default path)")
    q.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists (never the input)")
    q.add_argument("--point", choices=["auto", "G", "tip"], default="auto",
                   help="which point's path (default: the tip when recorded)")
    q.add_argument("--speed", type=float, default=20.0, help="SPEED in percent (default 20)")

    q = psub.add_parser("fit", help="the path as straight lines and circular arcs: a seam file and a plot",
                        description="Split a path file into lines and arcs (corners where the direction changes, "
                        "dwells, outliers rejected; the torch orientation per segment) and write a seam file "
                        "(JSON, mm and deg) and a PNG of the path, the segments and the residuals.")
    q.add_argument("input", help="a path file (CSV)")
    q.add_argument("--output", "-o", help="the seam file (default: INPUT with .seam.json)")
    q.add_argument("--plot", help="the picture (default: the seam file's name with .png)")
    q.add_argument("--no-plot", action="store_true", help="write no picture")
    q.add_argument("--tolerance", type=float, default=0.2, metavar="MM",
                   help="RMS a segment may deviate from its line or arc beyond the path's noise (default 0.2)")
    q.add_argument("--corner-deg", type=float, default=20.0, metavar="DEG",
                   help="a direction change above this between segments is a corner (default 20)")
    q.add_argument("--point", choices=["auto", "G", "tip"], default="auto",
                   help="which point's path (default: the tip when recorded)")
    q.add_argument("--overwrite", action="store_true", help="replace the outputs if they exist (never the input)")
    q = psub.add_parser("export", help="a seam file as a robot program: VAL II, KUKA KRL, ABB RAPID, URScript, JSON",
                        description="Write a program that moves the tool along a seam (humanpt path fit): a joint "
                        "move to its start, then linear and circular moves (an arc through its midpoint), blended "
                        "at tangent junctions, stopping exactly at corners. Poses in humanpt's world frame (the "
                        "robot's base must be it); the tool is the seam's point in the TOB frame (the rig's tip). "
                        "Frame conventions per format: components/seam/README.md, 'export'.")
    q.add_argument("input", help="a seam file (JSON, humanpt path fit)")
    q.add_argument("--format", "-f", required=True, choices=["val", "krl", "rapid", "urscript", "json"],
                   help="val (VAL II), krl (KUKA), rapid (ABB), urscript (Universal Robots), json (neutral)")
    q.add_argument("--output", "-o", help="the program (default: beside the seam, its name with .v2/.mod/.script/.json; "
                   "KRL: the program's name with .src, as KRL wants)")
    q.add_argument("--speed", type=float, metavar="MM_S",
                   help="feed along the seam, mm/s (default: the seam's feed if retimed, else 20)")
    q.add_argument("--zone", "--blend", type=float, default=1.0, metavar="MM",
                   help="blend radius at tangent junctions, mm (default 1; 0 stops exactly)")
    q.add_argument("--corner-zone", type=float, default=0.0, metavar="MM",
                   help="blend radius at corners, mm (default 0: stop exactly, fine)")
    q.add_argument("--accel", type=float, default=500.0, metavar="MM_S2",
                   help="tool acceleration for URScript's a, mm/s^2 (default 500)")
    q.add_argument("--name", help="program name (default: the seam file's name; KRL: OUTPUT's)")
    q.add_argument("--point", choices=["auto", "G", "tip"], default="auto",
                   help="the tool point: the seam's (default); must match what the seam was fitted on")
    q.add_argument("--tool", metavar="X,Y,Z,PSI,THETA,PHI",
                   help="the torch's tip on the flange, mm and Z-Y-X deg (default: the controller's "
                   "flange_T_tool_x, 0,0,200,0,0,0)")
    q.add_argument("--dwells", action="store_true",
                   help="wait where the welder dwelt (the seam's dwells, at segment ends), as long as he did")
    q.add_argument("--arc", metavar="OUTPUT|SIGNAL|arcware[:SEAM,WELD]", default="",
                   help="switch the welding arc on at the seam's start and off at its end: krl $OUT[OUTPUT] "
                   "(1..4096), urscript set_standard_digital_out(OUTPUT) (0..7), rapid SetDO SIGNAL (a digital "
                   "output's name) or arcware (ArcLStart/ArcL/ArcC/ArcLEnd with the controller's seamdata and "
                   "welddata, default seam1,weld1); json records it; val refuses (default: no arc switching)")
    q.add_argument("--timed", metavar="CSV",
                   help="the seam's timing from humanpt path retime: its feed is the default --speed, and the "
                   "JSON format carries its samples (t_s and pose every cycle)")
    q.add_argument("--max-speed", type=float, metavar="MM_S",
                   help="the feed's limit, mm/s (default 100: retime's, the robot gateway's max_speed_mm_s); a "
                   "higher --speed or seam feed is refused")
    q.add_argument("--envelope", metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
                   help="the workspace every pose of the program must lie in, mm in the world frame (default "
                   "the robot gateway's box, -1600,-1600,-1400,1600,1600,1600); a seam outside is refused")
    q.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists (never the input)")

    q = psub.add_parser("retime", help="a seam in time: constant feed, bounded acceleration and jerk",
                        description="Sample a seam file (from path fit) every controller cycle at a constant feed "
                        "along each run between corners (a stop at each corner, the torch turned on the spot, a "
                        "hold at each dwell), with cycloidal speed ramps that keep acceleration and jerk bounded, "
                        "within the paper's 100 mm/s and 60 deg/s. Writes a CSV (t_s, x..phi, speed).")
    q.add_argument("seam", help="a seam file (JSON)")
    q.add_argument("--output", "-o", help="the timed CSV (default: SEAM's name with .timed.csv)")
    q.add_argument("--speed", type=float, default=20.0, metavar="MM_S", help="feed along the seam (default 20)")
    q.add_argument("--accel", type=float, default=200.0, metavar="MM_S2", help="acceleration limit (default 200)")
    q.add_argument("--jerk", type=float, default=2000.0, metavar="MM_S3", help="jerk limit (default 2000)")
    q.add_argument("--max-speed", type=float, metavar="MM_S",
                   help="speed limit (default 100: the robot gateway's max_speed_mm_s, humanpt.seam.limits)")
    q.add_argument("--max-angular", type=float, metavar="DEG_S",
                   help="the torch's angular speed limit (default 60: the gateway's max_angular_speed_deg_s)")
    q.add_argument("--cycle-ms", type=float, default=28.0, help="sample period, the controller's cycle (default 28)")
    q.add_argument("--no-dwells", action="store_true", help="do not hold at the seam's dwells")
    q.add_argument("--overwrite", action="store_true", help="replace the output if it exists (never the input)")

    q = psub.add_parser("play", help="play a seam on the robot (the running cell's controller)",
                        description="Send a seam file to the running controller as a playback: re-timed at "
                        "--speed with a stop at each corner (humanpt path retime), through the normal command "
                        "path; pause, resume and rate with `humanpt console pause|resume|rate R`. The run's "
                        "recordings keep the robot's path: `humanpt path compare SEAM RUN_DIR`.")
    q.add_argument("seam", help="a seam file (JSON, from path fit)")
    q.add_argument("--speed", type=float, default=20.0, metavar="MM_S", help="feed along the seam (default 20)")
    q.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the controller's answer")
    _add_common(q)
    q = psub.add_parser("compare", help="the tool's played path (from a run's recordings) against a seam",
                        description="Read the robot's reported path during the run's last playback (robot "
                        "states times the controller's tool) and report its distance to the seam, how much "
                        "of the seam it covered and the largest stretch it left (the seam's start and end "
                        "included).")
    q.add_argument("seam", help="a seam file (JSON)")
    q.add_argument("run", help="the run directory the playback was recorded in")
    q.add_argument("--cover-mm", type=float, default=1.0, help="coverage radius, mm (default 1)")
    q.add_argument("--gap-mm", type=float, default=10.0,
                   help="two successive states farther apart along the seam leave the stretch between them "
                        "uncovered, mm (default 10)")

    from humanpt.cli import calibrate as calibrate_cli

    if full("calibrate"):
        calibrate_cli.add_parsers(sub)
    else:
        sub.add_parser("calibrate", help=calibrate_cli.HELP)

    p = sub.add_parser("rig", help="the rig file: what the pipeline believes about the hardware",
                       description="The rig is everything perception, the pose filter, the controller and viz "
                       "believe about the hardware: camera intrinsics and distortion, the PSVS (each virtual "
                       "camera's principal point and rotation, baseline, m, l), the hand-eye transform "
                       "flange_T_camera, the target's triangle, the driver tip, the camera-to-robot time offset "
                       "and, for kind = \"stereo\", an ordinary stereo pair ([stereo]: each camera and their "
                       "pose), each with how it was obtained (method, date, 1-sigma). One versioned TOML file named by [runtime] rig; the nominal "
                       "design values when none is named. Every recording keeps the rig it ran with.")
    rsub = p.add_subparsers(dest="rig_verb", metavar="ACTION")
    q = rsub.add_parser("init", help="write the nominal rig (design values) to FILE")
    q.add_argument("file")
    q.add_argument("--overwrite", action="store_true", help="replace FILE (the old one is kept as FILE.bak)")
    q = rsub.add_parser("check", help="validate a rig file (a bad field is named) and summarise it")
    q.add_argument("file")
    q = rsub.add_parser("show", help="print a rig file, or the rig the running components use",
                        description="With FILE: print it as the tools write it. Without: ask every running "
                        "component of the cell for its rig and say whether they all run with the same one "
                        "(exit 1 when they do not, or when none answers).")
    _add_common(q)
    q.add_argument("file", nargs="?")
    q.add_argument("--timeout", type=float, default=3.0)
    q.add_argument("--json", action="store_true", help="also print every component's rig as JSON")
    q = rsub.add_parser("diff", help="the values that differ between two rig files (exit 1 if any)")
    q.add_argument("a")
    q.add_argument("b")

    p = sub.add_parser("config", help="print the effective configuration, or check a file",
                       description="Print every section with its values (defaults where the file is silent); "
                       "with --check only validate and say OK.")
    p.add_argument("--config", "-c", metavar="FILE")
    p.add_argument("--check", action="store_true")

    p = sub.add_parser("robot-files", help="write what the robot controller needs for the cell's link (KUKA RSI: "
                       "KRL program, Ethernet XML, context)",
                       description="From the config's [robot_gateway] (link rsi): the RSI Ethernet object's XML "
                       "(the elements humanpt reads and writes, HOLDON 0), a KRL program (RSI_ON relative, "
                       "RSI_MOVECORR) and the RSI context's parameters to set in RSI Visual, all in OUT. See "
                       "components/robot_gateway/links/rsi/README.md, 'Setting up the robot'.")
    p.add_argument("--config", "-c", metavar="FILE")
    p.add_argument("--out", required=True, metavar="DIR", help="folder to write the files to (made if missing)")
    p.add_argument("--sensor-ip", metavar="IPV4", help="the gateway PC's address on the RSI network (default: "
                   "udp_bind's host; required when that is 0.0.0.0 or loopback)")
    p.add_argument("--overwrite", action="store_true", help="replace files that exist")

    p = sub.add_parser("report", help="regenerate the results page (docs/results.md): rerun its experiments",
                       description="Rerun what the results page shows (the lock-step twin's experiments, demo "
                       "--calibrate on seed 0, the hard cases, the error budget: deterministic) and write each "
                       "table between its '<!-- BEGIN generated NAME -->' and '<!-- END generated NAME -->' "
                       "markers, stamped with the commit, the machine and the date; the prose around them is "
                       "kept. --benches also measures humanpt bench on this machine. Takes tens of minutes on "
                       "a 2-core machine (--only for some sections).")
    p.add_argument("--out", metavar="FILE", help="the page to rewrite in place (docs/results.md); required but "
                   "with --list")
    p.add_argument("--only", metavar="A,B", help="just these sections (--list names them)")
    p.add_argument("--benches", action="store_true", help="also the benches (measured on this machine)")
    p.add_argument("--list", action="store_true", help="list the sections and the commands they stand for")

    p = sub.add_parser("bench", help="benchmarks that print a table (not asserted)",
                       description="Without WHAT: one table of perception images/s, lock-step speed, "
                       "image-to-command latency and ALTER cycles on time in a live demo run, replay speed "
                       "and MCAP write throughput. With WHAT: that component's detailed bench.")
    p.add_argument("--live-seconds", type=float, default=60.0,
                   help="length of the live demo run (default 60: the acceptance run of issue 9)")
    p.add_argument("--lockstep-seconds", type=float, default=10.0, help="lock-step twin time (default 10)")
    p.add_argument("--scenario", default="arc", help="scenario of the live run (default arc)")
    bsub = p.add_subparsers(dest="bench_verb", metavar="WHAT")
    q = bsub.add_parser("runtime", help="round-trip latency through the router; MCAP write throughput",
                        description="Round-trip latency p50/p99 through a loopback router for a 200-byte "
                        "message and a 640x480 mono8 image, and MCAP write throughput with the default "
                        "compression beside its baseline, mcap's own Writer on the same messages (each the "
                        "best of two interleaved runs).")
    q.add_argument("--n", type=int, default=300, help="round trips per payload (default 300)")
    q.add_argument("--seconds", type=float, default=3.0,
                   help="seconds of MCAP writing per case and run (default 3)")
    q = bsub.add_parser("alter", help="ALTER link: cycles on time at 28 ms; shortest cycle without a miss",
                        description="robot_gateway <-> sim_robot over a real pty in real time, with a scripted "
                        "controller: cycles served on time (the controller's own command, applied within its "
                        "cycle) over --duration at 28 ms, then short runs at each of --periods; prints a table "
                        "and the shortest period sustained without a miss.")
    q.add_argument("--duration", type=_duration, default=60.0, help="seconds at 28 ms (default 60)")
    q.add_argument("--periods", default="28,16,8,4,2", help="cycle periods to try, ms (default 28,16,8,4,2)")
    q.add_argument("--search-seconds", type=float, default=3.0, help="seconds per period tried (default 3)")
    q.add_argument("--zenoh", action="store_true", help="sim_robot and robot_gateway as child processes through "
                   "a router, this process the controller over Zenoh (default: threads of this process)")
    q = bsub.add_parser("rsi", help="RSI link (UDP/XML): cycles on time, late-reply histogram, gateway work",
                        description="The gateway (its UDP adapter on a thread) <-> the simulated KUKA RSI-style "
                        "controller (its own clock, its own process) over UDP on loopback, with a scripted command-ahead "
                        "controller, at each of --cycles: cycles answered in time, the reply-latency histogram "
                        "as the robot sees it (late = after its next cycle boundary), and the gateway's "
                        "per-cycle work p50/p99 in microseconds.")
    q.add_argument("--duration", type=_duration, default=10.0, help="seconds per cycle time (default 10)")
    q.add_argument("--cycles", default="12,4", help="RSI cycle times to run, ms: 4 and/or 12 (default 12,4)")
    q.add_argument("--same-process", action="store_true", help="the simulated controller on a thread of this "
                   "process (sharing its GIL) instead of a process of its own")
    q = bsub.add_parser("ur", help="UR link (RTDE over TCP): cycles answered in time, answer time, gateway work",
                        description="The gateway (its RTDE client on a thread) <-> the simulated UR5e controller "
                        "(humanpt's URScript program running; its own clock, its own process) over TCP on loopback, "
                        "with a scripted command-ahead controller, at each of --cycles for --seconds: cycles "
                        "answered in time (the answer read by the robot within one cycle of its data package), "
                        "late, the answer time p50/p99 and its histogram, the gateway's per-cycle work p50/p99 "
                        "in microseconds, the program's watchdog stops.")
    q.add_argument("--seconds", type=_duration, default=60.0, help="seconds per cycle time (default 60)")
    q.add_argument("--cycles", default="8,2", help="RTDE cycle times to run, ms: 8 (CB3, 125 Hz) and/or 2 "
                   "(e-Series, 500 Hz) (default 8,2)")
    q.add_argument("--same-process", action="store_true", help="the simulated controller on a thread of this "
                   "process (sharing its GIL) instead of a process of its own")
    q = bsub.add_parser("bridge", help="what the Foxglove bridge costs the live loop's latency",
                        description="The live demo run (--scenario) without and with the Foxglove bridge, "
                        "alternated --rounds times: image-to-command latency p50 and p99 of each, and their "
                        "ratio (issue 36: the bridge must cost under 5 %). No browser is connected: the bridge "
                        "takes every bus topic either way; a browser's WebSocket traffic is not measured.")
    q.add_argument("--seconds", type=float, default=20.0, help="seconds of each live run (default 20)")
    q.add_argument("--rounds", type=int, default=2, help="runs each way, alternated (default 2)")
    q = bsub.add_parser("render", help="frames per second of the simulated PSVS camera",
                        description="Render complex images of the static target (Table 1 pose, 600 mm "
                        "ahead) at the default sim_camera settings and print frames per second, with the "
                        "time of each stage (projection, coverage and blur, sensor noise) and of the whole "
                        "core step (render + message).")
    q.add_argument("--frames", type=int, default=300, help="images per case (default 300)")
    q = bsub.add_parser("perception", help="images per second of each perception method; their accuracy",
                        description="Images per second of the weighted (default) and paper perception methods "
                        "on 640x480 twin images on one core (whole-image search, region-of-interest tracking, "
                        "the whole core step), then both methods' accuracy on twin images with ground truth "
                        "(centre RMS, 3D and pose errors against the stereo bound, wrong correspondences).")
    q.add_argument("--images", type=int, default=1000, help="timed images per case (default 1000)")
    q.add_argument("--accuracy-images", type=int, default=200, help="images per accuracy set (default 200)")
    q.add_argument("--seed", type=int, default=0, help="seed of the accuracy sets (default 0)")
    q.add_argument("--no-accuracy", action="store_true", help="timing only")
    q = bsub.add_parser("faults", help="the attack set of issue 14 against a live twin: reaction, held, recovered",
                        description="Start the whole system live (scenario --scenario, default static), wait for "
                        "the servo loop, inject each attack (param loosening, forged robot_state, NaN/1e308 "
                        "measurement, absurd command, forged STRT on the serial line, bus flood, bad console "
                        "commands, reset_fault without operator; issue 29's on the robot link: the gateway killed "
                        "mid-motion, a 1795-point seam played, and over RSI <Rob> injection, a junk flood and a "
                        "spoofed IPOC from another UDP port) with a recovery check after each, stop the "
                        "twin and print one row per attack: verdict, reaction time, robot held (largest flange "
                        "step per cycle against the gateway's limit), recovered, data lost (sequence gaps). Exit "
                        "status 1 if a verdict failed (not answered as it should, or not held), 2 if the twin "
                        "failed; whether the loop stayed up is reported, not judged.")
    q.add_argument("--only", metavar="A,B", help="attacks to run (param, forged, nan, absurd, strt, flood, "
                   "console, reset; the robot link's (issue 29): kill, bigseam, and with --link rsi inject, junk, "
                   "ipoc; with --secure also unauthorised, uncertified, token, aclflood, partition; default all)")
    q.add_argument("--link", choices=["alter", "rsi", "abb", "ur"], default="alter",
                   help="the twin's robot link: the Puma's serial ALTER line (default), RSI over UDP (12 ms), "
                   "ABB EGM over UDP (4 ms: kill and junk) or UR RTDE over TCP (a CB3's 8 ms: kill, rtde2, rtdejunk, "
                   "freeze, lost, pstop); "
                   "the rows that do not apply to it are skipped, with the reason")
    q.add_argument("--quick", action="store_true", help="issue 14's attacks but the bus flood (which takes both "
                   "cores of a small machine); with --secure also issue 19's but the floods and the partition")
    q.add_argument("--scenario", dest="faults_scenario", default="static",
                   help="scenario of the live twin (default static)")
    q.add_argument("--run-dir", help="keep the twin's recordings here (default: a temporary directory, removed)")
    q.add_argument("--secure", "--security-mtls", dest="secure", action="store_true",
                   help="run the twin under mTLS with a throwaway PKI and add the rows that need it: unauthorised "
                   "publisher, uncertified client, rogue liveliness token, flood from an identity not allowed "
                   "to publish (without it those rows are skipped, with the reason)")
    return ap


def main(argv: list[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    verb = _first_word(words)
    ap = build_parser(verb or "")
    args, extra = ap.parse_known_args(words)
    if extra and args.verb in INTERMIXED:
        # Positionals after an option (humanpt param controller --timeout 2 a=1): argparse
        # ends a subcommand's positionals at the first option; its own parser re-reads its
        # words intermixed (a parser with subcommands cannot).
        rest = words[words.index(args.verb) + 1:]
        args = INTERMIXED[args.verb].parse_intermixed_args(
            rest, namespace=argparse.Namespace(verb=args.verb, verbose=args.verbose))
        extra = []
    if extra:
        ap.error(f"unrecognized arguments: {' '.join(extra)}")

    level = logging.WARNING - 10 * min(args.verbose, 2) if args.verbose else logging.INFO
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s: %(message)s", stream=sys.stderr)
    if not args.verb:
        ap.print_help()
        return 2
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.recording import RecordingError
    from humanpt.runtime.registry import UnknownComponentError
    from humanpt.runtime.tuning import tune_process

    tune_process()
    try:
        return _dispatch(ap, args)
    except (ConfigError, RecordingError, UnknownComponentError, FileNotFoundError, FileExistsError,
            ValueError) as e:
        print(f"humanpt {args.verb}: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # (a ConnectionError: caught first)
        # The reader went away (``humanpt topics --table | head``): stop quietly, as a Unix
        # tool killed by SIGPIPE would, and keep Python from complaining at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except ConnectionError as e:  # no router where the config says: one line, not a traceback
        print(f"humanpt {args.verb}: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except ModuleNotFoundError as e:  # a verb of the full install on the server's (runtime/install.py)
        from humanpt.runtime.install import needs_full_install

        why = needs_full_install(e)
        if why is None:
            raise
        print(f"humanpt {args.verb}: {why}", file=sys.stderr)
        return 2


def _dispatch(ap: argparse.ArgumentParser, args) -> int:
    from humanpt.cli import commands
    from humanpt.runtime.config import current_name

    if getattr(args, "component", None) and current_name(args.verb) == args.component:
        return commands.run_component(args)
    if args.verb == "experiment":
        from humanpt.cli.experiment import experiment

        return experiment(args)
    if args.verb == "demo":
        from humanpt.cli.demo import demo

        return demo(args)
    if args.verb == "report":
        from humanpt.cli.report import report

        return report(args)
    fn = {
        "router": commands.router, "up": commands.up, "topics": commands.topics_cmd, "echo": commands.echo,
        "param": commands.param, "replay": commands.replay, "config": commands.config,
        "robot-files": commands.robot_files,
    }.get(args.verb)
    if fn is not None:
        return fn(args)
    if args.verb == "calibrate":
        from humanpt.cli import calibrate as calibrate_cli

        return calibrate_cli.run(args, ap)
    if args.verb == "rig":
        from humanpt.cli import rig as rig_cli

        return rig_cli.run(args)
    if args.verb == "view":
        from humanpt.cli import view as view_cli

        return view_cli.run(args)
    if args.verb == "console":
        from humanpt.cli import console as console_cli

        return console_cli.run(args)
    if args.verb == "pki":
        from humanpt.cli import pki as pki_cli

        return pki_cli.run(args, ap)
    if args.verb == "runs":
        if args.runs_verb == "merge":
            return commands.runs_merge(args)
        if args.runs_verb == "info":
            return commands.runs_info(args)
        if args.runs_verb == "list":
            return commands.runs_list(args)
        if args.runs_verb == "play":
            return commands.runs_play(args)
        if args.runs_verb == "rerecord":
            from humanpt.cli.rerecord import rerecord

            return rerecord(args)
        ap.parse_args(["runs", "--help"])
    if args.verb == "path":
        if args.path_verb in ("smooth", "val"):
            return commands.path_cmd(args)
        if args.path_verb == "fit":
            from humanpt.cli.seam import path_fit

            return path_fit(args)
        if args.path_verb in ("retime", "play", "compare"):
            from humanpt.cli import seam as seam_cli

            return getattr(seam_cli, f"path_{args.path_verb}")(args)
        if args.path_verb == "export":
            from humanpt.cli.seam_export import path_export
            return path_export(args)
        ap.parse_args(["path", "--help"])
    if args.verb == "bench":
        from humanpt.cli import bench as bench_cli

        # every sub-bench is cli/bench.py's bench_<verb> (bench_all without one)
        return getattr(bench_cli, f"bench_{args.bench_verb or 'all'}")(args)
    ap.print_help()
    return 2


if __name__ == "__main__":
    sys.exit(main())
