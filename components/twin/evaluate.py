"""Judging a run against ground truth: the servo's true error, the recorded path's error,
and the paper's error statistics (ME, MAE, MaxE, SD per coordinate of X).

Works on a lock-step :class:`~humanpt.twin.world.TwinWorld` or on a recorded run directory
(:class:`RunOutputs`): both give ``outputs(topic)`` and ``truths(topic)``.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.geometry.frames import SAMPLE_HOLD_HOLD, TimedPoses
from humanpt.geometry.transforms import rotation_angle_rad, x_from_transform
from humanpt.geometry.units import to_mm
from humanpt.runtime import tables
from humanpt.runtime.lockstep import Delivered
from humanpt.runtime.recording import iter_entries, read_metadata
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose
from humanpt.sim_camera.core import truth_poses

COORDS = ("x", "y", "z", "psi", "theta", "phi")


def truths_from(outputs: list[Delivered]) -> list[tuple[int, dict[str, np.ndarray]]]:
    """(stamp ns, {field: (4, 4) mm}) of Truth messages."""
    out = []
    for o in outputs:
        msg = pb.Truth.FromString(o.data)
        poses = {}
        for field in ("world_T_tob", "world_T_tip", "world_T_flange"):
            if msg.HasField(field):
                T = from_pose(getattr(msg, field))
                T[:3, 3] *= 1000.0
                poses[field] = T
        out.append((msg.header.stamp_ns, poses))
    return out


class RunOutputs:
    """Every component's outputs of a recorded run directory, in time order."""

    def __init__(self, run_dir: str | Path):
        self.run_dir = Path(run_dir)
        self.notes: list[str] = []
        self.metadata: dict[str, dict[str, str]] = {}
        streams = []
        for i, f in enumerate(sorted(self.run_dir.glob("*.mcap"))):
            meta, _ = read_metadata(f)
            comp = meta.get("component", f.stem)
            self.metadata[comp] = meta
            streams.append([(e.t_ns, i, e.index, Delivered(e.t_ns, comp, e.topic, e.data))
                            for e in iter_entries(f, self.notes) if e.direction == "out"])
        self._all = [d for *_, d in heapq.merge(*streams)]

    def outputs(self, topic: str | None = None) -> list[Delivered]:
        return [o for o in self._all if topic is None or o.topic == topic]

    def truths(self, topic: str = "sim_camera/truth") -> list[tuple[int, dict[str, np.ndarray]]]:
        return truths_from(self.outputs(topic))


def truth_track(src, field: str = "world_T_tob", topic: str = "operator/truth") -> TimedPoses:
    """A truth stream's true trajectory (the one the camera renders from: linear and
    geodesic between the stamped samples), mm."""
    track = truth_poses(maxlen=None)
    for stamp, poses in src.truths(topic):
        if field in poses:
            track.add(stamp, poses[field])
    return track


def truth_at(src, stamps_ns, field: str = "world_T_tob", topic: str = "operator/truth") -> np.ndarray:
    """(N, 4, 4) mm: a truth stream's trajectory at the stamps (interpolated between the
    samples around each stamp, never the nearest sample; held beyond the last one)."""
    track = truth_track(src, field, topic)
    return np.array([track.at(int(ts), SAMPLE_HOLD_HOLD) for ts in np.asarray(stamps_ns, dtype=np.int64)])


def tracking_errors(src, flange_T_desired_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True servo error per robot cycle: (stamps ns, |G - D| mm, angle(G, D) deg), from
    the robot's true flange (``sim_robot/truth``) and the operator's true target."""
    robot = src.truths("sim_robot/truth")
    stamps = np.array([s for s, _ in robot], dtype=np.int64)
    if not len(stamps):
        return stamps, np.zeros(0), np.zeros(0)
    tobs = truth_at(src, stamps)
    e_mm, e_deg = [], []
    for (_, r), G in zip(robot, tobs, strict=True):
        D = r["world_T_flange"] @ flange_T_desired_mm
        e_mm.append(np.linalg.norm(G[:3, 3] - D[:3, 3]))
        e_deg.append(np.degrees(rotation_angle_rad(G[:3, :3] @ D[:3, :3].T)))
    return stamps, np.array(e_mm), np.array(e_deg)


def _x(p: pb.Pose) -> np.ndarray:
    return x_from_transform(to_mm(from_pose(p)))


def path_points(src) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The recorded path: (stamps ns, X of G (N, 6) mm/deg, X of the tip or None)."""
    pts = [pb.PathPoint.FromString(o.data) for o in src.outputs("controller/path")]
    if not pts:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 6)), None
    stamps = np.array([p.header.stamp_ns for p in pts], dtype=np.int64)
    xg = np.array([_x(p.world_T_tob) for p in pts])
    xt = np.array([_x(p.world_T_tip) for p in pts]) if pts[0].has_tip else None
    return stamps, xg, xt


def wrap_deg(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class Stats:
    """The paper's error statistics of (N, 6) errors: ME, MAE, MaxE (largest |error|), SD."""

    me: np.ndarray
    mae: np.ndarray
    maxe: np.ndarray
    sd: np.ndarray
    n: int

    @classmethod
    def of(cls, err: np.ndarray) -> Stats:
        err = np.asarray(err, dtype=float).reshape(-1, 6)
        if not len(err):
            nan = np.full(6, np.nan)
            return cls(nan, nan, nan, nan, 0)
        return cls(err.mean(0), np.abs(err).mean(0), np.abs(err).max(0), err.std(0, ddof=1) if len(err) > 1
                   else np.zeros(6), len(err))

    def rows(self) -> list[tuple[str, np.ndarray]]:
        return [("ME", self.me), ("MAE", self.mae), ("MaxE", self.maxe), ("SD", self.sd)]


def path_truth_errors(src, after_ns: int = 0) -> tuple[str, np.ndarray, np.ndarray]:
    """Errors (N, 6) of the recorded path (the tip's when recorded, else G's) against the
    ground truth at the same stamps, and the stamps; ``which`` names the point."""
    stamps, xg, xt = path_points(src)
    keep = stamps >= after_ns
    stamps, xg = stamps[keep], xg[keep]
    xt = None if xt is None else xt[keep]
    if not len(stamps):
        return "G", np.zeros((0, 6)), stamps
    which, field, x = ("tip", "world_T_tip", xt) if xt is not None else ("G", "world_T_tob", xg)
    truth = np.array([x_from_transform(T) for T in truth_at(src, stamps, field=field)])
    err = x - truth
    err[:, 3:] = wrap_deg(err[:, 3:])
    return which, err, stamps


def scenario_start_ns(src) -> int:
    """When the operator started moving (its ``scenario_started`` event), or 0."""
    for o in src.outputs("operator/events"):
        ev = pb.Event.FromString(o.data)
        if ev.code == "scenario_started":
            return ev.header.stamp_ns
    return 0


def format_stats(title: str, stats: Stats, unit_note: str = "mm, deg") -> str:
    rows = [[name, *(tables.number(float(x)) for x in v)] for name, v in stats.rows()]
    return tables.render(["", *COORDS], rows, title=f"{title} (n = {stats.n}; {unit_note})", rule=False)
