"""A path against the seam (issue 21.4, 32.2): ``humanpt path compare SEAM RUN``, and the
twin job's table (``humanpt demo --calibrate``: the taught points, the fitted seam and
the played-back torch, each against the seam, by :func:`compare_points`).

The tool's actual path is read from a run's recordings: every ``robot_gateway/robot_state``
the robot reported (``world_T_flange``, metres on the bus) converted to mm
(:mod:`humanpt.geometry.units`) times the controller's ``flange_T_tool`` (mm, from the
controller's recorded configuration), between the controller's last ``playback_started``
and the ``playback_done`` after it (the whole run if there was none).

The report: each point's distance to the seam (RMS, 95th percentile, max and where), and
how much of the seam the path covered.  Coverage is measured along the seam: each point
within ``cover_mm`` of the seam is placed at the arc length of its nearest seam point
(the seam sampled every 0.1 mm); two consecutive such points cover the stretch between
their places when it is at most ``gap_mm`` long (a longer one is a jump or a hole in the
recording, not a pass along the seam).  ``covered`` is the covered share of the seam's
length; the largest stretch left uncovered, the seam's start and end included (a path
that begins 5 mm into the seam leaves [0, 5] mm uncovered), is reported with where it
lies.  Points before the path first comes within ``approach_mm`` of the seam's start
(the approach from where the robot was) do not count.  This is the robot's own account
of where it was; on the twin ``humanpt.twin`` also has the truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.geometry.transforms import transform_from_x
from humanpt.geometry.units import to_mm
from humanpt.runtime.recording import RecordingError, iter_entries, read_metadata
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose
from humanpt.seam.fit import FitConfig, Seam, Segment, distance_to_seam, sample_segment

__all__ = ["Played", "Comparison", "played_tool_path", "compare", "compare_points", "seam_samples", "polyline_seam"]


@dataclass(frozen=True)
class Played:
    stamp_ns: np.ndarray  # (N,)
    tool_mm: np.ndarray  # (N, 3) the tool's position in the world frame
    window: str  # which part of the run: "playback 2 (started at 12.3 s, done)" or "whole run"


@dataclass(frozen=True)
class Comparison:
    n: int  # points compared (after the approach)
    rms_mm: float
    mean_mm: float
    p95_mm: float
    max_mm: float
    worst_mm: tuple[float, float, float]  # where the largest distance is (the point, world mm)
    covered: float  # share of the seam's length covered (0..1)
    largest_gap_mm: float  # the longest stretch of the seam left uncovered (its start and end included)
    gap_from_mm: float  # ... from this arc length along the seam
    gap_to_mm: float  # ... to this one
    length_mm: float  # the seam's length
    cover_mm: float
    gap_mm: float
    window: str

    def row(self) -> list[str]:
        """RMS, max, coverage and the largest uncovered stretch as printed (mm, %)."""
        return [f"{self.rms_mm:.3f}", f"{self.max_mm:.3f}", f"{100 * self.covered:.1f}",
                f"{self.largest_gap_mm:.1f} ({self.gap_from_mm:.1f}-{self.gap_to_mm:.1f})"]


ROW_HEADER = ["RMS mm", "max mm", "covered %", "largest gap mm (from-to along the seam)"]
SAMPLE_MM = 0.1  # the seam's sampling for placing points along it
# Consecutive points farther apart along the seam than this do not cover the stretch
# between them: a robot state comes every 4-28 ms (at most 2.8 mm at 100 mm/s); a taught
# point at least every few mm (issue 32.3).
GAP_MM = 10.0


def played_tool_path(run_dir: str | Path) -> Played:
    """The tool's reported path during the run's last playback (see the module doc);
    RecordingError when the run has no controller recording or no robot states."""
    run = Path(run_dir)
    ctl = run / "controller.mcap"
    if not ctl.exists():
        raise RecordingError(f"{run}: no controller.mcap (the controller's recording gives the tool and the "
                             "playback's start and end)")
    meta, _ = read_metadata(ctl)
    try:
        tool_x = json.loads(meta.get("config", "{}"))["flange_T_tool_x"]
    except (KeyError, ValueError, TypeError):
        raise RecordingError(f"{ctl}: no flange_T_tool_x in the controller's recorded configuration") from None
    flange_T_tool_mm = transform_from_x(np.asarray(tool_x, dtype=float))
    starts, dones = [], []
    for e in iter_entries(ctl):
        if e.direction == "out" and e.topic == "controller/events":
            ev = e.decode()
            if ev.code == "playback_started":
                starts.append(ev.header.stamp_ns)
            elif ev.code == "playback_done":
                dones.append(ev.header.stamp_ns)
    states: list[tuple[int, np.ndarray]] = []
    for f in sorted(run.glob("*.mcap")):
        for e in iter_entries(f):
            if e.direction == "out" and e.topic == "robot_gateway/robot_state":
                msg: pb.RobotState = e.decode()
                states.append((msg.header.stamp_ns, from_pose(msg.world_T_flange)))  # metres
    if not states:
        raise RecordingError(f"{run}: no robot state was recorded (robot_gateway/robot_state)")
    states.sort(key=lambda s: s[0])
    t = np.array([s for s, _ in states], dtype=np.int64)
    lo, hi, window = t[0], t[-1], "whole run (no playback_started event)"
    if starts:
        lo = starts[-1]
        after = [d for d in dones if d >= lo]
        hi = after[0] if after else t[-1]
        window = (f"playback {len(starts)} (from {(lo - t[0]) / 1e9:.1f} s into the run, "
                  f"{'done' if after else 'not done'})")
    keep = (t >= lo) & (t <= hi)
    world_T_flange_mm = to_mm(np.array([T for (_, T), k in zip(states, keep, strict=True) if k]).reshape(-1, 4, 4))
    tool = (world_T_flange_mm @ flange_T_tool_mm)[:, :3, 3]
    return Played(t[keep], tool.reshape(-1, 3), window)


def polyline_seam(points_mm: np.ndarray) -> Seam:
    """A seam of straight lines through (K, 3) points in order (mm; repeated points
    dropped): a seam known as a dense polyline (the twin's seam as designed) to compare
    against."""
    p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-9]
    p = p[keep]
    if len(p) < 2:
        raise ValueError("a seam needs two distinct points")
    ypr = (0.0, 0.0, 0.0)
    segs = tuple(Segment("line", i, i + 1, tuple(map(float, a)), tuple(map(float, b)), ypr, ypr, 0.0, 0.0, 2)
                 for i, (a, b) in enumerate(zip(p[:-1], p[1:], strict=True)))
    return Seam(segs, (), (), (), 0.0, FitConfig(), len(p))


def compare(seam: Seam, played: Played, cover_mm: float = 1.0, approach_mm: float = 0.25,
            gap_mm: float = GAP_MM) -> Comparison:
    """The played path against the seam (:func:`compare_points`)."""
    return compare_points(seam, played.tool_mm, cover_mm, approach_mm, gap_mm, played.window)


def seam_samples(seam: Seam, step_mm: float = SAMPLE_MM) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) points along the seam at most ``step_mm`` apart, ends included, and (K,) the
    arc length of each from the seam's start (mm; between segments the seam's own gap,
    if any, is not counted)."""
    pts, arc = [], []
    s0 = 0.0
    for seg in seam.segments:
        p = sample_segment(seg, step_mm)
        f = np.linspace(0.0, 1.0, len(p))
        pts.append(p)
        arc.append(s0 + f * seg.length_mm)
        s0 += seg.length_mm
    return np.vstack(pts), np.concatenate(arc)


def compare_points(seam: Seam, points_mm: np.ndarray, cover_mm: float = 1.0, approach_mm: float | None = 0.25,
                   gap_mm: float = GAP_MM, window: str = "points") -> Comparison:
    """(N, 3) points in order along their path against the seam (see the module doc):
    distances to the seam, coverage along it.  ``approach_mm`` None: every point counts.
    ValueError when no point is left to compare."""
    if not (cover_mm > 0 and gap_mm > 0):
        raise ValueError(f"cover_mm and gap_mm must be > 0, got {cover_mm!r}, {gap_mm!r}")
    p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    if approach_mm is not None and len(p):
        start = np.array(seam.segments[0].start_mm)
        near = np.flatnonzero(np.linalg.norm(p - start, axis=1) < approach_mm)
        p = p[near[0]:] if len(near) else p
    if len(p) == 0:
        raise ValueError(f"no points to compare in {window}")
    d = distance_to_seam(seam, p)
    samples, arc = seam_samples(seam)
    length = float(arc[-1])
    from scipy.spatial import cKDTree

    s = arc[cKDTree(samples).query(p)[1]]
    on = d <= cover_mm
    pair = on[:-1] & on[1:] & (np.abs(np.diff(s)) <= gap_mm)
    lo, hi = np.minimum(s[:-1], s[1:])[pair], np.maximum(s[:-1], s[1:])[pair]
    covered_mm, gaps = _union(lo, hi, length)
    g = max(gaps, key=lambda ab: ab[1] - ab[0]) if gaps else (0.0, 0.0)
    worst = int(np.argmax(d))
    return Comparison(len(d), float(np.sqrt(np.mean(d ** 2))), float(d.mean()), float(np.percentile(d, 95)),
                      float(d[worst]),
                      tuple(float(v) for v in p[worst]), covered_mm / length if length > 0 else 0.0,
                      g[1] - g[0], g[0], g[1], length, cover_mm, gap_mm, window)


def _union(lo: np.ndarray, hi: np.ndarray, length: float) -> tuple[float, list[tuple[float, float]]]:
    """The length of the union of the intervals [lo_i, hi_i] within [0, length], and the
    stretches of [0, length] outside it (the start's and the end's included)."""
    merged: list[list[float]] = []
    for a, b in sorted(zip(np.clip(lo, 0, length).tolist(), np.clip(hi, 0, length).tolist(), strict=True)):
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    edges = [0.0] + [v for ab in merged for v in ab] + [length]
    gaps = [(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True) if b > a]
    return sum(b - a for a, b in merged), gaps
