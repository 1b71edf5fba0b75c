"""A network partition between the cell's two machines, judged from the recordings (issue 19).

The server (router, robot_gateway, sim_robot) and the client (camera side and control) each
record what they consumed and produced; a partition is judged afterwards from those files
alone, against the times the link was cut and restored (wall-clock ns, the recordings' time
base):

- :func:`robot_track` - the flange position per ALTER cycle, from the gateway's own
  ``robot_gateway/robot_state`` outputs (what the robot reported);
- :func:`holds` - per partition: how far the robot moved after the cut, when it stood still
  (and stayed still up to the restore), how long the hold lasted and when it moved again;
- :func:`late_commands` - commands that reached the gateway after their cycle's reuse window
  (a partition's backlog) and whether any of them was acted on (a correction written in
  answer to it);
- :func:`output_gaps` - whether each recording keeps everything its component produced (the
  per-topic ``header.seq`` of its outputs counts up by one with no gap).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.runtime.recording import IN, OUT, iter_entries
from humanpt.schemas.convert import from_pose

ROBOT_STATE = "robot_gateway/robot_state"
COMMAND = "controller/command"


@dataclass(frozen=True)
class Hold:
    """What the robot did during one partition (times: wall-clock ns)."""

    cut_ns: int
    restore_ns: int
    moving_before_mm: float  # flange travel in the second before the cut
    moved_after_cut_mm: float  # flange travel from the cut to the start of the hold
    hold_from_ns: int | None  # first robot_state of the stillness that lasts to the restore
    resumed_ns: int | None  # first robot_state that moved after the restore

    @property
    def onset_ms(self) -> float | None:
        """Cut -> robot still, ms."""
        return None if self.hold_from_ns is None else (self.hold_from_ns - self.cut_ns) / 1e6

    @property
    def hold_s(self) -> float | None:
        """How long the robot held: still from the hold's start until it moved again (or
        until the restore, when it never moved again), s."""
        if self.hold_from_ns is None:
            return None
        end = self.resumed_ns if self.resumed_ns is not None else self.restore_ns
        return (end - self.hold_from_ns) / 1e9

    @property
    def resume_s(self) -> float | None:
        """Restore -> robot moving again, s."""
        return None if self.resumed_ns is None else (self.resumed_ns - self.restore_ns) / 1e9

    def line(self) -> str:
        part = (self.restore_ns - self.cut_ns) / 1e9
        onset = "never" if self.onset_ms is None else f"{self.onset_ms:.0f} ms"
        hold = "-" if self.hold_s is None else f"{self.hold_s:.2f} s"
        resume = "not within the run" if self.resume_s is None else f"{self.resume_s:.2f} s after the restore"
        return (f"partition {part:.1f} s: moving {self.moving_before_mm:.1f} mm/s before; "
                f"{self.moved_after_cut_mm:.2f} mm after the cut, still {onset} after it; "
                f"held {hold}; moved again {resume}")


def robot_track(gateway_mcap: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_ns (n,), cycle (n,), p_mm (n, 3)): each robot_state the gateway produced, at the
    time it produced it (its recording's t_ns), with the flange position in world mm."""
    t, c, p = [], [], []
    for e in iter_entries(gateway_mcap):
        if e.direction == OUT and e.topic == ROBOT_STATE:
            m = e.decode()
            t.append(e.t_ns)
            c.append(m.cycle)
            p.append(from_pose(m.world_T_flange)[:3, 3] * 1000.0)
    return np.array(t, dtype=np.int64), np.array(c, dtype=np.int64), np.array(p).reshape(-1, 3)


def holds(track: tuple[np.ndarray, np.ndarray, np.ndarray], cuts: list[tuple[int, int]],
          still_mm: float = 0.005) -> list[Hold]:
    """Per (cut_ns, restore_ns): the robot's motion around the partition. A cycle is still
    when the flange moved less than ``still_mm`` since the previous robot_state (the wire's
    resolution is 0.01 mm: a zero correction leaves the reported pose unchanged)."""
    t, _, p = track
    step = np.r_[np.inf, np.linalg.norm(np.diff(p, axis=0), axis=1)] if len(t) else np.array([])
    out = []
    for cut, restore in cuts:
        before = (t >= cut - 1_000_000_000) & (t <= cut)
        moving = float(step[before][1:].sum()) if before.sum() > 1 else 0.0
        i_cut = int(np.searchsorted(t, cut))
        i_restore = int(np.searchsorted(t, restore))
        hold_from = None
        # the earliest index from which every state up to the restore is still
        j = i_restore
        while j > i_cut and step[j - 1] < still_mm:
            j -= 1
        if j < i_restore:
            hold_from = j
        moved = (float(np.linalg.norm(p[hold_from] - p[max(i_cut - 1, 0)]))
                 if hold_from is not None and len(p) else float("nan"))
        later = np.nonzero(step[i_restore:] >= still_mm)[0]
        resumed = int(t[i_restore + later[0]]) if len(later) else None
        out.append(Hold(cut, restore, moving, moved, None if hold_from is None else int(t[hold_from]), resumed))
    return out


def _cycles_after(a: int, b: int) -> int:
    d = (a - b) % (1 << 32)
    return d - (1 << 32) if d >= 1 << 31 else d


def late_commands(gateway_mcap: str | Path, stale_cycles: int) -> tuple[int, int]:
    """(late, acted on): commands the gateway consumed more than ``stale_cycles`` cycles
    after their cycle (its last robot_state's cycle at the time), and how many of them a
    correction (``serial_tx``) answered in the same step."""
    late = acted = 0
    k = None
    current_late = False
    for e in iter_entries(gateway_mcap):
        if e.direction == IN:
            current_late = False
            if e.topic == COMMAND and k is not None:
                c = e.decode().cycle
                if _cycles_after(c, k) < -stale_cycles:
                    late += 1
                    current_late = True
        elif e.direction == OUT:
            if e.topic == ROBOT_STATE:
                k = e.decode().cycle
            elif e.topic == "serial_tx" and current_late:
                acted += 1
                current_late = False
    return late, acted


def output_gaps(mcap: str | Path) -> dict[str, str]:
    """Topics whose outputs' ``header.seq`` in this recording does not count 0, 1, 2...
    with no gap: topic -> what is wrong. Empty: the recording keeps all it produced.
    (humanpt messages only: a foxglove image carries no sequence number.)"""
    seqs: dict[str, list[int]] = defaultdict(list)
    for e in iter_entries(mcap):
        if e.direction == OUT and "/" in e.topic and e.schema.startswith("humanpt."):
            seqs[e.topic].append(e.decode().header.seq)
    bad = {}
    for topic, s in seqs.items():
        a = np.asarray(s, dtype=np.int64)
        if a[0] != 0 or np.any(np.diff(a) != 1):
            holes = int(np.sum(np.clip(np.diff(a) - 1, 0, None)))
            bad[topic] = f"seq from {a[0]} to {a[-1]} in {len(a)} messages ({holes} missing)"
    return bad
