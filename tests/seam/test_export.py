"""``humanpt path export``: each format's text against a committed golden file, and each
program's poses parsed back (a regex per format, the format's own angle convention
inverted with scipy) against the seam file's numbers within 0.01 mm / 0.01 deg.

The seam is hand-made (``data/export-seam.json``): a line, a tangent arc (r 50 mm, 90
deg), a line on from it, a 90 deg corner (with a 0.8 s dwell) and a last line, the torch
tilted and turning.
Regenerate the goldens (after a deliberate change of a format, and read the diff):
``python -m tests.seam.test_export --regenerate``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from humanpt.seam import seamfile
from humanpt.seam.export import FORMATS, SUFFIXES, ExportOptions, export
from humanpt.seam.fit import Corner, Dwell, FitConfig, Seam, Segment
from tests.conftest import run_cli_here

DATA = Path(__file__).parent / "data"
SEAM_FILE = DATA / "export-seam.json"
TORCH_MM = (0.0, 0.0, 200.0)  # the controller's default flange_T_tool_x: the torch 200 mm along the flange's z
TOL_MM, TOL_DEG = 0.01, 0.01


def hand_made_seam() -> Seam:
    """The seam of the module doc, its numbers chosen by hand (mm, deg)."""
    def seg(kind, a, b, ya, yb, **arc):
        return Segment(kind=kind, first=0, last=0, start_mm=a, end_mm=b, start_ypr_deg=ya, end_ypr_deg=yb,
                       residual_rms_mm=0.0, residual_max_mm=0.0, points=10, **arc)

    segs = (
        seg("line", (0.0, 0.0, 0.0), (100.0, 0.0, 0.0), (0.0, 30.0, 180.0), (10.0, 30.0, 175.0)),
        # centre (100, 50, 0), normal +z: from (100, 0, 0) a quarter turn to (150, 50, 0)
        seg("arc", (100.0, 0.0, 0.0), (150.0, 50.0, 0.0), (10.0, 30.0, 175.0), (95.0, 25.0, 170.0),
            centre_mm=(100.0, 50.0, 0.0), normal=(0.0, 0.0, 1.0), radius_mm=50.0, sweep_deg=90.0),
        seg("line", (150.0, 50.0, 0.0), (150.0, 120.0, 10.0), (95.0, 25.0, 170.0), (100.0, 20.0, -175.0)),
        seg("line", (150.0, 120.0, 10.0), (60.0, 120.0, 10.0), (-170.0, 20.0, -175.0), (-175.0, 35.0, 178.0)),
    )
    corner = Corner((150.0, 120.0, 10.0), 90.0, 2, 3)
    dwell = Dwell((150.2, 120.1, 10.0), 0, 0, 0.8)  # the hand hesitating at the corner
    return Seam(segments=segs, corners=(corner,), dwells=(dwell,), outliers=(), noise_mm=0.0, config=FitConfig(),
                points=40, meta={"path": "hand-made", "point": "tip", "frame": "world"})


def options() -> ExportOptions:
    T = np.eye(4)
    T[:3, 3] = TORCH_MM
    return ExportOptions(speed_mm_s=20.0, zone_mm=1.0, name="seam", point="tip", json_step_mm=5.0,
                         flange_T_tool_mm=tuple(map(tuple, T)), source="export-seam.json")


def golden(fmt: str) -> Path:
    return DATA / f"export-seam{SUFFIXES[fmt]}".replace(".json", ".program.json")


def regenerate() -> None:
    DATA.mkdir(exist_ok=True)
    seamfile.write(SEAM_FILE, hand_made_seam(), overwrite=True)
    seam = seamfile.read(SEAM_FILE)
    for fmt in FORMATS:
        golden(fmt).write_text(export(seam, fmt, options()))
        print(golden(fmt))


# ---------------------------------------------------------------------------- the seam's own numbers

def seam_numbers() -> dict:
    """From the seam FILE (not the exporter): the targets each program must reach, in
    order: (position mm, rotation) of the start, every segment's end, and each arc's
    midpoint (on the circle, half the sweep on from the start's direction; the torch half way on the geodesic between its end orientations, scipy's Slerp)."""
    d = json.loads(SEAM_FILE.read_text())
    segs = d["segments"]
    def rot(ypr):
        return Rotation.from_euler("ZYX", ypr, degrees=True)

    ends = [(np.array(segs[0]["start_mm"]), rot(segs[0]["start_ypr_deg"]))]
    vias = []
    for s in segs:
        r0, r1 = rot(s["start_ypr_deg"]), rot(s["end_ypr_deg"])
        if s["kind"] == "arc":
            # on the circle, half the sweep on from the start's direction (right-handed about the normal)
            n, c = np.array(s["normal"]), np.array(s["centre_mm"])
            u = np.array(s["start_mm"]) - c
            u = u - (u @ n) * n
            half = Rotation.from_rotvec(n * math.radians(s["sweep_deg"] / 2))
            via_p = c + half.apply(u / np.linalg.norm(u) * s["radius_mm"])
            vias.append((via_p, Slerp([0, 1], Rotation.concatenate([r0, r1]))(0.5)))
        ends.append((np.array(s["end_mm"]), r1))
    return {"ends": ends, "vias": vias, "kinds": [s["kind"] for s in segs], "corners": d["corners"]}


# ---------------------------------------------------------------------------- parsers, one per format

NUM = r"(-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?)"


def _floats(s: str) -> list[float]:
    return [float(v) for v in re.findall(NUM, s)]


def parse_krl(text: str) -> list[tuple[str, list]]:
    """[(PTP|LIN|CIRC, [(p mm, Rotation), ...])]: {X, Y, Z, A, B, C}, A B C about Z Y X."""
    out = []
    frame = r"\{X ([^,]+), Y ([^,]+), Z ([^,]+), A ([^,]+), B ([^,]+), C ([^}]+)\}"
    for m in re.finditer(r"^(PTP|LIN|CIRC) (.*)$", text, re.M):
        poses = [(np.array(v[:3], dtype=float), Rotation.from_euler("ZYX", np.array(v[3:], dtype=float),
                                                                      degrees=True))
                 for v in re.findall(frame, m.group(2))]
        out.append((m.group(1), poses))
    return out


def parse_rapid(text: str) -> list[tuple[str, list]]:
    """[(MoveJ|MoveL|MoveC, [(p mm, Rotation), ...])]: robtarget quaternions [w, x, y, z]."""
    targets = {}
    for m in re.finditer(r"CONST robtarget (\w+) := \[\[([^\]]+)\],\[([^\]]+)\]", text):
        w, x, y, z = _floats(m.group(3))
        targets[m.group(1)] = (np.array(_floats(m.group(2))), Rotation.from_quat([x, y, z, w]))
    out = []
    for m in re.finditer(r"^\s*(MoveJ|MoveL|MoveC) ([^;]+);", text, re.M):
        names = [n.strip() for n in m.group(2).split(",")][:2 if m.group(1) == "MoveC" else 1]
        out.append((m.group(1), [targets[n] for n in names]))
    return out


def parse_urscript(text: str) -> list[tuple[str, list]]:
    """[(movej|movel|movec, [(p mm, Rotation), ...])]: p[x, y, z (m), rx, ry, rz (rad)]."""
    out = []
    for m in re.finditer(r"^\s*(movej|movel|movec)\((.*)\)$", text, re.M):
        poses = []
        for p in re.findall(r"p\[([^\]]+)\]", m.group(2)):
            v = _floats(p)
            poses.append((np.array(v[:3]) * 1000.0, Rotation.from_rotvec(v[3:])))
        out.append((m.group(1), poses))
    return out


def parse_val(text: str) -> list[tuple[str, list]]:
    """[(MOVE|MOVES, [(p mm, Rotation)])]: TRANS(x, y, z, o, a, t), O A T Euler Z-Y-Z."""
    pts = {m.group(1): _floats(m.group(2)) for m in re.finditer(r"SET (\w+) = TRANS\(([^)]*)\)", text)}
    return [(m.group(1), [(np.array(pts[m.group(2)][:3]),
                           Rotation.from_euler("ZYZ", pts[m.group(2)][3:], degrees=True))])
            for m in re.finditer(r"^\s*(MOVES?) (\w+)$", text, re.M)]


def parse_json(text: str) -> list[tuple[str, list]]:
    d = json.loads(text)
    out = []
    for m in d["moves"]:
        poses = [m["via"]] if "via" in m else []
        poses.append(m["target"])
        out.append((m["kind"], [(np.array(p["x_mm"]), Rotation.from_euler("ZYX", p["ypr_deg"], degrees=True))
                                for p in poses]))
    return out


PARSERS = {"krl": parse_krl, "rapid": parse_rapid, "urscript": parse_urscript, "val": parse_val,
           "json": parse_json}


def assert_pose(got, want, what: str) -> None:
    dp = float(np.linalg.norm(got[0] - want[0]))
    da = math.degrees((got[1].inv() * want[1]).magnitude())
    assert dp < TOL_MM and da < TOL_DEG, f"{what}: {dp:.4f} mm, {da:.4f} deg off the seam"


# ---------------------------------------------------------------------------- tests

@pytest.fixture(scope="module")
def seam() -> Seam:
    return seamfile.read(SEAM_FILE)


@pytest.mark.parametrize("fmt", FORMATS)
def test_golden_text(seam, fmt):
    assert export(seam, fmt, options()) == golden(fmt).read_text()


@pytest.mark.parametrize("fmt", ["krl", "rapid", "urscript", "json"])
def test_round_trip_moves(seam, fmt):
    """The program's moves: the approach to the start, then per segment a linear move to
    its end, or a circular one through the arc's midpoint to its end."""
    want = seam_numbers()
    moves = PARSERS[fmt](export(seam, fmt, options()))
    assert len(moves) == 1 + len(want["kinds"])
    assert_pose(moves[0][1][0], want["ends"][0], f"{fmt} start")
    vias = iter(want["vias"])
    for i, (kind, (verb, poses)) in enumerate(zip(want["kinds"], moves[1:], strict=True)):
        circ = {"krl": "CIRC", "rapid": "MoveC", "urscript": "movec", "json": "arc"}[fmt]
        assert (verb == circ) == (kind == "arc"), f"{fmt} segment {i}: {verb} for a {kind}"
        if kind == "arc":
            assert_pose(poses[0], next(vias), f"{fmt} segment {i} via")
        assert_pose(poses[-1], want["ends"][i + 1], f"{fmt} segment {i} end")


def test_round_trip_val(seam):
    """VAL II has no circular move: every segment end is a point of the program, in order,
    and the points between lie on the arc (at its radius, in its plane)."""
    want = seam_numbers()
    moves = parse_val(export(seam, "val", options()))
    assert moves[0][0] == "MOVE" and all(v == "MOVES" for v, _ in moves[1:])
    poses = [p[0] for _, p in moves]
    k = 0
    for j, end in enumerate(want["ends"]):
        while float(np.linalg.norm(poses[k][0] - end[0])) > TOL_MM:
            k += 1  # points along an arc
            assert k < len(poses), f"segment end {j} is not in the program"
        assert_pose(poses[k], end, f"val end {j}")
    d = json.loads(SEAM_FILE.read_text())["segments"][1]
    arc_pts = [p for p, _ in poses if 100 < p[0] < 150 - 1e-6 and 0 < p[1] < 50]
    assert len(arc_pts) >= 5
    r = np.linalg.norm(np.array(arc_pts) - d["centre_mm"], axis=1)
    assert np.all(np.abs(r - d["radius_mm"]) < TOL_MM)


def test_blends(seam):
    """Blended at the tangent junctions (line-arc, arc-line), stopping exactly at the
    corner and at the end: KRL C_DIS, RAPID zonedata vs fine, URScript r."""
    krl = [line for line in export(seam, "krl", options()).splitlines() if line.startswith(("LIN", "CIRC"))]
    assert [line.endswith("C_DIS") for line in krl] == [True, True, False, False]
    rapid = [m.group(1) for m in re.finditer(r"Move[LC] .*, vSeam, (\w+), tSeam", export(seam, "rapid", options()))]
    assert rapid[2:] == ["fine", "fine"] and "fine" not in rapid[:2]
    ur = [float(m.group(1)) for m in re.finditer(r"r=([\d.]+)", export(seam, "urscript", options()))]
    assert ur == [0.001, 0.001, 0.0, 0.0]
    assert "$VEL.CP = 0.020000" in export(seam, "krl", options())  # 20 mm/s in m/s


def test_dwells(seam):
    """With ``dwells``: the 0.8 s at the corner, after the move that ends there, in each
    format's own wait; none without."""
    waits = {"krl": ("WAIT SEC 0.800", "X 150.000, Y 120.000, Z 10.000"),
             "rapid": ("WaitTime \\InPos, 0.800;", "[[150.000,120.000,10.000]"),
             "urscript": ("sleep(0.800)", "p[0.1500000, 0.1200000, 0.0100000"),
             "val": ("DELAY 0.800", "TRANS(150.000, 120.000, 10.000")}
    opts = dataclasses.replace(options(), dwells=True)
    for fmt, (wait, corner) in waits.items():
        text = export(seam, fmt, opts)
        lines = text.splitlines()
        at = [i for i, line in enumerate(lines) if wait in line]
        assert len(at) == 1, fmt
        move = [line for line in lines[:at[0]] if re.match(r"\s*(PTP|LIN|CIRC|Move|move|MOVE)", line)][-1]
        name = re.match(r"\s*(?:MoveL|MOVES?) (\w+)", move)
        if name:  # RAPID and VAL II name their targets
            move = next(line for line in lines if re.search(rf"\b{name.group(1)} (:=|=) ", line))
        assert corner in move, f"{fmt}: waits after {move}"
        assert wait not in export(seam, fmt, options())
    assert [m.get("dwell_s") for m in json.loads(export(seam, "json", opts))["moves"]] == [None, None, None,
                                                                                          0.8, None]


def test_long_arc_is_two_circular_moves():
    """An arc of 270 deg (r 40 mm about (0, 0, 5), normal -z): two CIRCs, each via and
    target on the circle, the vias and the middle target at 1/4, 1/2, 3/4 of the sweep
    (hand: from (40, 0, 5) clockwise seen from +z), the last target the arc's end."""
    seg = Segment(kind="arc", first=0, last=0, start_mm=(40.0, 0.0, 5.0), end_mm=(0.0, 40.0, 5.0),
                  start_ypr_deg=(0.0, 0.0, 180.0), end_ypr_deg=(0.0, 0.0, 180.0), residual_rms_mm=0.0,
                  residual_max_mm=0.0, points=10, centre_mm=(0.0, 0.0, 5.0), normal=(0.0, 0.0, -1.0),
                  radius_mm=40.0, sweep_deg=270.0)
    seam = Seam(segments=(seg,), corners=(), dwells=(), outliers=(), noise_mm=0.0, config=FitConfig(), points=10,
                meta={"point": "tip"})
    moves = parse_krl(export(seam, "krl", options()))
    assert [verb for verb, _ in moves] == ["PTP", "CIRC", "CIRC"]
    # clockwise from +x by 67.5, 135, 202.5 and 270 deg
    c67, s67, h = 40 * math.cos(math.radians(67.5)), 40 * math.sin(math.radians(67.5)), 40 * math.sqrt(0.5)
    want = [(c67, -s67), (-h, -h), (-s67, c67), (0.0, 40.0)]  # via 1, target 1, via 2, target 2
    got = [tuple(p[0][:2]) for _, poses in moves[1:] for p in poses]
    assert np.allclose(got, want, atol=TOL_MM)
    assert all(abs(p[0][2] - 5.0) < TOL_MM for _, poses in moves for p in poses)


def test_json_samples_on_the_seam():
    """The neutral JSON's poses along the seam: on the hand-made lines and arc (mm), arc
    length from 0 to the seam's length (100 + 25 pi + sqrt(70^2 + 10^2) + 90 mm)."""
    d = json.loads(golden("json").read_text())
    s = np.array([x["s_mm"] for x in d["samples"]])
    assert s[0] == 0 and np.all(np.diff(s) > 0) and np.all(np.diff(s) <= 5.0 + 1e-9)
    assert abs(s[-1] - (100 + 25 * math.pi + math.hypot(70, 10) + 90)) < 1e-3
    for x in d["samples"]:
        p = np.array(x["x_mm"])
        if x["segment"] == 1:
            assert abs(np.linalg.norm(p - [100, 50, 0]) - 50) < TOL_MM and abs(p[2]) < TOL_MM
        else:
            a, b = {0: ([0, 0, 0], [100, 0, 0]), 2: ([150, 50, 0], [150, 120, 10]),
                    3: ([150, 120, 10], [60, 120, 10])}[x["segment"]]
            a, b = np.array(a, float), np.array(b, float)
            t = (p - a) @ (b - a) / ((b - a) @ (b - a))
            assert -1e-9 <= t <= 1 + 1e-9 and np.linalg.norm(a + t * (b - a) - p) < TOL_MM


def test_tool_is_the_torch_on_the_flange(seam):
    """The tool: the torch 200 mm along the flange's z (the controller's flange_T_tool_x)."""
    assert "$TOOL = {X 0.000, Y 0.000, Z 200.000, A 0.0000, B 0.0000, C 0.0000}" in export(seam, "krl", options())
    assert "[TRUE,[[0.000,0.000,200.000],[1.0000000,0.0000000,0.0000000,0.0000000]]" in export(seam, "rapid",
                                                                                                   options())
    assert "set_tcp(p[0.0000000, 0.0000000, 0.2000000, " in export(seam, "urscript", options())


def test_cli_writes_refuses_and_errs(tmp_path):
    out = tmp_path / "seam.src"
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "krl", "-o", str(out), "--name", "seam")
    assert r.returncode == 0, r.stderr
    assert out.read_text() == golden("krl").read_text()
    before = out.read_text()
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "rapid", "-o", str(out))
    assert r.returncode != 0 and "exists" in r.stderr and out.read_text() == before
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "abb", "-o", str(tmp_path / "x"))
    assert r.returncode != 0 and "invalid choice" in r.stderr and not (tmp_path / "x").exists()
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"format": "humanpt.seam", "version": 1, "segments": []}))
    r = run_cli_here("path", "export", str(empty), "--format", "json", "-o", str(tmp_path / "e.json"))
    assert r.returncode != 0 and "no segments" in r.stderr and not (tmp_path / "e.json").exists()
    (tmp_path / "zero.json").write_text("")
    r = run_cli_here("path", "export", str(tmp_path / "zero.json"), "--format", "krl", "-o", str(tmp_path / "z.src"))
    assert r.returncode != 0 and "not JSON" in r.stderr and not (tmp_path / "z.src").exists()
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "json", "-o", str(SEAM_FILE), "--overwrite")
    assert r.returncode != 0 and "is the input" in r.stderr
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "json", "--point", "G", "-o", str(tmp_path / "g"))
    assert r.returncode != 0 and "the seam is of tip" in r.stderr and not (tmp_path / "g").exists()


if __name__ == "__main__":
    if "--regenerate" in sys.argv:
        regenerate()
    else:
        print(__doc__)


def test_cli_retimed_g_seam_and_tool(tmp_path):
    """A seam of G with a feed and timed samples (a retimed seam): the feed is the
    default speed, the JSON carries the samples' times; the tool is the controller's
    torch by default, --tool's when given, refused when not six numbers."""
    d = json.loads(SEAM_FILE.read_text())
    d["source"]["point"] = "G"
    d["retime"] = {"speed_mm_s": 35.0, "samples": [{"t_s": 0.0, "x": [0, 0, 0, 0, 30, 180]},
                                                   {"t_s": 0.004, "x": [0.14, 0, 0, 0.01, 30, 179.99]}]}
    g = tmp_path / "g.seam.json"
    g.write_text(json.dumps(d))
    r = run_cli_here("path", "export", str(g), "--format", "json")
    assert r.returncode == 0, r.stderr
    prog = json.loads((tmp_path / "g.json").read_text())
    assert prog["speed_mm_s"] == 35.0 and prog["point"] == "G"
    assert [x["t_s"] for x in prog["samples"]] == [0.0, 0.004]
    assert prog["samples"][1]["x_mm"] == [0.14, 0.0, 0.0]
    assert prog["tool"]["flange_T_tool"]["x_mm"] == [0.0, 0.0, 200.0]
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "krl", "--tool", "1,-2,75,0,0,0", "-o",
                str(tmp_path / "t.src"))
    assert r.returncode == 0, r.stderr
    assert "$TOOL = {X 1.000, Y -2.000, Z 75.000, A 0.0000, B 0.0000, C 0.0000}" in (tmp_path / "t.src").read_text()
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", "krl", "--tool", "1,2,3", "-o", str(tmp_path / "u.src"))
    assert r.returncode == 2 and "six finite numbers" in r.stderr and not (tmp_path / "u.src").exists()
