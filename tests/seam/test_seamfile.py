"""Issue 29.3 and 29.14: a seam file with absurd values, a broken structure or deep
nesting is refused by the reader (humanpt.seam.seamfile), in one line naming the file
and the field, exit 2, nothing written: for `path export`, `path retime` and `path
play`'s retiming alike.  And what export itself must refuse: a feed above its limit (the
limit retime uses), a pose outside the workspace (the robot gateway's box by default).

Each case is the attack as the issue did it (a real crafted file through the real CLI);
before the fix they gave ``$VEL.CP = 1e305...``, ``WAIT SEC inf``, ``CIRC {X nan, ...}``,
a 309-digit coordinate (exit 0), or a traceback (AttributeError, KeyError,
RecursionError, OverflowError).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import numpy as np
import pytest

from humanpt.seam import limits, seamfile
from humanpt.seam.export import (
    ExportError,
    ExportOptions,
    export,
    to_json,
    to_krl,
    to_rapid,
    to_urscript,
    to_val,
)
from humanpt.seam.fit import FitConfig, Seam, Segment
from humanpt.seam.retime import RetimeConfig, retime
from tests.conftest import run_cli_here
from tests.seam.test_export import SEAM_FILE, options


def _seam_dict() -> dict:
    return json.loads(SEAM_FILE.read_text())


def _set(d: dict, path: str, value) -> dict:
    """d with the field at ``path`` (dots; list indices as numbers) set (``...`` deletes it)."""
    d = copy.deepcopy(d)
    *head, last = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = d
    for k in head:
        node = node[k]
    if value is ...:
        del node[last]
    else:
        node[last] = value
    return d


# (what, the changed field, its value, what the one-line error must say)
CASES = [
    ("feed 1e308", "feed_mm_s", 1e308, "feed_mm_s must be a finite number in (0, 1000] mm/s"),
    ("retime feed", "retime", {"speed_mm_s": 1e308}, "retime: speed_mm_s"),
    ("negative feed", "feed_mm_s", -5, "feed_mm_s"),
    ("dwell Infinity", "dwells.0.duration_s", math.inf, "dwells[0]: duration_s must be a finite number in [0, 3600] s"),
    ("dwell NaN", "dwells.0.duration_s", math.nan, "dwells[0]: duration_s"),
    ("zero normal", "segments.1.normal", [0, 0, 0], "segments[1]: normal must not be zero"),
    ("centre at start", "segments.1.centre_mm", [100.0, 0.0, 0.0], "segments[1]: centre_mm is at start_mm"),
    ("tiny radius", "segments.1.radius_mm", 0.01, "segments[1]: radius_mm"),
    ("sweep 360", "segments.1.sweep_deg", 360.0, "segments[1]: sweep_deg"),
    ("start 1e308", "segments.0.start_mm", [1e308, 0.0, 0.0], "segments[0]: start_mm must be 3 finite numbers"),
    ("start NaN", "segments.0.start_mm", [math.nan, 0.0, 0.0], "segments[0]: start_mm"),
    ("angle 1e308", "segments.2.end_ypr_deg", [0.0, 1e308, 0.0], "segments[2]: end_ypr_deg"),
    ("bool coordinate", "segments.0.end_mm", [True, 0.0, 0.0], "segments[0]: end_mm"),
    ("segments a dict", "segments", {"a": 1}, "segments must be a list"),
    ("segments a string", "segments", "abc", "segments must be a list"),
    ("segment a number", "segments.0", 7, "segments[0]: must be an object"),
    ("first a string", "segments.0.first", "x", "segments[0]: first must be a whole number"),
    ("corner without angle", "corners.0.angle_deg", ..., "corners[0]: angle_deg is missing"),
    ("corner of no segment", "corners.0.before", 7, "corners[0]: before must be a whole number in [0, 2]"),
    ("corners a dict", "corners", {"x": 1}, "corners must be a list"),
    ("dwell without first", "dwells.0.first", ..., "dwells[0]: first"),
    ("fit a list", "fit", [1], "fit: must be an object"),
    ("fit noise a string", "fit.noise_mm", "x", "fit: noise_mm"),
    ("point X", "source.point", "X\n$OUT[1]=TRUE", "source: point must be tip or G, got 'X\\n$OUT[1]=TRUE'"),
    ("timed sample far", "retime", {"samples": [{"t_s": 0, "x": [0, 0, 0, 0, 30, 180]},
                                                {"t_s": 1, "x": [1e308, 0, 0, 0, 30, 180]}]},
     "retime.samples[1]: x"),
    ("timed sample back", "retime", {"samples": [{"t_s": 1, "x": [0, 0, 0, 0, 30, 180]},
                                                 {"t_s": 0.5, "x": [0, 0, 0, 0, 30, 180]}]},
     "retime.samples[1]: t_s 0.5 goes back"),
]


def _write(tmp_path, d: dict | str):
    f = tmp_path / "bad.seam.json"
    f.write_text(d if isinstance(d, str) else json.dumps(d))  # json writes inf / nan as Infinity / NaN
    return f


def _refused(r, says: str, tmp_path, keep=("bad.seam.json",)) -> None:
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "bad.seam.json" in r.stderr and says in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(keep)  # no program, no .tmp left behind


@pytest.mark.parametrize("what, field, value, says", CASES, ids=[c[0] for c in CASES])
def test_reader_names_the_field(tmp_path, what, field, value, says):
    f = _write(tmp_path, _set(_seam_dict(), field, value))
    with pytest.raises(seamfile.SeamFileError) as e:
        seamfile.read(f)
    assert says in str(e.value) and str(f) in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("fmt", ["krl", "val", "rapid", "urscript", "json"])
@pytest.mark.parametrize("what, field, value, says", [CASES[0], CASES[3], CASES[5], CASES[6], CASES[9]],
                         ids=["feed", "dwell", "normal", "centre", "start"])
def test_export_refuses_what_it_wrote_before(tmp_path, fmt, what, field, value, says):
    """The issue's four: $VEL.CP = 1e305, WAIT SEC inf, CIRC {X nan}, a 309-digit X."""
    f = _write(tmp_path, _set(_seam_dict(), field, value))
    r = run_cli_here("path", "export", str(f), "--format", fmt, "--dwells", "-o", str(tmp_path / "out"))
    _refused(r, says, tmp_path)


@pytest.mark.parametrize("doc, says", [
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ('{"format": "humanpt.seam", "version": 1, "segments": [{"first": ' + "9" * 5000 + "}]}", "not a seam file"),
    ('{"format": "humanpt.seam", "version": 1, "segments": "abc"}', "segments must be a list"),
], ids=["deep", "5000 digits", "string"])
@pytest.mark.parametrize("verb", ["export", "retime"])
def test_broken_structure_is_one_line(tmp_path, doc, says, verb):
    f = _write(tmp_path, doc)
    args = ["--format", "krl", "-o", str(tmp_path / "o.src")] if verb == "export" else ["-o", str(tmp_path / "o.csv")]
    _refused(run_cli_here("path", verb, str(f), *args), says, tmp_path)


def test_retime_and_play_of_a_1e308_seam(tmp_path):
    """`path retime` and `path play`'s retiming (console.seam_playback) of a seam at
    1e308 mm: the reader's one line, not retime's OverflowError."""
    f = _write(tmp_path, _set(_seam_dict(), "segments.0.start_mm", [1e308, 0.0, 0.0]))
    _refused(run_cli_here("path", "retime", str(f), "-o", str(tmp_path / "o.csv")), "segments[0]: start_mm", tmp_path)
    from humanpt.console.client import seam_playback

    with pytest.raises(seamfile.SeamFileError, match=r"segments\[0\]: start_mm"):
        seam_playback(str(f), 20.0)


def test_write_checks_before_writing(tmp_path):
    """seamfile.write refuses a seam that would not read back (here an arc with a zero
    normal) and leaves no file."""
    seam = seamfile.read(SEAM_FILE)
    bad = dataclasses.replace(seam.segments[1], normal=(0.0, 0.0, 0.0))
    seam = dataclasses.replace(seam, segments=(seam.segments[0], bad, *seam.segments[2:]))
    with pytest.raises(seamfile.SeamFileError, match=r"segments\[1\]: normal"):
        seamfile.write(tmp_path / "s.json", seam)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- export's limits

def test_limits_are_the_gateways():
    """One place: retime's defaults, export's and the robot gateway's defaults agree."""
    from humanpt.robot_gateway.links.alter.config import AlterConfig

    gw = AlterConfig()
    assert limits.MAX_SPEED_MM_S == gw.max_speed_mm_s == RetimeConfig().max_speed_mm_s == 100.0
    assert limits.MAX_ANGULAR_DEG_S == gw.max_angular_speed_deg_s == RetimeConfig().max_angular_deg_s == 60.0
    assert ExportOptions().max_speed_mm_s == limits.MAX_SPEED_MM_S
    assert ExportOptions().envelope_min_mm == tuple(gw.envelope_min_mm) == (-1600.0, -1600.0, -1400.0)
    assert ExportOptions().envelope_max_mm == tuple(gw.envelope_max_mm) == (1600.0, 1600.0, 1600.0)


def test_feed_above_the_limit_is_refused_unless_raised(tmp_path):
    """A seam feed of 150 mm/s (within what a file may hold) is above the 100 mm/s limit
    retime keeps: refused, naming the feed; with --max-speed 200 written as 0.15 m/s."""
    f = _write(tmp_path, _set(_seam_dict(), "feed_mm_s", 150.0))
    _refused(run_cli_here("path", "export", str(f), "-f", "krl", "-o", str(tmp_path / "o.src")),
             "the seam's feed 150 mm/s is above the limit 100 mm/s", tmp_path)
    r = run_cli_here("path", "export", str(f), "-f", "krl", "-o", str(tmp_path / "o.src"), "--speed", "1e308")
    _refused(r, "speed_mm_s must be a number in (0, 1000]", tmp_path)
    r = run_cli_here("path", "export", str(f), "-f", "krl", "-o", str(tmp_path / "o.src"), "--max-speed", "200")
    assert r.returncode == 0, r.stderr
    assert "$VEL.CP = 0.150000" in (tmp_path / "o.src").read_text()


def test_a_seam_outside_the_workspace_is_refused(tmp_path):
    """3000 mm off (the issue's `path play` figure): outside the gateway's box
    (x >= -1600), refused naming the segment; inside a wider --envelope it is written."""
    d = _seam_dict()
    for s in d["segments"]:
        for k in ("start_mm", "end_mm", "centre_mm"):
            if k in s:
                s[k] = [s[k][0] - 3000.0, *s[k][1:]]
    f = _write(tmp_path, d)
    _refused(run_cli_here("path", "export", str(f), "-f", "rapid", "-o", str(tmp_path / "o.mod")),
             "segments[0]: start_mm: (-3000, 0, 0) mm is outside the workspace (-1600, -1600, -1400)..(1600, "
             "1600, 1600) mm", tmp_path)
    r = run_cli_here("path", "export", str(f), "-f", "rapid", "-o", str(tmp_path / "o.mod"),
                "--envelope=-4000,-1000,-1000,1000,1000,1000")
    assert r.returncode == 0, r.stderr
    r = run_cli_here("path", "export", str(f), "-f", "rapid", "-o", str(tmp_path / "p.mod"), "--envelope", "1,2,3")
    assert r.returncode == 2 and "--envelope 1,2,3: give XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX" in r.stderr, r.stderr
    r = run_cli_here("path", "export", str(f), "-f", "rapid", "-o", str(tmp_path / "p.mod"), "--envelope", "0,0,0,0,0,0")
    assert r.returncode == 2 and "three finite lower bounds below three upper ones" in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.seam.json", "o.mod"]


def _arc_seam(end_mm=(-50.0, 0.0, 0.0)) -> Seam:
    """A half circle of r 50 about the origin in the xy plane, from (50, 0, 0) through (0,
    50, 0): its bulge at y = 50 mm (hand)."""
    seg = Segment(kind="arc", first=0, last=0, start_mm=(50.0, 0.0, 0.0), end_mm=end_mm,
                  start_ypr_deg=(0.0, 0.0, 180.0), end_ypr_deg=(0.0, 0.0, 180.0), residual_rms_mm=0.0,
                  residual_max_mm=0.0, points=10, centre_mm=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0),
                  radius_mm=50.0, sweep_deg=180.0)
    return Seam((seg,), (), (), (), 0.0, FitConfig(), 10, {"point": "tip"})


def test_an_arc_bulging_out_of_the_workspace_is_refused():
    """Both ends inside a box reaching y = 40 mm, the arc's bulge (y = 50 mm) not."""
    opts = dataclasses.replace(options(), envelope_min_mm=(-100.0, -100.0, -100.0),
                               envelope_max_mm=(100.0, 40.0, 100.0))
    with pytest.raises(ExportError, match=r"segments\[0\]: a point on the arc: \(.*\) mm is outside"):
        export(_arc_seam(), "krl", opts)
    for writer in (to_val, to_krl, to_rapid, to_urscript, to_json):  # each writer checks, not only export()
        with pytest.raises(ExportError, match="outside the workspace"):
            writer(_arc_seam(), opts)
    export(_arc_seam(), "krl", dataclasses.replace(opts, envelope_max_mm=(100.0, 51.0, 100.0)))


def test_a_circular_move_the_robot_would_take_the_long_way_is_refused():
    """The arc's end moved off its circle, behind its start (as a hand-edited file may):
    the via (on the circle) no longer lies between the ends, the robot's circle through
    start, via and target would sweep about 350 deg: refused."""
    with pytest.raises(ExportError, match=r"segments\[0\]: the circular move .* sweeps 3\d\d\.\d deg, the seam's "
                                          r"arc 180.0 deg"):
        export(_arc_seam(end_mm=(49.0, -9.0, 0.0)), "krl", options())


def test_timed_samples_faster_than_the_limit_are_refused(tmp_path):
    """JSON export of a retimed seam whose samples jump 10 mm in 4 ms (2500 mm/s)."""
    f = _write(tmp_path, _set(_seam_dict(), "retime", {
        "samples": [{"t_s": 0.0, "x": [0, 0, 0, 0, 30, 180]}, {"t_s": 0.004, "x": [10, 0, 0, 0, 30, 180]}]}))
    _refused(run_cli_here("path", "export", str(f), "-f", "json", "-o", str(tmp_path / "o.json")),
             "retime.samples[1]: 2500 mm/s from the sample before, above the limit max_speed_mm_s 100", tmp_path)


@pytest.mark.parametrize("field, value, says", [
    ("accel_mm_s2", 1e308, "accel_mm_s2"), ("zone_mm", math.inf, "zone_mm"), ("val_speed_percent", 150, "percent"),
    ("json_step_mm", 1e-300, "json_step_mm"), ("val_chord_mm", 1e-300, "val_chord_mm"),
    ("max_speed_mm_s", 1e6, "max_speed_mm_s"),
], ids=lambda v: str(v)[:12])
def test_options_out_of_bounds(field, value, says):
    with pytest.raises(ExportError, match=says):
        dataclasses.replace(options(), **{field: value})


def test_tool_out_of_bounds(tmp_path):
    r = run_cli_here("path", "export", str(SEAM_FILE), "-f", "urscript", "-o", str(tmp_path / "o.script"), "--tool",
                "1e308,0,0,0,0,0")
    assert r.returncode == 2 and "tool's offset" in r.stderr and "Warning" not in r.stderr
    assert not (tmp_path / "o.script").exists()


def test_retime_bounds():
    with pytest.raises(Exception, match="max_speed_mm_s must be at most 1000"):
        RetimeConfig(max_speed_mm_s=1e308, speed_mm_s=1e308)
    seam = seamfile.read(SEAM_FILE)
    with pytest.raises(Exception, match="at most 5000000 samples"):
        retime(seam, RetimeConfig(speed_mm_s=1e-9, max_speed_mm_s=1e-9))
    timed = retime(seam)  # the seam itself: within the limits
    assert np.all(np.isfinite(timed.x)) and max(timed.feeds_mm_s) <= 20.0 + 1e-9


def test_the_console_retimes_a_seam_for_the_cells_tool():
    """`path play` / `console playback` of a seam re-time it for the tool the config names
    (it used the controller's default tool whatever the cell's)."""
    from humanpt.console.client import playback_args
    from humanpt.controller.config import ControllerConfig
    from humanpt.controller.playback import seam_command

    long_tool = (0.0, 0.0, 600.0, 0.0, 30.0, 0.0)
    got = playback_args(str(SEAM_FILE), 60.0, flange_T_tool_x=long_tool)
    assert got == seam_command(seamfile.read(SEAM_FILE), 60.0, long_tool)
    default = playback_args(str(SEAM_FILE), 60.0)
    assert default == seam_command(seamfile.read(SEAM_FILE), 60.0, ControllerConfig().flange_T_tool_x)
