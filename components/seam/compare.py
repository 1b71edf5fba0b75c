"""What the robot played against the seam (issue 21.4): ``humanpt path compare SEAM RUN``.

The tool's actual path is read from a run's recordings: every ``robot_gateway/robot_state``
the robot reported (``world_T_flange``) times the controller's ``flange_T_tool`` (from the
controller's recorded configuration), between the controller's last ``playback_started``
and the ``playback_done`` after it (the whole run if there was none).  The report: each
played point's distance to the seam (RMS, 95th percentile, max), and how much of the seam
the tool covered (the share of the seam, sampled every mm, within ``cover_mm`` of the
played path).  This is the robot's own account of where it was; on the twin
``humanpt.twin`` also has the truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.geometry.transforms import transform_from_x
from humanpt.runtime.recording import RecordingError, iter_entries, read_metadata
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose
from humanpt.seam.fit import Seam, distance_to_seam, sample_segment

__all__ = ["Played", "Comparison", "played_tool_path", "compare"]


@dataclass(frozen=True)
class Played:
    stamp_ns: np.ndarray  # (N,)
    tool_mm: np.ndarray  # (N, 3) the tool's position in the world frame
    window: str  # which part of the run: "playback 2 (started at 12.3 s, done)" or "whole run"


@dataclass(frozen=True)
class Comparison:
    n: int
    rms_mm: float
    p95_mm: float
    max_mm: float
    covered: float  # share of the seam within cover_mm of the played path
    cover_mm: float
    window: str


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
    except (KeyError, ValueError):
        raise RecordingError(f"{ctl}: no flange_T_tool_x in the controller's recorded configuration") from None
    flange_T_tool = transform_from_x(np.asarray(tool_x, dtype=float))
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
                states.append((msg.header.stamp_ns, from_pose(msg.world_T_flange)))
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
    tool = np.array([(T @ flange_T_tool)[:3, 3] for (_, T), k in zip(states, keep, strict=True) if k])
    return Played(t[keep], tool.reshape(-1, 3), window)


def compare(seam: Seam, played: Played, cover_mm: float = 1.0, approach_mm: float = 0.25) -> Comparison:
    """The played path against the seam.  Played points before the tool first comes within
    ``approach_mm`` of the seam's start (the approach from where the robot was) do not count."""
    p = played.tool_mm
    if len(p) == 0:
        raise ValueError(f"no played points in {played.window}")
    start = np.array(seam.segments[0].start_mm)
    near = np.flatnonzero(np.linalg.norm(p - start, axis=1) < approach_mm)
    p = p[near[0]:] if len(near) else p
    d = distance_to_seam(seam, p)
    samples = np.vstack([sample_segment(s, 1.0) for s in seam.segments])
    # coverage: each seam sample's distance to the played polyline's points (dense: 28 ms apart)
    from scipy.spatial import cKDTree

    covered = float(np.mean(cKDTree(p).query(samples)[0] <= cover_mm))
    return Comparison(len(d), float(np.sqrt(np.mean(d ** 2))), float(np.percentile(d, 95)), float(d.max()),
                      covered, cover_mm, played.window)
