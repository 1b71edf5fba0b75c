"""Scenarios: how the operator moves the target. Pure: a scenario and a time give a pose.

A :class:`Scenario` is a start pose and a list of segments (straight lines, circular arcs,
dwells), each with its own speeds, optionally a driver (the needle tip P of eq. (9)) and a
hand tremor, and covers (the operator's hand or an obstacle hiding part of a source for a
while). :class:`Trajectory` turns it into ``pose(t)`` and ``cover(t)``. Scenarios are
written as text files (see ``README.md`` in this folder for the format;
:func:`parse_scenario`, :func:`format_scenario`), and some are built in
(:func:`builtin_scenario`): the paper's static target (Table 1), its rotating base
(Section 6, Fig. 8), the trapezium seam (Fig. 9), a freehand seam, and the hard cases of
issue 18: an S-curve with a sharp corner and a dwell, abrupt starts, stops and torch turns,
a source hidden for 2 s, and a source partly covered.

Frames and units: world frame, mm and degrees (X = x, y, z, yaw, pitch, roll, Z-Y-X as in
the geometry library); transforms (4, 4) in mm. The path frame is the TOB frame (``path
tob``) or the driver tip frame (``path tip``, parallel to the TOB frame, eq. (9)).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from humanpt.geometry import (
    apply_step,
    interpolate_transform,
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    rotation_angle_rad,
    transform_from_x,
)

__all__ = [
    "ScenarioError",
    "Line",
    "Arc",
    "Dwell",
    "Tremor",
    "Cover",
    "SOURCE_NAMES",
    "Scenario",
    "Trajectory",
    "TremorModel",
    "parse_scenario",
    "format_scenario",
    "builtin_scenario",
    "BUILTIN_SCENARIOS",
    "TABLE1_X_MM_DEG",
    "ARC_CENTRE_MM",
    "ARC_RADIUS_MM",
    "DEFAULT_SPEED_MM_S",
    "DEFAULT_ANGULAR_SPEED_DEG_S",
]

DEFAULT_SPEED_MM_S = 20.0
DEFAULT_ANGULAR_SPEED_DEG_S = 20.0
TABLE1_X_MM_DEG = (236.132, 1248.772, 85.284, -2.598, -0.883, -4.535)
"""The paper's static TOB state (Section 6, Table 1): x, y, z mm, psi, theta, phi deg."""
ARC_CENTRE_MM = (147.5, 1378.5, 448.0)
ARC_RADIUS_MM = 246.0
FACE_UP_ROLL_DEG = 180.0  # roll 180 deg: w points down, the lit face up to a camera above

Vec3 = tuple[float, float, float]


class ScenarioError(ValueError):
    """A scenario that cannot be used; ``line`` is its 1-based line in the file (0: none)."""

    def __init__(self, message: str, line: int = 0, source: str = "<scenario>"):
        self.line = line
        self.source = source
        self.reason = message
        super().__init__(f"{source}:{line}: {message}" if line else f"{source}: {message}")


# --------------------------------------------------------------------------- model


@dataclass(frozen=True)
class Line:
    """Straight line from the current pose to ``to_mm`` (path frame origin, world, mm);
    orientation turns (geodesically) to ``ypr_deg`` when given, else stays."""

    to_mm: Vec3
    ypr_deg: Vec3 | None = None
    speed_mm_s: float = DEFAULT_SPEED_MM_S
    angular_speed_deg_s: float = DEFAULT_ANGULAR_SPEED_DEG_S
    line: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Arc:
    """Circular arc: the current pose turns by ``angle_deg`` about the axis through
    ``centre_mm`` along ``axis`` (right hand); orientation turns with it (``follow``) or
    stays (``fixed``)."""

    centre_mm: Vec3
    angle_deg: float
    axis: Vec3 = (0.0, 0.0, 1.0)
    orientation: Literal["follow", "fixed"] = "follow"
    speed_mm_s: float = DEFAULT_SPEED_MM_S
    angular_speed_deg_s: float = DEFAULT_ANGULAR_SPEED_DEG_S
    line: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Dwell:
    """Hold the current pose for ``duration_s``."""

    duration_s: float
    line: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Tremor:
    """Human tremor added to the path frame: RMS ``amplitude_mm`` per axis and
    ``amplitude_deg`` per rotation axis; ``seed`` picks the (deterministic) waveform."""

    amplitude_mm: float
    amplitude_deg: float = 0.0
    seed: int = 0


Segment = Line | Arc | Dwell
SOURCE_NAMES = ("A", "B", "C")  # the TOB's sources, in the order of the target model


@dataclass(frozen=True)
class Cover:
    """Part of source ``source`` (0 = A, 1 = B, 2 = C) hidden from scenario time ``start_s``
    until ``end_s`` (s from the start of the motion; ``math.inf``: to the end): the part of
    its disc beyond a straight edge, ``fraction`` of its area (1: all of it), the hidden side
    at ``angle_deg`` in the TOB plane (0: along the TOB's u axis)."""

    source: int
    fraction: float
    start_s: float
    end_s: float = math.inf
    angle_deg: float = 0.0
    line: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Scenario:
    """A start pose X (mm, deg) of the path frame, then segments. ``driver_mm``: the tip P
    in the TOB frame (eq. (9), tip frame parallel to the TOB's) or None; ``path``: whether
    the poses describe the TOB frame or the tip (needs a driver)."""

    start_x_mm_deg: tuple[float, float, float, float, float, float]
    segments: tuple[Segment, ...] = ()
    name: str = "scenario"
    driver_mm: Vec3 | None = None
    path: Literal["tob", "tip"] = "tob"
    tremor: Tremor | None = None
    covers: tuple[Cover, ...] = ()

    def __post_init__(self) -> None:
        _check_name(self.name)
        for c in self.covers:
            _check_cover(c)
        _check_finite("start", self.start_x_mm_deg, 6)
        if self.driver_mm is not None:
            _check_finite("driver", self.driver_mm, 3)
        if self.path not in ("tob", "tip"):
            raise ScenarioError(f"path must be 'tob' or 'tip', got {self.path!r}")
        if self.path == "tip" and self.driver_mm is None:
            raise ScenarioError("'path tip' needs a driver ('driver <x> <y> <z>')")
        if self.tremor is not None:
            t = self.tremor
            _check_finite("tremor", (t.amplitude_mm, t.amplitude_deg), 2)
            if t.amplitude_mm < 0 or t.amplitude_deg < 0:
                raise ScenarioError("tremor amplitudes must be >= 0")
            if not isinstance(t.seed, int) or t.seed < 0:
                raise ScenarioError(f"tremor seed must be an integer >= 0, got {t.seed!r}")
        for seg in self.segments:
            _check_segment(seg)

    @property
    def tob_T_tip(self) -> np.ndarray | None:
        """Eq. (9): (4, 4) mm, identity rotation, or None without a driver."""
        if self.driver_mm is None:
            return None
        return make_transform(np.eye(3), np.asarray(self.driver_mm, dtype=float))


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.\-]+", name):
        raise ScenarioError(
            f"a scenario name is one word of letters, digits, '_', '.', '-': {name!r}"
        )


def _check_finite(what: str, values, n: int, line: int = 0) -> None:
    vals = tuple(values)
    if len(vals) != n or not all(isinstance(v, int | float) and math.isfinite(v) for v in vals):
        raise ScenarioError(f"{what} needs {n} finite numbers, got {vals!r}", line)


def _check_cover(c: Cover) -> None:
    if c.source not in (0, 1, 2) or isinstance(c.source, bool):
        raise ScenarioError(f"cover: the source is A, B or C (0, 1, 2), got {c.source!r}", c.line)
    _check_finite("cover", (c.fraction, c.start_s, c.angle_deg), 3, c.line)
    if not 0.0 <= c.fraction <= 1.0:
        raise ScenarioError(f"cover: the fraction must be within 0 and 1, got {c.fraction!r}", c.line)
    if c.start_s < 0 or not (isinstance(c.end_s, int | float) and c.end_s > c.start_s):
        raise ScenarioError(f"cover: needs 0 <= from < to, got from {c.start_s!r} to {c.end_s!r}", c.line)


def _check_speeds(seg, line: int) -> None:
    for name in ("speed_mm_s", "angular_speed_deg_s"):
        v = getattr(seg, name)
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ScenarioError(
                f"{name.split('_mm')[0].split('_deg')[0]} must be > 0, got {v!r}", line
            )


def _check_segment(seg) -> None:
    if isinstance(seg, Line):
        _check_finite("line", seg.to_mm, 3, seg.line)
        if seg.ypr_deg is not None:
            _check_finite("line orientation", seg.ypr_deg, 3, seg.line)
        _check_speeds(seg, seg.line)
    elif isinstance(seg, Arc):
        _check_finite("arc centre", seg.centre_mm, 3, seg.line)
        _check_finite("arc angle", (seg.angle_deg,), 1, seg.line)
        _check_finite("arc axis", seg.axis, 3, seg.line)
        if math.hypot(*seg.axis) < 1e-9:
            raise ScenarioError("arc axis must not be zero", seg.line)
        if seg.orientation not in ("follow", "fixed"):
            raise ScenarioError(
                f"arc orientation must be 'follow' or 'fixed', got {seg.orientation!r}", seg.line
            )
        _check_speeds(seg, seg.line)
    elif isinstance(seg, Dwell):
        if not (
            isinstance(seg.duration_s, int | float)
            and math.isfinite(seg.duration_s)
            and seg.duration_s >= 0
        ):
            raise ScenarioError(f"dwell needs a duration >= 0 s, got {seg.duration_s!r}", seg.line)
    else:
        raise ScenarioError(f"not a segment: {seg!r}")


# --------------------------------------------------------------------------- file format

KEYWORDS = (
    "scenario",
    "driver",
    "path",
    "tremor",
    "start",
    "speed",
    "angular_speed",
    "line",
    "arc",
    "dwell",
    "cover",
)
_HEADER_KEYWORDS = ("scenario", "driver", "path", "tremor")


def _numbers(words: list[str], line: int, what: str) -> list[float]:
    out = []
    for w in words:
        try:
            v = float(w)
        except ValueError:
            raise ScenarioError(f"{what}: {w!r} is not a number", line) from None
        if not math.isfinite(v):
            raise ScenarioError(f"{what}: {w!r} is not a finite number", line)
        out.append(v)
    return out


def parse_scenario(text: str, source: str = "<scenario>") -> Scenario:
    """Parse the scenario text format (``README.md``); errors name ``source`` and the line."""
    name = "scenario"
    driver: Vec3 | None = None
    path = "tob"
    tremor: Tremor | None = None
    start: tuple | None = None
    speed, angular = DEFAULT_SPEED_MM_S, DEFAULT_ANGULAR_SPEED_DEG_S
    segments: list[Segment] = []
    covers: list[Cover] = []
    seen: dict[str, int] = {}
    path_line = 0
    try:
        for no, raw in enumerate(text.splitlines(), start=1):
            words = raw.split("#", 1)[0].split()
            if not words:
                continue
            key, args = words[0], words[1:]
            if key not in KEYWORDS:
                raise ScenarioError(
                    f"unknown keyword {key!r}; expected one of: {', '.join(KEYWORDS)}", no
                )
            if key in _HEADER_KEYWORDS + ("start",):
                if key in seen:
                    raise ScenarioError(f"{key!r} given twice (first on line {seen[key]})", no)
                seen[key] = no
                if key != "start" and start is not None:
                    raise ScenarioError(f"{key!r} must come before 'start'", no)
            if key == "scenario":
                if len(args) != 1:
                    raise ScenarioError("scenario: expected one name", no)
                try:
                    _check_name(args[0])
                except ScenarioError as e:
                    raise ScenarioError(e.reason, no) from None
                name = args[0]
            elif key == "driver":
                if args == ["none"]:
                    driver = None
                elif len(args) == 3:
                    driver = tuple(_numbers(args, no, "driver"))
                else:
                    raise ScenarioError(
                        "driver: expected 'none' or three numbers x y z (mm, TOB frame)", no
                    )
            elif key == "path":
                if args not in (["tob"], ["tip"]):
                    raise ScenarioError("path: expected 'tob' or 'tip'", no)
                path, path_line = args[0], no
            elif key == "tremor":
                if len(args) != 3:
                    raise ScenarioError("tremor: expected <mm> <deg> <seed>", no)
                amp_mm, amp_deg = _numbers(args[:2], no, "tremor")
                if amp_mm < 0 or amp_deg < 0:
                    raise ScenarioError("tremor: amplitudes must be >= 0", no)
                if not re.fullmatch(r"\d+", args[2]):
                    raise ScenarioError(f"tremor: seed {args[2]!r} is not an integer >= 0", no)
                tremor = Tremor(amp_mm, amp_deg, int(args[2]))
            elif key == "start":
                if len(args) != 6:
                    raise ScenarioError(
                        f"start: expected 6 numbers x y z psi theta phi, got {len(args)}", no
                    )
                start = tuple(_numbers(args, no, "start"))
            elif key == "cover":
                covers.append(_parse_cover(args, no))
            elif key in ("speed", "angular_speed"):
                if len(args) != 1:
                    raise ScenarioError(f"{key}: expected one number", no)
                (v,) = _numbers(args, no, key)
                if v <= 0:
                    raise ScenarioError(f"{key}: must be > 0, got {args[0]}", no)
                if key == "speed":
                    speed = v
                else:
                    angular = v
            else:  # motion
                if start is None:
                    raise ScenarioError(f"{key!r} before 'start': the first pose is unknown", no)
                if key == "line":
                    if len(args) not in (3, 6):
                        raise ScenarioError(f"line: expected 3 or 6 numbers, got {len(args)}", no)
                    v = _numbers(args, no, "line")
                    segments.append(
                        Line(
                            tuple(v[:3]), tuple(v[3:]) if len(v) == 6 else None, speed, angular, no
                        )
                    )
                elif key == "arc":
                    segments.append(_parse_arc(args, no, speed, angular))
                else:
                    if len(args) != 1:
                        raise ScenarioError("dwell: expected one number (s)", no)
                    (v,) = _numbers(args, no, "dwell")
                    if v < 0:
                        raise ScenarioError(f"dwell: duration must be >= 0 s, got {args[0]}", no)
                    segments.append(Dwell(v, no))
        if start is None:
            raise ScenarioError("no 'start' line: a scenario needs its first pose")
        if path == "tip" and driver is None:
            raise ScenarioError("'path tip' needs a driver ('driver <x> <y> <z>')", path_line)
        return Scenario(start, tuple(segments), name, driver, path, tremor, tuple(covers))
    except ScenarioError as e:
        raise ScenarioError(e.reason, e.line, source) from None


def _parse_arc(args: list[str], no: int, speed: float, angular: float) -> Arc:
    usage = "arc: expected <cx> <cy> <cz> <angle> [axis <ax> <ay> <az>] [follow|fixed]"
    orientation = "follow"
    if args and args[-1] in ("follow", "fixed"):
        orientation = args[-1]
        args = args[:-1]
    axis = (0.0, 0.0, 1.0)
    if len(args) == 8 and args[4] == "axis":
        axis = tuple(_numbers(args[5:], no, "arc axis"))
        if math.hypot(*axis) < 1e-9:
            raise ScenarioError("arc: the axis must not be zero", no)
        args = args[:4]
    if len(args) != 4:
        raise ScenarioError(usage, no)
    v = _numbers(args, no, "arc")
    return Arc(tuple(v[:3]), v[3], axis, orientation, speed, angular, no)


def _parse_cover(args: list[str], no: int) -> Cover:
    usage = "cover: expected <A|B|C> <fraction 0..1> from <s> [to <s>] [angle <deg>]"
    if len(args) < 4 or args[2] != "from":
        raise ScenarioError(usage, no)
    if args[0] not in SOURCE_NAMES:
        raise ScenarioError(f"cover: the source is A, B or C, got {args[0]!r}", no)
    (fraction,) = _numbers(args[1:2], no, "cover fraction")
    (start_s,) = _numbers(args[3:4], no, "cover from")
    end_s, angle = math.inf, 0.0
    rest = args[4:]
    while rest:
        if len(rest) < 2 or rest[0] not in ("to", "angle"):
            raise ScenarioError(usage, no)
        (v,) = _numbers(rest[1:2], no, f"cover {rest[0]}")
        if rest[0] == "to":
            end_s = v
        else:
            angle = v
        rest = rest[2:]
    c = Cover(SOURCE_NAMES.index(args[0]), fraction, start_s, end_s, angle, no)
    _check_cover(c)
    return c


def _num(v: float) -> str:
    """Shortest text that reads back as the same float."""
    text = repr(float(v))
    return text[:-2] if text.endswith(".0") else text


def format_scenario(scenario: Scenario) -> str:
    """The text form of a scenario; ``parse_scenario(format_scenario(s)) == s``."""
    s = scenario
    out = [
        "# humanpt scenario (mm, deg, s; see components/operator/README.md)",
        f"scenario {s.name}",
    ]
    out.append(
        "driver none" if s.driver_mm is None else "driver " + " ".join(map(_num, s.driver_mm))
    )
    out.append(f"path {s.path}")
    if s.tremor is not None:
        t = s.tremor
        out.append(f"tremor {_num(t.amplitude_mm)} {_num(t.amplitude_deg)} {t.seed}")
    out.append("start " + " ".join(map(_num, s.start_x_mm_deg)))
    speed, angular = DEFAULT_SPEED_MM_S, DEFAULT_ANGULAR_SPEED_DEG_S
    for seg in s.segments:
        if isinstance(seg, Line | Arc):
            if seg.speed_mm_s != speed:
                speed = seg.speed_mm_s
                out.append(f"speed {_num(speed)}")
            if seg.angular_speed_deg_s != angular:
                angular = seg.angular_speed_deg_s
                out.append(f"angular_speed {_num(angular)}")
        if isinstance(seg, Line):
            words = list(seg.to_mm) + (list(seg.ypr_deg) if seg.ypr_deg is not None else [])
            out.append("line " + " ".join(map(_num, words)))
        elif isinstance(seg, Arc):
            text = "arc " + " ".join(map(_num, (*seg.centre_mm, seg.angle_deg)))
            if tuple(seg.axis) != (0.0, 0.0, 1.0):
                text += " axis " + " ".join(map(_num, seg.axis))
            if seg.orientation != "follow":
                text += " " + seg.orientation
            out.append(text)
        else:
            out.append(f"dwell {_num(seg.duration_s)}")
    for c in s.covers:
        text = f"cover {SOURCE_NAMES[c.source]} {_num(c.fraction)} from {_num(c.start_s)}"
        if c.end_s != math.inf:
            text += f" to {_num(c.end_s)}"
        if c.angle_deg:
            text += f" angle {_num(c.angle_deg)}"
        out.append(text)
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------- motion


class TremorModel:
    """Deterministic hand tremor: per axis a sum of sines - physiological tremor (8-12 Hz)
    and slow drift (0.2-1.5 Hz) - with seeded frequencies and phases, scaled to the RMS
    amplitudes. A pure function of time, so it can be evaluated at any t. ``stream``
    separates independent waveforms of one seed (a scenario's own tremor: 7)."""

    def __init__(self, tremor: Tremor, stream: int = 7):
        rng = np.random.default_rng([tremor.seed, stream])
        freqs = np.concatenate(
            [rng.uniform(8.0, 12.0, (6, 3)), rng.uniform(0.2, 1.5, (6, 3))], axis=1
        )
        weights = np.concatenate([np.full((6, 3), 0.6), np.full((6, 3), 1.0)], axis=1)
        rms = np.sqrt(np.sum(weights**2, axis=1, keepdims=True) / 2.0)
        scale = np.array([tremor.amplitude_mm] * 3 + [math.radians(tremor.amplitude_deg)] * 3)
        self.amplitude = weights / rms * scale[:, None]  # (6 channels, 6 sines)
        self.omega = 2.0 * math.pi * freqs
        self.phase = rng.uniform(0.0, 2.0 * math.pi, (6, 6))

    def offset(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(translation (3,) mm, rotation vector (3,) rad) at ``t_s``."""
        v = np.sum(self.amplitude * np.sin(self.omega * t_s + self.phase), axis=1)
        return v[:3], v[3:]


@dataclass(frozen=True)
class _Piece:
    t0_s: float
    duration_s: float
    seg: Segment
    start: np.ndarray  # (4, 4) path-frame pose at the start of the piece, mm
    end: np.ndarray


def _rotation_angle_deg(r0: np.ndarray, r1: np.ndarray) -> float:
    return math.degrees(rotation_angle_rad(r0.T @ r1))


def _arc_pose(seg: Arc, start: np.ndarray, fraction: float) -> np.ndarray:
    axis = np.asarray(seg.axis, dtype=float)
    rot = matrix_from_rotvec(axis / np.linalg.norm(axis) * math.radians(seg.angle_deg) * fraction)
    centre = np.asarray(seg.centre_mm, dtype=float)
    out = np.eye(4)
    out[:3, 3] = centre + rot @ (start[:3, 3] - centre)
    out[:3, :3] = rot @ start[:3, :3] if seg.orientation == "follow" else start[:3, :3]
    return out


class Trajectory:
    """A scenario in time. ``duration_s`` is when the last segment ends; afterwards the
    target holds the final pose. :meth:`pose` gives world_T_tob and world_T_tip."""

    def __init__(self, scenario: Scenario, hand_tremor: TremorModel | None = None):
        self.scenario = scenario
        self.hand_tremor = hand_tremor  # the operator's own, on top of the scenario's
        self.tob_T_tip = scenario.tob_T_tip
        self.tip_T_tob = None if self.tob_T_tip is None else invert_transform(self.tob_T_tip)
        self.tremor = None if scenario.tremor is None else TremorModel(scenario.tremor)
        pose = transform_from_x(np.asarray(scenario.start_x_mm_deg, dtype=float))
        self.start_pose = pose
        t = 0.0
        pieces = []
        for seg in scenario.segments:
            duration, end = self._segment(seg, pose)
            pieces.append(_Piece(t, duration, seg, pose, end))
            t += duration
            pose = end
        self.pieces = pieces
        self.starts = np.array([p.t0_s for p in pieces])
        self.duration_s = t
        self.end_pose = pose

    @staticmethod
    def _segment(seg: Segment, start: np.ndarray) -> tuple[float, np.ndarray]:
        if isinstance(seg, Dwell):
            return float(seg.duration_s), start
        if isinstance(seg, Line):
            end = np.eye(4)
            end[:3, 3] = seg.to_mm
            if seg.ypr_deg is None:
                end[:3, :3] = start[:3, :3]
            else:
                end[:3, :3] = transform_from_x(np.array([0, 0, 0, *seg.ypr_deg], dtype=float))[
                    :3, :3
                ]
            distance = float(np.linalg.norm(end[:3, 3] - start[:3, 3]))
            angle = _rotation_angle_deg(start[:3, :3], end[:3, :3])
            return max(distance / seg.speed_mm_s, angle / seg.angular_speed_deg_s), end
        axis = np.asarray(seg.axis, dtype=float)
        axis = axis / np.linalg.norm(axis)
        rel = start[:3, 3] - np.asarray(seg.centre_mm, dtype=float)
        radius = float(np.linalg.norm(rel - np.dot(rel, axis) * axis))
        sweep = abs(seg.angle_deg)
        duration = radius * math.radians(sweep) / seg.speed_mm_s
        if seg.orientation == "follow":
            duration = max(duration, sweep / seg.angular_speed_deg_s)
        return duration, _arc_pose(seg, start, 1.0)

    def cover(self, t_s: float) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """(hidden fraction of A, B, C; angle of each one's hidden side, deg) at scenario time
        ``t_s``, or None when the scenario has no covers (several covers of one source at
        once: the largest fraction counts)."""
        covers = self.scenario.covers
        if not covers:
            return None
        fraction = [0.0, 0.0, 0.0]
        angle = [0.0, 0.0, 0.0]
        for c in covers:
            if c.start_s <= t_s < c.end_s and c.fraction > fraction[c.source]:
                fraction[c.source], angle[c.source] = float(c.fraction), float(c.angle_deg)
        return tuple(fraction), tuple(angle)

    def path_pose(self, t_s: float) -> np.ndarray:
        """Path-frame pose (4, 4), mm, at scenario time ``t_s`` (no tremor)."""
        if not self.pieces or t_s <= 0.0:
            return (self.pieces[0].start if self.pieces else self.start_pose).copy()
        if t_s >= self.duration_s:
            return self.end_pose.copy()
        i = int(np.searchsorted(self.starts, t_s, side="right")) - 1
        piece = self.pieces[max(i, 0)]
        f = (
            1.0
            if piece.duration_s <= 0
            else min(max((t_s - piece.t0_s) / piece.duration_s, 0.0), 1.0)
        )
        seg = piece.seg
        if isinstance(seg, Dwell):
            return piece.start.copy()
        if isinstance(seg, Arc):
            return _arc_pose(seg, piece.start, f)
        return interpolate_transform(piece.start, piece.end, f, assume_valid=True)

    def pose(
        self, t_s: float, tremor_t_s: float | None = None
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """(world_T_tob, world_T_tip or None), (4, 4) mm, at scenario time ``t_s``; the
        tremor (if any) is evaluated at ``tremor_t_s`` (default ``t_s``)."""
        path = self.path_pose(t_s)
        for tremor in (self.tremor, self.hand_tremor):
            if tremor is not None:
                d_p, d_r = tremor.offset(t_s if tremor_t_s is None else tremor_t_s)
                path = apply_step(path, d_p, d_r)
        if self.scenario.path == "tip":
            return path @ self.tip_T_tob, path
        tip = None if self.tob_T_tip is None else path @ self.tob_T_tip
        return path, tip


# --------------------------------------------------------------------------- built-ins

BUILTIN_SCENARIOS = ("static", "arc", "trapezium", "freehand", "scurve", "abrupt", "occluded", "partial")
NEEDLE_MM = (0.0, 0.0, 60.0)  # the default TOB's needle (humanpt.geometry.TargetModel)


def _static() -> Scenario:
    return Scenario(TABLE1_X_MM_DEG, (), "static")


def _arc(speed_mm_s: float) -> Scenario:
    """The paper's rotating base (Section 6, Fig. 8): the TOB on a base of radius 246 mm
    about (147.5, 1378.5, 448.0) mm turns from index angle +50 to -50 deg. The index angle
    is measured about world z from the -y direction (towards the robot); the TOB faces up
    and turns with the base."""
    beta = math.radians(50.0)
    cx, cy, cz = ARC_CENTRE_MM
    start = (
        cx + ARC_RADIUS_MM * math.sin(beta),
        cy - ARC_RADIUS_MM * math.cos(beta),
        cz,
        50.0,
        0.0,
        FACE_UP_ROLL_DEG,
    )
    return Scenario(
        tuple(round(v, 6) for v in start),
        (Arc(ARC_CENTRE_MM, -100.0, speed_mm_s=speed_mm_s, angular_speed_deg_s=60.0), Dwell(1.0)),
        "arc",
    )


def _trapezium(speed_mm_s: float, torch_angle_deg: float = 15.0) -> Scenario:
    """The trapezium seam (Section 6, Fig. 9): b1 = 451 mm, b2 = 361 mm, h = 45 mm, on a
    table at z = 0 centred under the Table 1 position; the needle tip runs once round the
    edges at a constant torch angle (the TOB tilted by ``torch_angle_deg`` about world y)."""
    b1, b2, h = 451.0, 361.0, 45.0
    x0, y0 = round(TABLE1_X_MM_DEG[0], 3), round(TABLE1_X_MM_DEG[1], 3)
    corners = [
        (round(x, 3), round(y, 3))
        for x, y in (
            (x0 - b1 / 2, y0 - h / 2),
            (x0 + b1 / 2, y0 - h / 2),
            (x0 + b2 / 2, y0 + h / 2),
            (x0 - b2 / 2, y0 + h / 2),
            (x0 - b1 / 2, y0 - h / 2),
        )
    ]
    ypr = (0.0, torch_angle_deg, FACE_UP_ROLL_DEG)
    segs: list[Segment] = [Line((x, y, 0.0), None, speed_mm_s) for x, y in corners[1:]]
    segs.append(Dwell(1.0))
    return Scenario((*corners[0], 0.0, *ypr), tuple(segs), "trapezium", NEEDLE_MM, "tip")


def _freehand(speed_mm_s: float, seed: int) -> Scenario:
    """A hand-drawn seam: a smooth, seeded wavy curve (400 mm along x, +-40 mm in y,
    +-4 mm in z) on the table at z = 0, traced by the needle tip at a varying speed
    (+-30 %) with a wobbling torch (+-3 deg) and human tremor (0.2 mm, 0.3 deg RMS)."""
    rng = np.random.default_rng([seed, 11])
    amp = rng.uniform([15, 5, 1.5], [25, 12, 2.5])
    wavelength = rng.uniform([350, 120, 200], [500, 200, 300])
    phase = rng.uniform(0, 2 * math.pi, 3)
    x0, y0 = round(TABLE1_X_MM_DEG[0], 3), round(TABLE1_X_MM_DEG[1], 3)
    xs = np.arange(-200.0, 200.0 + 1e-9, 10.0)
    y = amp[0] * np.sin(2 * math.pi * xs / wavelength[0] + phase[0]) + amp[1] * np.sin(
        2 * math.pi * xs / wavelength[1] + phase[1]
    )
    z = amp[2] * np.sin(2 * math.pi * xs / wavelength[2] + phase[2])
    wobble = rng.uniform(0, 2 * math.pi, 3)
    speed_wobble = rng.uniform(0, 2 * math.pi)

    def ypr(x: float) -> tuple[float, float, float]:
        return (
            round(3.0 * math.sin(x / 90.0 + wobble[0]), 3),
            round(10.0 + 3.0 * math.sin(x / 70.0 + wobble[1]), 3),
            round(FACE_UP_ROLL_DEG + 2.0 * math.sin(x / 110.0 + wobble[2]), 3),
        )

    points = [
        (round(x0 + x, 3), round(y0 + yy, 3), round(zz, 3))
        for x, yy, zz in zip(xs, y, z, strict=True)
    ]
    segs: list[Segment] = []
    for x, p in zip(xs[1:], points[1:], strict=True):
        v = round(speed_mm_s * (1.0 + 0.3 * math.sin(x / 60.0 + speed_wobble)), 3)
        segs.append(Line(p, ypr(x), v))
    segs.append(Dwell(1.0))
    start = (*points[0], *ypr(xs[0]))
    return Scenario(start, tuple(segs), "freehand", NEEDLE_MM, "tip", Tremor(0.2, 0.3, seed))


def _table_point(dx_mm: float, dy_mm: float) -> tuple[float, float, float]:
    """A point on the table (z = 0) offset from under the Table 1 position, mm."""
    return (round(TABLE1_X_MM_DEG[0] + dx_mm, 3), round(TABLE1_X_MM_DEG[1] + dy_mm, 3), 0.0)


TORCH_YPR_DEG = (0.0, 15.0, FACE_UP_ROLL_DEG)  # the trapezium's torch: tilted 15 deg, face up


def _scurve(speed_mm_s: float) -> Scenario:
    """An S-curve with a sharp corner and a dwell (issue 18): two quarter arcs of radius
    60 mm in opposite senses with the torch following (its turning rate steps from
    +v/r to -v/r between them), a straight run, a sharp 90 deg corner (a velocity step),
    a 1 s dwell, then another 90 deg corner and a run; tip path at the trapezium's torch
    angle."""
    r = 60.0
    x, y = -120.0, -60.0
    segs: list[Segment] = [
        Arc(_table_point(x, y + r), 90.0, speed_mm_s=speed_mm_s, angular_speed_deg_s=90.0),
        Arc(_table_point(x + 2 * r, y + r), -90.0, speed_mm_s=speed_mm_s, angular_speed_deg_s=90.0),
        Line(_table_point(x + 2 * r + 60, y + 2 * r), None, speed_mm_s),
        Line(_table_point(x + 2 * r + 60, y + 2 * r - 60), None, speed_mm_s),
        Dwell(1.0),
        Line(_table_point(x + 2 * r + 120, y + 2 * r - 60), None, speed_mm_s),
        Dwell(1.0),
    ]
    return Scenario((*_table_point(x, y), *TORCH_YPR_DEG), tuple(segs), "scurve", NEEDLE_MM, "tip")


def _abrupt(speed_mm_s: float) -> Scenario:
    """Abrupt motion (issue 18): an instant start at full speed, an instant stop, a
    reversal, a quick torch turn on the spot (25 deg at 45 deg/s), a slow run then an
    instant speed step to three times it while the torch turns back; tip path."""
    v = speed_mm_s
    yaw25 = (25.0, TORCH_YPR_DEG[1], TORCH_YPR_DEG[2])
    segs: list[Segment] = [
        Line(_table_point(0.0, 0.0), None, v),
        Dwell(0.5),
        Line(_table_point(-40.0, 0.0), None, v),
        Line(_table_point(-40.0, 0.0), yaw25, v, 45.0),
        Line(_table_point(-20.0, 20.0), None, v / 3),
        Line(_table_point(100.0, 20.0), TORCH_YPR_DEG, v, 45.0),
        Dwell(1.0),
    ]
    return Scenario((*_table_point(-100.0, 0.0), *TORCH_YPR_DEG), tuple(segs), "abrupt", NEEDLE_MM, "tip")


def _occluded(speed_mm_s: float) -> Scenario:
    """A straight seam 6 s long at any speed, source B hidden completely from 2 s to 4 s
    into the motion (issue 18: position-only tracking and recording); tip path."""
    half = 3.0 * speed_mm_s
    segs: list[Segment] = [Line(_table_point(half, 0.0), None, speed_mm_s), Dwell(1.0)]
    return Scenario((*_table_point(-half, 0.0), *TORCH_YPR_DEG), tuple(segs), "occluded", NEEDLE_MM, "tip",
                    covers=(Cover(1, 1.0, 2.0, 4.0),))


def _partial(speed_mm_s: float) -> Scenario:
    """A straight seam 5 s long at any speed, source A 30 % covered (the hidden side towards
    the TOB's +v) from 1 s into the motion to the end (issue 18: a partly covered source
    must be flagged, not trusted); tip path."""
    half = 2.5 * speed_mm_s
    segs: list[Segment] = [Line(_table_point(half, 0.0), None, speed_mm_s), Dwell(1.0)]
    return Scenario((*_table_point(-half, 0.0), *TORCH_YPR_DEG), tuple(segs), "partial", NEEDLE_MM, "tip",
                    covers=(Cover(0, 0.3, 1.0, math.inf, 90.0),))


def builtin_scenario(name: str, speed_mm_s: float = 0.0, seed: int = 0) -> Scenario:
    """One of :data:`BUILTIN_SCENARIOS`; ``speed_mm_s`` > 0 replaces the default speed
    (freehand 15 mm/s on average, the others 20 mm/s)."""
    if name == "static":
        return _static()
    if name == "arc":
        return _arc(speed_mm_s or DEFAULT_SPEED_MM_S)
    if name == "trapezium":
        return _trapezium(speed_mm_s or DEFAULT_SPEED_MM_S)
    if name == "freehand":
        return _freehand(speed_mm_s or 15.0, seed)
    hard = {"scurve": _scurve, "abrupt": _abrupt, "occluded": _occluded, "partial": _partial}
    if name in hard:
        return hard[name](speed_mm_s or DEFAULT_SPEED_MM_S)
    raise ScenarioError(f"no built-in scenario {name!r}; built in: {', '.join(BUILTIN_SCENARIOS)}")
