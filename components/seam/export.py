"""A fitted seam as a robot program (issue 21.3): VAL II, KUKA KRL, ABB RAPID, URScript, JSON.

The seam (:class:`humanpt.seam.fit.Seam`, humanpt's world frame, mm, torch Z-Y-X degrees
per segment end) becomes a list of :class:`Move`: a joint move to the first point, then
per segment a linear move to its end or, for an arc, a circular move through the arc's
midpoint (the via point) to its end.  Where one segment runs on from the previous one
without a corner (a tangent junction) the move is blended by ``zone_mm``; at a corner and
at the last point the robot stops exactly (``corner_zone_mm``, default 0: fine).  Along
a segment the torch turns on the geodesic between its two end orientations, so the via
point's orientation is half way (:func:`humanpt.geometry.transforms.slerp`).

Conventions of each format (every conversion is scipy's ``Rotation``):

==========  ======  ==============================================  ====================
format      units   orientation                                      tool
==========  ======  ==============================================  ====================
val         mm      TRANS O, A, T: Euler Z-Y-Z (deg)                 TOOL TRANS(...)
krl         mm      A, B, C: rotations about Z, Y, X (deg) =         ``$TOOL`` FRAME
                    humanpt's psi, theta, phi
rapid       mm      quaternion [q1, q2, q3, q4] = [w, x, y, z],      tooldata tframe
                    q1 >= 0
urscript    m       rotation vector [rx, ry, rz] (rad)               ``set_tcp(p[...])``
json        mm      Z-Y-X psi, theta, phi (deg) and [w, x, y, z]     flange_T_tool
==========  ======  ==============================================  ====================

Every pose is of the seam's point (the driver tip P or the target's G, as the seam says)
in humanpt's world frame: the robot's base (KRL ``$BASE``, RAPID ``wobj0``, UR base)
must be humanpt's world frame.  The tool is the torch's tip on the robot's flange
(``flange_T_tool``: the controller's ``flange_T_tool_x``, what humanpt's own playback
moves along the seam), so the robot puts the torch where the seam is.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from humanpt.geometry.transforms import oat_deg_from_rotation, rotation_from_ypr_deg, slerp
from humanpt.seam import limits
from humanpt.seam.fit import Seam, Segment
from humanpt.seam.sanitise import comment, comment_line, identifier, shown

__all__ = ["FORMATS", "SUFFIXES", "ExportError", "ExportOptions", "Move", "moves", "pose_at", "export",
           "to_val", "to_krl", "to_rapid", "to_urscript", "to_json", "program_name", "check"]

FORMATS = ("val", "krl", "rapid", "urscript", "json")
SUFFIXES = {"val": ".v2", "krl": ".src", "rapid": ".mod", "urscript": ".script", "json": ".json"}

# A dwell is waited at the nearest move target within this (mm).
DWELL_REACH_MM = 2.0

# Two segments closer than this (mm) at a junction are continuous; farther (a seam file
# not from humanpt's fit), a linear move bridges the gap.
_JOIN_MM = 1e-3

# An arc sweeping more than this (deg) is two circular moves: robots take a circle
# through three points only up to some sweep (ABB about 240 deg), and the via point
# defines the circle poorly as it nears the ends.
MAX_CIRC_SWEEP_DEG = 180.0


class ExportError(ValueError):
    """A seam or an option that cannot be exported; says which."""


@dataclass(frozen=True)
class ExportOptions:
    """How to write the program: the feed (mm/s), the blend at tangent junctions and at
    corners (mm; 0 stops exactly), the program's name, the seam's point (``tip`` or ``G``)
    and the tool ``flange_T_tool_mm`` (4, 4) mm, the acceleration for URScript (mm/s^2),
    the VAL II SPEED
    (percent of the monitor speed: VAL II has no speed in mm/s) and the largest chord
    error (mm) of the points VAL II gets along an arc (it has no circular move), the
    spacing (mm) of the JSON's poses along the seam; ``dwells``: wait where the welder
    dwelt (:func:`moves`).  Every number is checked here: the feed within
    ``max_speed_mm_s`` (default :data:`humanpt.seam.limits.MAX_SPEED_MM_S`, retime's),
    the acceleration, blends, tool within their bounds; every pose the program moves
    through must lie in the workspace box ``envelope_min_mm``..``envelope_max_mm``
    (world, mm; default the gateway's, :mod:`humanpt.seam.limits`), or :func:`export`
    refuses (:func:`check`).  ``name`` and ``source`` reach the program only through
    :mod:`humanpt.seam.sanitise`.  ``arc``: switch the welding arc on at the seam's start and
    off at its end (:func:`arc_switch`; "" leaves the arc to the cell), checked against the
    format when the program is written."""

    speed_mm_s: float = 20.0
    zone_mm: float = 1.0
    corner_zone_mm: float = 0.0
    name: str = "seam"
    point: str = "tip"
    flange_T_tool_mm: tuple[tuple[float, ...], ...] = tuple(map(tuple, np.eye(4)))
    accel_mm_s2: float = 500.0
    val_speed_percent: float = 20.0
    val_chord_mm: float = 0.05
    json_step_mm: float = 1.0
    dwells: bool = False
    source: str = ""
    max_speed_mm_s: float = limits.MAX_SPEED_MM_S
    envelope_min_mm: tuple[float, float, float] = limits.ENVELOPE_MIN_MM
    envelope_max_mm: tuple[float, float, float] = limits.ENVELOPE_MAX_MM
    arc: str = ""

    def __post_init__(self):
        def within(k, lo, hi, lo_open=True):
            v = getattr(self, k)
            ok = isinstance(v, (int, float)) and math.isfinite(v) and (lo < v if lo_open else lo <= v) and v <= hi
            if not ok:
                raise ExportError(f"{k} must be a number in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {v!r}")

        within("max_speed_mm_s", 0.0, limits.SPEED_CEILING_MM_S)
        within("speed_mm_s", 0.0, limits.SPEED_CEILING_MM_S)
        if self.speed_mm_s > self.max_speed_mm_s:
            raise ExportError(f"speed_mm_s {self.speed_mm_s:g} mm/s is above the limit max_speed_mm_s "
                              f"{self.max_speed_mm_s:g} mm/s")
        within("accel_mm_s2", 0.0, limits.ACCEL_CEILING_MM_S2)
        within("val_speed_percent", 0.0, 100.0)
        within("val_chord_mm", 1e-3, 10.0, lo_open=False)
        within("json_step_mm", 0.01, 1000.0, lo_open=False)
        for k in ("zone_mm", "corner_zone_mm"):
            within(k, 0.0, 1000.0, lo_open=False)
        if self.point not in ("tip", "G"):
            raise ExportError(f"point must be tip or G, got {self.point!r}")
        T = np.asarray(self.flange_T_tool_mm, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ExportError("flange_T_tool_mm must be a 4x4 transform of finite numbers")
        if float(np.abs(T[:3, 3]).max()) > limits.MAX_TOOL_MM or float(np.linalg.norm(T[:3, 3])) > limits.MAX_TOOL_MM:
            raise ExportError(f"the tool's offset {_fmt_xyz(T[:3, 3])} mm from the flange is beyond "
                              f"{limits.MAX_TOOL_MM:g} mm")
        if not (np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6) and np.linalg.det(T[:3, :3]) > 0
                and np.allclose(T[3], [0, 0, 0, 1])):
            raise ExportError("flange_T_tool_mm's rotation is not a rotation")
        if not isinstance(self.arc, str) or len(self.arc) > 80:
            raise ExportError(f"arc must be a short text (an output, a signal name or arcware), got {self.arc!r}")
        lo, hi = np.asarray(self.envelope_min_mm, dtype=float), np.asarray(self.envelope_max_mm, dtype=float)
        if (lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)))
                or np.any(np.abs(np.r_[lo, hi]) > limits.MAX_ABS_MM) or np.any(lo >= hi)):
            raise ExportError(f"the envelope {list(self.envelope_min_mm)}..{list(self.envelope_max_mm)} mm: three "
                              f"finite lower bounds below three upper ones, within +-{limits.MAX_ABS_MM:g} mm")


@dataclass(frozen=True)
class Move:
    """One motion of the program: ``kind`` ``joint`` (to the first point), ``line`` or
    ``arc``; ``target`` and (arcs) ``via`` are (6,) x, y, z mm and psi, theta, phi deg
    (Z-Y-X) in the world frame; ``zone_mm`` the blend at the target (0: stop exactly);
    ``segment`` the seam's segment (-1: the approach, or a bridge between two segments);
    ``dwell_s`` how long to wait at the target (s; 0: none)."""

    kind: str
    target: np.ndarray
    via: np.ndarray | None
    zone_mm: float
    segment: int
    dwell_s: float = 0.0


def program_name(name: str, fmt: str = "krl") -> str:
    """``name`` as a program name ``fmt`` accepts (:func:`humanpt.seam.sanitise.identifier`:
    letters, digits and ``_``, starting with a letter, no keyword, at most 24 characters
    for KRL, 32 for RAPID and URScript, 15 for VAL II)."""
    return identifier(name, fmt)


def pose_at(seg: Segment, s: float) -> np.ndarray:
    """(6,) the seam's pose a fraction ``s`` (0..1) along a segment: mm on the line or the
    arc (by arc length; at 0 and 1 the segment's own ends), the torch on the geodesic
    between the end orientations, Z-Y-X deg."""
    p = seg.points_at(s)[0]  # the ends are the seam's own
    r0, r1 = rotation_from_ypr_deg(seg.start_ypr_deg), rotation_from_ypr_deg(seg.end_ypr_deg)
    ypr = Rotation.from_matrix(slerp(r0, r1, s)).as_euler("ZYX", degrees=True)
    return np.concatenate([p, ypr])


def _is_corner(seam: Seam, i: int) -> bool:
    """Whether the junction after segment ``i`` is a corner of the seam."""
    return any(c.before == i and c.after == i + 1 for c in seam.corners)


def moves(seam: Seam, zone_mm: float = 1.0, corner_zone_mm: float = 0.0, dwells: bool = False) -> list[Move]:
    """The seam as moves (see the module doc); an arc of more than
    :data:`MAX_CIRC_SWEEP_DEG` is two circular moves (vias at 1/4 and 3/4 of it, the
    first target half way).  A blend never exceeds 0.4 of the shorter of the two moves it
    joins (robots refuse or shrink overlapping blends).  With
    ``dwells``, each of the seam's dwells is a wait of its duration, without a blend, at
    the move's target nearest to it (the fit puts dwells at segment ends) if within
    :data:`DWELL_REACH_MM`; a dwell farther from every target is left out."""
    segs = seam.segments
    if not segs:
        raise ExportError("the seam has no segments")
    out = [Move("joint", pose_at(segs[0], 0.0), None, 0.0, -1)]
    for i, seg in enumerate(segs):
        start = pose_at(seg, 0.0)
        if np.linalg.norm(start[:3] - out[-1].target[:3]) > _JOIN_MM:
            out.append(Move("line", start, None, 0.0, -1))
        last = i == len(segs) - 1
        z = 0.0 if last else (corner_zone_mm if _is_corner(seam, i) else zone_mm)
        if z > 0:
            nxt = segs[i + 1]
            gap = float(np.linalg.norm(np.subtract(nxt.start_mm, seg.end_mm)))
            z = min(z, 0.4 * seg.length_mm, 0.4 * (gap if gap > _JOIN_MM else nxt.length_mm))
        if seg.kind == "arc" and abs(seg.sweep_deg) > MAX_CIRC_SWEEP_DEG:
            half = min(zone_mm, 0.4 * seg.length_mm / 2)  # the two halves run on tangentially
            out.append(Move("arc", pose_at(seg, 0.5), pose_at(seg, 0.25), half, i))
            out.append(Move("arc", pose_at(seg, 1.0), pose_at(seg, 0.75), z, i))
        elif seg.kind == "arc":
            out.append(Move("arc", pose_at(seg, 1.0), pose_at(seg, 0.5), z, i))
        else:
            out.append(Move("line", pose_at(seg, 1.0), None, z, i))
    if dwells:
        for d in seam.dwells:
            dist = [float(np.linalg.norm(m.target[:3] - np.asarray(d.point_mm))) for m in out]
            k = int(np.argmin(dist))
            if dist[k] <= DWELL_REACH_MM:
                m = out[k]
                out[k] = Move(m.kind, m.target, m.via, 0.0, m.segment, m.dwell_s + d.duration_s)
    return out


# ---------------------------------------------------------------------------- checks

# A circular move's robot arc (through its start, via and target) may sweep this much
# (deg) more or less than the seam's arc before the export is refused: the via would
# not lie between the ends (the robot would go the long way round).
ARC_SWEEP_TOL_DEG = 30.0


def _robot_arc(a: np.ndarray, b: np.ndarray, c: np.ndarray, n: int = 90) -> tuple[np.ndarray, float] | None:
    """The circle a robot takes through ``a``, via ``b``, to ``c`` (mm): (n, 3) points
    along it from ``a`` to ``c`` and its sweep (deg); None when the three are in a line."""
    u, v = b - a, c - a
    w = np.cross(u, v)
    ww = float(w @ w)
    if ww < 1e-12 * max(float(u @ u) * float(v @ v), 1e-30):
        return None
    centre = a + (float(u @ u) * np.cross(v, w) + float(v @ v) * np.cross(w, u)) / (2.0 * ww)
    r = float(np.linalg.norm(a - centre))
    nrm = w / math.sqrt(ww)
    e1 = (a - centre) / r
    e2 = np.cross(nrm, e1)
    dc = c - centre
    sweep = math.atan2(float(dc @ e2), float(dc @ e1)) % (2 * math.pi)  # a -> b -> c turns positively about w
    ang = np.linspace(0.0, sweep, n)
    return centre + r * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2), math.degrees(sweep)


def check(seam: Seam, opts: ExportOptions, timed: list[tuple[float, np.ndarray]] | None = None) -> list[Move]:
    """The moves of the program, once every pose it goes through is known to lie in the
    workspace box (``opts.envelope_min_mm``..``envelope_max_mm``): each move's target and
    via, every point along each arc of the seam, the arc each circular move makes the
    robot take (through its start, via and target: refused when the three are in a line
    or it sweeps more than :data:`ARC_SWEEP_TOL_DEG` beyond the seam's arc), and the
    timed samples (whose speed between samples must keep within ``max_speed_mm_s``);
    :class:`ExportError` naming the segment or sample otherwise."""
    lo, hi = np.asarray(opts.envelope_min_mm, dtype=float), np.asarray(opts.envelope_max_mm, dtype=float)
    box = f"the workspace {_fmt_xyz(lo)}..{_fmt_xyz(hi)} mm"

    def inside(p: np.ndarray, what: str) -> None:
        p = np.atleast_2d(p)
        bad = ~np.all(np.isfinite(p) & (p >= lo - 1e-9) & (p <= hi + 1e-9), axis=1)
        if bad.any():
            raise ExportError(f"{what}: {_fmt_xyz(p[int(np.argmax(bad))])} mm is outside {box} (--envelope)")

    for i, seg in enumerate(seam.segments):
        inside(np.asarray(seg.start_mm), f"segments[{i}]: start_mm")
        inside(np.asarray(seg.end_mm), f"segments[{i}]: end_mm")
        if seg.kind == "arc":
            n = max(2, math.ceil(abs(seg.sweep_deg)) + 1)
            inside(seg.points_at(np.linspace(0.0, 1.0, n)), f"segments[{i}]: a point on the arc")
    mv = moves(seam, opts.zone_mm, opts.corner_zone_mm, opts.dwells)
    prev = mv[0].target
    for m in mv:
        where = f"segments[{m.segment}]" if m.segment >= 0 else "a move between segments"
        inside(m.target[:3], f"{where}: the move's target")
        if m.via is not None:
            inside(m.via[:3], f"{where}: the circular move's via point")
            arc = _robot_arc(prev[:3], m.via[:3], m.target[:3])
            if arc is None:
                raise ExportError(f"{where}: the circular move's start, via and target are in a line")
            pts, sweep = arc
            seg = seam.segments[m.segment]
            part = abs(seg.sweep_deg) / (2 if abs(seg.sweep_deg) > MAX_CIRC_SWEEP_DEG else 1)
            if abs(sweep - part) > ARC_SWEEP_TOL_DEG:
                raise ExportError(f"{where}: the circular move through its start, via and target sweeps "
                                  f"{sweep:.1f} deg, the seam's arc {part:.1f} deg: the arc's ends are off its circle")
            inside(pts, f"{where}: the robot's arc")
        prev = m.target
    if timed is not None:
        last = None
        for k, (t, x) in enumerate(timed):
            x = np.asarray(x, dtype=float)
            if x.shape != (6,) or not np.all(np.isfinite(x)) or not math.isfinite(t):
                raise ExportError(f"retime.samples[{k}]: t_s and x must be finite (6 numbers)")
            inside(x[:3], f"retime.samples[{k}]: x")
            if last is not None:
                dt, dp = t - last[0], float(np.linalg.norm(x[:3] - last[1][:3]))
                if dt < 0 or (dp > 1e-3 and dp > opts.max_speed_mm_s * 1.01 * dt + 1e-3):
                    v = dp / dt if dt > 0 else math.inf
                    raise ExportError(f"retime.samples[{k}]: {v:.6g} mm/s from the sample before, above the limit "
                                      f"max_speed_mm_s {opts.max_speed_mm_s:g} mm/s")
            last = (t, x)
    return mv


def _fmt_xyz(p) -> str:
    return "(" + ", ".join(f"{float(v):.6g}" for v in p) + ")"


# ---------------------------------------------------------------------------- the arc

# Where each language switches a digital output, and the outputs it has (the vendors' manuals:
# KSS 8 $OUT[1..4096]; URScript set_standard_digital_out(n, b), n 0..7; RAPID SetDO takes a
# signal's name, declared in the controller's I/O configuration).
ARC_OUTPUTS = {"krl": (1, 4096), "urscript": (0, 7)}
ARCWARE_DEFAULTS = ("seam1", "weld1")  # seamdata, welddata of the RobotWare Arc option


@dataclass(frozen=True)
class ArcSwitch:
    """How a program switches the arc: ``kind`` ``output`` (``output`` a number, KRL and
    URScript), ``signal`` (``signal`` a RAPID digital output's name) or ``arcware`` (RAPID's
    ArcLStart/ArcL/ArcC/ArcLEnd with ``seamdata`` and ``welddata``, which the controller's
    Arc option must define)."""

    kind: str
    output: int = 0
    signal: str = ""
    seamdata: str = ""
    welddata: str = ""


def _rapid_name(name: str, what: str) -> str:
    """``name`` when RAPID accepts it as it is (a name on the robot must not be rewritten: a
    rewritten signal name would switch another output, or none), else ExportError."""
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,31}", name) or identifier(name, "rapid") != name:
        raise ExportError(f"--arc: {what} {shown(name)} is not a RAPID name this program may use (a letter, then "
                          "letters, digits and _, at most 32, not a keyword nor one of the program's own names)")
    return name


def arc_switch(arc: str, fmt: str) -> ArcSwitch | None:
    """``arc`` (:attr:`ExportOptions.arc`) checked for ``fmt``: None for ""; KRL and URScript
    an output number within :data:`ARC_OUTPUTS`; RAPID a digital output's name, or
    ``arcware[:SEAMDATA,WELDDATA]`` (default :data:`ARCWARE_DEFAULTS`); VAL II has no
    arc switching here (the Puma's welding interface was the cell's own), JSON records the
    text as given.  ExportError saying what is allowed otherwise."""
    arc = arc.strip()
    if not arc:
        return None
    if fmt == "val":
        raise ExportError("--arc: VAL II programs here do not switch the arc (wire it in the cell's own way); "
                          "krl, rapid, urscript and json do")
    if fmt == "json":
        return ArcSwitch("signal", signal=comment(arc))
    if fmt == "rapid":
        if arc == "arcware" or arc.startswith("arcware:"):
            names = arc.partition(":")[2]
            seam_d, weld_d = names.split(",") if names.count(",") == 1 else (names, "") if names else ARCWARE_DEFAULTS
            if not (seam_d and weld_d):
                raise ExportError(f"--arc {shown(arc)}: arcware:SEAMDATA,WELDDATA (default arcware = "
                                  f"arcware:{','.join(ARCWARE_DEFAULTS)})")
            return ArcSwitch("arcware", seamdata=_rapid_name(seam_d.strip(), "seamdata"),
                             welddata=_rapid_name(weld_d.strip(), "welddata"))
        return ArcSwitch("signal", signal=_rapid_name(arc, "the signal"))
    lo, hi = ARC_OUTPUTS[fmt]
    if not re.fullmatch(r"\d{1,5}", arc) or not lo <= int(arc) <= hi:
        raise ExportError(f"--arc {shown(arc)}: {fmt} switches a digital output by its number, {lo}..{hi}")
    return ArcSwitch("output", output=int(arc))


# ---------------------------------------------------------------------------- formatting


def _f(v: float, nd: int) -> str:
    """``v`` with ``nd`` decimals, never ``-0.000``."""
    return f"{round(float(v), nd) + 0.0:.{nd}f}"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _moves(seam: Seam, opts: ExportOptions, timed: list[tuple[float, np.ndarray]] | None = None) -> list[Move]:
    """The moves every writer writes, once :func:`check` passed them."""
    return check(seam, opts, timed)


def _rot(x: np.ndarray) -> Rotation:
    return Rotation.from_matrix(rotation_from_ypr_deg(np.asarray(x[3:6], dtype=float)))


def _tool_x(opts: ExportOptions) -> np.ndarray:
    """(6,) the tool (flange_T_tool) as x, y, z mm and Z-Y-X deg."""
    T = np.asarray(opts.flange_T_tool_mm, dtype=float)
    return np.concatenate([T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_euler("ZYX", degrees=True)])


def _quat_wxyz(r: Rotation) -> np.ndarray:
    q = r.as_quat(canonical=True)  # scipy: [x, y, z, w], w >= 0
    return np.array([q[3], q[0], q[1], q[2]])


def _header_lines(seam: Seam, opts: ExportOptions, fmt: str, indent: str = "") -> list[str]:
    """The program's header comment lines, each through the comment whitelist of ``fmt``
    (the seam file's name is a user's: it may hold a newline and a statement)."""
    n_arc = sum(s.kind == "arc" for s in seam.segments)
    return [comment_line(line, fmt, indent) for line in (
        f"humanpt path export --format {fmt}" + (f": {opts.source}" if opts.source else ""),
        f"{_plural(len(seam.segments), 'segment')} ({_plural(len(seam.segments) - n_arc, 'line')}, "
        f"{_plural(n_arc, 'arc')}), {_plural(len(seam.corners), 'corner')}, the {opts.point} in humanpt's world frame",
        f"feed {opts.speed_mm_s:g} mm/s, blend {opts.zone_mm:g} mm at tangent junctions, "
        f"{opts.corner_zone_mm:g} mm at corners")]


def to_val(seam: Seam, opts: ExportOptions) -> str:
    """VAL II (the Puma's language; the conventions of
    :func:`humanpt.controller.pathfile.to_val2`): TRANS(x, y, z, o, a, t), mm and Euler
    Z-Y-Z deg; MOVE to the first point, MOVES (straight) through the rest.  VAL II has no
    circular move: an arc is given as points on it, at most ``val_chord_mm`` chord error
    apart.  SPEED is a percent of the monitor speed; the feed is stated in a comment."""
    prog = program_name(opts.name, "val")
    arc_switch(opts.arc, "val")  # refused when asked for
    pts: list[np.ndarray] = []
    waits: dict[int, float] = {}  # point index -> dwell s
    for m in _moves(seam, opts):
        if m.kind == "arc":
            seg = seam.segments[m.segment]
            # chord error r (1 - cos(da / 2)) <= val_chord_mm
            da = 2 * math.acos(max(-1.0, 1 - opts.val_chord_mm / seg.radius_mm))
            n = max(2, math.ceil(abs(math.radians(seg.sweep_deg)) / da))
            pts += [pose_at(seg, k / n) for k in range(1, n + 1)]
        else:
            pts.append(m.target)
        if m.dwell_s > 0:
            waits[len(pts) - 1] = m.dwell_s
    tool = _tool_x(opts)
    o, a, t = oat_deg_from_rotation(Rotation.from_euler("ZYX", tool[3:], degrees=True))
    lines = [f".PROGRAM {prog}()"] + _header_lines(seam, opts, "val", "  ")
    lines += [f"  ; SPEED {opts.val_speed_percent:g} (percent of the monitor speed): set it for "
              f"{opts.speed_mm_s:g} mm/s", f"  TOOL TRANS({_f(tool[0], 3)}, {_f(tool[1], 3)}, {_f(tool[2], 3)}, "
              f"{_f(o, 4)}, {_f(a, 4)}, {_f(t, 4)})", f"  SPEED {opts.val_speed_percent:g} ALWAYS"]
    for i, p in enumerate(pts):
        o, a, t = oat_deg_from_rotation(_rot(p))
        lines.append(f"  SET p{i} = TRANS({_f(p[0], 3)}, {_f(p[1], 3)}, {_f(p[2], 3)}, {_f(o, 4)}, {_f(a, 4)}, "
                     f"{_f(t, 4)})")
    for i in range(len(pts)):
        lines.append(f"  MOVE{'S' if i else ''} p{i}")
        if i in waits:
            lines += ["  BREAK", f"  DELAY {_f(waits[i], 3)}"]  # BREAK: arrive, then wait
    lines.append(".END")
    return "\n".join(lines) + "\n"


def _krl_frame(x: np.ndarray) -> str:
    a, b, c = _rot(x).as_euler("ZYX", degrees=True)
    return (f"{{X {_f(x[0], 3)}, Y {_f(x[1], 3)}, Z {_f(x[2], 3)}, A {_f(a, 4)}, B {_f(b, 4)}, "
            f"C {_f(c, 4)}}}")


def to_krl(seam: Seam, opts: ExportOptions) -> str:
    """KUKA KRL (.src): FRAME aggregates {X, Y, Z, A, B, C} (mm; A, B, C about Z, Y, X,
    deg); ``$BASE`` the world frame, ``$TOOL`` the tool; PTP to the first point, LIN, CIRC
    (via, target); ``$VEL.CP`` (m/s) the feed; ``C_DIS`` with ``$APO.CDIS`` (mm) where a
    move is blended."""
    prog = program_name(opts.name, "krl")
    lines = [f"DEF {prog}( )"] + _header_lines(seam, opts, "krl")
    lines += ["; $BASE = humanpt's world frame; $TOOL = the torch on the flange (flange_T_tool)",
              "$BASE = {X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}", f"$TOOL = {_krl_frame(_tool_x(opts))}",
              f"$VEL.CP = {_f(opts.speed_mm_s / 1000.0, 6)}", "$VEL.ORI1 = 200", "$VEL.ORI2 = 200",
              "$ORI_TYPE = #VAR", "$CIRC_TYPE = #PATH", "$ADVANCE = 3"]
    apo = None
    mv = _moves(seam, opts)
    arc = arc_switch(opts.arc, "krl")
    if arc:
        lines.append(f"; the arc: $OUT[{arc.output}] on at the seam's start, off at its end (humanpt path export --arc)")
    for k, m in enumerate(mv):
        if arc and k == 1:
            lines.append(f"$OUT[{arc.output}] = TRUE")
        if m.zone_mm > 0 and m.zone_mm != apo:
            apo = m.zone_mm
            lines.append(f"$APO.CDIS = {_f(apo, 3)}")
        cdis = " C_DIS" if m.zone_mm > 0 else ""
        if m.kind == "joint":
            lines.append(f"PTP {_krl_frame(m.target)}")
        elif m.kind == "line":
            lines.append(f"LIN {_krl_frame(m.target)}{cdis}")
        else:
            lines.append(f"CIRC {_krl_frame(m.via)}, {_krl_frame(m.target)}{cdis}")
        if m.dwell_s > 0:
            lines.append(f"WAIT SEC {_f(m.dwell_s, 3)}")
    if arc:
        lines.append(f"$OUT[{arc.output}] = FALSE")
    lines.append("END")
    return "\n".join(lines) + "\n"


_EXTAX = "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]"


def _rapid_pose(x: np.ndarray) -> str:
    q = _quat_wxyz(_rot(x))
    return f"[{_f(x[0], 3)},{_f(x[1], 3)},{_f(x[2], 3)}],[{','.join(_f(v, 7) for v in q)}]"


def _rapid_zone(z: float) -> str:
    if z <= 0:
        return "fine"
    # as the predefined z1: [finep, pzone_tcp, pzone_ori, pzone_eax, zone_ori, zone_leax, zone_reax]
    zs = _f(z, 3)
    return f"[FALSE,{zs},{zs},{zs},{_f(0.1 * z, 3)},{zs},{_f(0.1 * z, 3)}]"


def to_rapid(seam: Seam, opts: ExportOptions) -> str:
    """ABB RAPID (.mod): robtargets [[x, y, z] mm, [q1, q2, q3, q4] = [w, x, y, z]] in
    ``wobj0`` (the robot's base = humanpt's world), a tooldata of the torch on the flange, a speeddata
    of the feed, zonedata of the blends (``fine`` at corners and the end); MoveJ to the
    first point, MoveL, MoveC (via, target); ``ConfL \\Off`` (no configuration given)."""
    prog = program_name(opts.name, "rapid")
    tool = _tool_x(opts)
    mv = _moves(seam, opts)
    lines = [f"MODULE {prog}"] + _header_lines(seam, opts, "rapid", "  ")
    lines += ["  ! robtargets in wobj0 = humanpt's world frame; quaternions [q1,q2,q3,q4] = [w,x,y,z]",
              f"  PERS tooldata tSeam := [TRUE,[{_rapid_pose(tool)}],[1,[0,0,1],[1,0,0,0],0,0,0]];  ! load: 1 kg placeholder",
              f"  CONST speeddata vSeam := [{opts.speed_mm_s:g},500,5000,1000];"]
    zones: dict[str, str] = {}
    for m in mv:
        z = _rapid_zone(m.zone_mm)
        if z != "fine" and z not in zones:
            zones[z] = f"zSeam{len(zones) + 1}"
            lines.append(f"  CONST zonedata {zones[z]} := {z};")
    names: list[tuple[str, ...]] = []
    k = 0
    for m in mv:
        these = []
        for x in ([m.via] if m.via is not None else []) + [m.target]:
            lines.append(f"  CONST robtarget p{k} := [{_rapid_pose(x)},[0,0,0,0],{_EXTAX}];")
            these.append(f"p{k}")
            k += 1
        names.append(tuple(these))
    arc = arc_switch(opts.arc, "rapid")
    if arc and arc.kind == "arcware":
        lines.append(f"  ! the arc: RobotWare Arc's ArcLStart/ArcL/ArcC/ArcLEnd with seamdata {arc.seamdata} and "
                     f"welddata {arc.welddata}, which the controller must define (humanpt path export --arc)")
    elif arc:
        lines.append(f"  ! the arc: digital output {arc.signal} on at the seam's start, off at its end "
                     "(humanpt path export --arc)")
    lines += ["", "  PROC main()", "    ConfJ \\Off;", "    ConfL \\Off;"]
    ware = f"{arc.seamdata}, {arc.welddata}, " if arc and arc.kind == "arcware" else ""
    for k, (m, ns) in enumerate(zip(mv, names, strict=True)):
        z = zones.get(_rapid_zone(m.zone_mm), "fine")
        end = "End" if ware and k == len(mv) - 1 else ""
        if m.kind == "joint":
            lines.append(f"    MoveJ {ns[0]}, v100, fine, tSeam \\WObj:=wobj0;")
            if ware:  # the weld starts where ArcLStart ends: at the seam's first point
                lines.append(f"    ArcLStart {ns[0]}, v100, {ware}fine, tSeam \\WObj:=wobj0;")
            elif arc:
                lines.append(f"    SetDO {arc.signal}, 1;")
        elif m.kind == "line":
            lines.append(f"    {'ArcL' + end if ware else 'MoveL'} {ns[0]}, vSeam, {ware}{z}, tSeam \\WObj:=wobj0;")
        else:
            lines.append(f"    {'ArcC' + end if ware else 'MoveC'} {ns[0]}, {ns[1]}, vSeam, {ware}{z}, "
                         "tSeam \\WObj:=wobj0;")
        if m.dwell_s > 0:
            lines.append(f"    WaitTime \\InPos, {_f(m.dwell_s, 3)};")
    if arc and not ware:
        lines.append(f"    SetDO {arc.signal}, 0;")
    lines += ["  ENDPROC", "ENDMODULE"]
    return "\n".join(lines) + "\n"


def _ur_pose(x: np.ndarray) -> str:
    rv = _rot(x).as_rotvec()
    return f"p[{', '.join(_f(v / 1000.0, 7) for v in x[:3])}, {', '.join(_f(v, 7) for v in rv)}]"


def to_urscript(seam: Seam, opts: ExportOptions) -> str:
    """Universal Robots URScript: poses p[x, y, z, rx, ry, rz] (m; rotation vector, rad)
    in the robot's base frame (= humanpt's world), ``set_tcp`` the tool; movej to the
    first point, movel, movec (via, target; mode 0: the orientation interpolated from the
    start to the target) with a (m/s^2), v (m/s) and the blend radius r (m)."""
    prog = program_name(opts.name, "urscript")
    a, v = _f(opts.accel_mm_s2 / 1000.0, 4), _f(opts.speed_mm_s / 1000.0, 6)
    lines = [f"def {prog}():"] + _header_lines(seam, opts, "urscript", "  ")
    lines += ["  # poses in the base frame = humanpt's world; the TCP = the torch on the flange",
              f"  set_tcp({_ur_pose(_tool_x(opts))})"]
    arc = arc_switch(opts.arc, "urscript")
    if arc:
        lines.append(f"  # the arc: standard digital output {arc.output} on at the seam's start, off at its end "
                     "(humanpt path export --arc)")
    for m in _moves(seam, opts):
        r = _f(m.zone_mm / 1000.0, 6)
        if m.kind == "joint":
            lines.append(f"  movej({_ur_pose(m.target)}, a=0.5, v=0.25)")
            if arc:
                lines.append(f"  set_standard_digital_out({arc.output}, True)")
        elif m.kind == "line":
            lines.append(f"  movel({_ur_pose(m.target)}, a={a}, v={v}, r={r})")
        else:
            lines.append(f"  movec({_ur_pose(m.via)}, {_ur_pose(m.target)}, a={a}, v={v}, r={r}, mode=0)")
        if m.dwell_s > 0:
            lines.append(f"  sleep({_f(m.dwell_s, 3)})")
    if arc:
        lines.append(f"  set_standard_digital_out({arc.output}, False)")
    lines.append("end")
    return "\n".join(lines) + "\n"


def _json_pose(x: np.ndarray) -> dict:
    return {"x_mm": [round(float(v), 4) + 0.0 for v in x[:3]],
            "ypr_deg": [round(float(v), 5) + 0.0 for v in _rot(x).as_euler("ZYX", degrees=True)],
            "quat_wxyz": [round(float(v), 8) + 0.0 for v in _quat_wxyz(_rot(x))]}


def to_json(seam: Seam, opts: ExportOptions, timed: list[tuple[float, np.ndarray]] | None = None) -> str:
    """A neutral program (``"format": "humanpt.program"``): the moves (targets and via
    points as mm, Z-Y-X deg and quaternions [w, x, y, z]), and the poses along the seam,
    each ``json_step_mm`` (arc length ``s_mm``), or, when the seam was retimed, ``timed``: its
    samples (t s, (6,) pose) with ``t_s``."""
    step_mm = opts.json_step_mm
    mv = _moves(seam, opts, timed)
    samples = []
    if timed is not None:
        samples = [{"t_s": round(float(t), 6), **_json_pose(np.asarray(x, dtype=float))} for t, x in timed]
    else:
        s0 = 0.0
        for i, seg in enumerate(seam.segments):
            n = max(1, math.ceil(seg.length_mm / step_mm))
            for k in range(0 if i == 0 else 1, n + 1):
                samples.append({"s_mm": round(s0 + seg.length_mm * k / n, 4), "segment": i,
                                **_json_pose(pose_at(seg, k / n))})
            s0 += seg.length_mm
    doc = {
        "format": "humanpt.program", "version": 1, "name": program_name(opts.name, "json"),
        "source": comment(opts.source),
        "frame": "world", "point": opts.point,
        "units": {"position": "mm", "ypr_deg": "Z-Y-X psi, theta, phi: R = Rz(psi) Ry(theta) Rx(phi)",
                  "quat_wxyz": "[w, x, y, z]", "speed": "mm/s", "zone": "mm"},
        "tool": {"flange_T_tool": _json_pose(_tool_x(opts))},
        "speed_mm_s": opts.speed_mm_s, "zone_mm": opts.zone_mm, "corner_zone_mm": opts.corner_zone_mm,
        **({"arc": {"signal": arc.signal, "on_after_move": 0, "off_after_move": len(mv) - 1}}
           if (arc := arc_switch(opts.arc, "json")) else {}),
        "moves": [{"kind": m.kind, "segment": m.segment, "zone_mm": round(m.zone_mm, 4),
                   **({"dwell_s": round(m.dwell_s, 4)} if m.dwell_s > 0 else {}),
                   **({"via": _json_pose(m.via)} if m.via is not None else {}), "target": _json_pose(m.target)}
                  for m in mv],
    }
    # Readable and diffable: numeric lists on one line, each sample on one line.
    head = re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]",
                  json.dumps(doc, indent=1))
    rows = ",\n".join("  " + json.dumps(s) for s in samples)
    return head[:-2] + ',\n "samples": [\n' + rows + "\n ]\n}\n"


_WRITERS = {"val": to_val, "krl": to_krl, "rapid": to_rapid, "urscript": to_urscript, "json": to_json}


def export(seam: Seam, fmt: str, opts: ExportOptions, timed: list[tuple[float, np.ndarray]] | None = None) -> str:
    """The program's text in format ``fmt`` (one of :data:`FORMATS`), once :func:`check`
    found every pose in the workspace (else :class:`ExportError`; every writer checks)."""
    if fmt not in _WRITERS:
        raise ExportError(f"unknown format {fmt!r}; one of {', '.join(FORMATS)}")
    if fmt == "json":
        return to_json(seam, opts, timed=timed)
    return _WRITERS[fmt](seam, opts)
