"""``humanpt calibrate camera|stereo|psvs|mirrors|hand-eye|arm|tip``: each tool has its own module
(``calibrate_<tool>.py`` with ``add_parser(subparsers)`` and ``run(args)``); this one
registers them and dispatches."""

from __future__ import annotations

import importlib

# tool name -> module of humanpt.cli
TOOLS = {
    "camera": "calibrate_camera",
    "stereo": "calibrate_stereo",
    "tip": "calibrate_tip",
    "psvs": "calibrate_psvs",
    "mirrors": "calibrate_psvs",
    "hand-eye": "calibrate_handeye",
    "arm": "calibrate_arm",
}


def add_rig_args(p) -> None:
    """``--rig FILE`` and ``--dry-run``: every tool writes its part of one rig file."""
    p.add_argument("--rig", default="rig.toml", metavar="FILE",
                   help="the rig file to update (default rig.toml; created from the nominal rig if absent; the old "
                   "one kept as .bak)")
    p.add_argument("--dry-run", action="store_true", help="estimate and report, write nothing")


def add_world_args(p) -> None:
    """``--world`` and ``--seed`` of a tool's ``--twin``: one default for every tool (the
    realistic world: what a tool is for), as ``humanpt demo --calibrate`` uses."""
    p.add_argument("--world", default="realistic", metavar="ideal|realistic|ideal+SOURCE...|FILE",
                   help="with --twin: the twin's world (default realistic; humanpt demo --help)")
    p.add_argument("--seed", type=int, default=0, help="with --twin: the twin's seed (poses, noise; default 0)")


HELP = "calibrate the cell: camera, stereo, psvs, mirrors, hand-eye, arm, tip"


def add_parsers(sub) -> None:
    p = sub.add_parser("calibrate", help=HELP,
                       description="Calibrate the cell as the paper's HumanPT does: the camera (Zhang's method; "
                       "OpenCV's corner detector or the paper's appendix one), the PSVS and its mirrors' "
                       "alignment, hand-eye (AX = YB), the arm's kinematics and the driver tip. Each tool observes a live cell, "
                       "a folder of images or the digital twin (whose truth it never reads) and writes the rig "
                       "(humanpt rig --help).")
    csub = p.add_subparsers(dest="calibrate_verb", metavar="TOOL")
    for module in dict.fromkeys(TOOLS.values()):  # a module may add several tools
        importlib.import_module(f"humanpt.cli.{module}").add_parser(csub)


def run(args, ap) -> int:
    module = TOOLS.get(getattr(args, "calibrate_verb", None) or "")
    if module is None:
        ap.parse_args(["calibrate", "--help"])
        return 2
    return importlib.import_module(f"humanpt.cli.{module}").run(args)
