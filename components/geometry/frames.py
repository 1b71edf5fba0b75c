"""The cell's frames: one frame graph and one time-stamped pose buffer (issue 30.5).

The anchor is pytransform3d's ``TransformManager`` and its temporal variant (not a
dependency): named frames joined by transforms, some fixed, some that move in time, and a
lookup of any ``a_T_b`` at a stamp.

* :class:`TimedPoses` holds one moving transform as stamped samples ``(stamp, a_T_b)``, in
  stamp order, at most ``maxlen`` of them (older ones fall out; ``forget_before`` prunes
  what a caller no longer needs). What ``add`` does with a repeated or an earlier stamp
  (:class:`Repeat`, :class:`Backwards`), and what ``at`` answers between, on and beyond the
  samples (:class:`Lookup`: :class:`Between`, :class:`Outside`), are explicit policies of
  the caller: each user keeps its own behaviour, named, instead of a private copy.
* :class:`FrameGraph` is a tree of named frames (``world`` at the root; ``base``,
  ``flange``, ``camera``, ``tob``, ``tip``, ...) whose edges ``parent_T_child`` are static
  (a 4x4) or timed (a :class:`TimedPoses` with its :class:`Lookup`). ``lookup(a, b, stamp)``
  composes ``a_T_b = inverse(c_T_a) @ c_T_b`` through their nearest common ancestor ``c``,
  each chain from ``c`` down, left to right (so ``world_T_camera = world_T_flange @
  flange_T_camera`` and ``camera_T_tob = inverse(world_T_camera) @ world_T_tob`` bit for bit
  as written out by hand; a parent-child lookup is the edge itself); None when a timed edge
  on the way has no pose at the stamp.
* :func:`smooth_poses_at` is the batch lookup of a smooth track through stamped poses
  (position a cubic spline, orientation scipy's ``Slerp``): the camera-to-robot timing
  estimate's arithmetic (:mod:`humanpt.calibration.timing`), kept as it was.

Interpolation between two samples is :func:`humanpt.geometry.transforms.interpolate_transform`
(translation on the straight line, rotation on the geodesic): the project's one slerp.
Everything here is unit-agnostic (a pose's translation keeps the unit it was added in: m
in the pose filter, mm in the simulated camera) and pure (no clock, no I/O). Stamps are
integers (ns) by convention; any increasing numbers work.

The users and their policies:

================================  ==========  ===========  ========  =========  ==========
user                              repeat      backwards    before    between    after
================================  ==========  ===========  ========  =========  ==========
pose filter (robot at an image)   refuse      refuse       reach     segment    reach
simulated camera (truth)          replace     restart      hold      sample     refuse
evaluation (truth, offline)       replace     restart      hold      sample     hold
viewer (robot at an image)        keep        restart      hold      nearest    hold
scene (latest robot state)        replace     restart      hold      nearest    hold
hand-eye timing (batch)           -           -            hold      cubic      hold
================================  ==========  ===========  ========  =========  ==========
"""

from __future__ import annotations

import enum
from bisect import bisect_left
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .errors import GeometryError
from .transforms import interpolate_transform, invert_transform

__all__ = [
    "Repeat",
    "Backwards",
    "Outside",
    "Between",
    "Lookup",
    "TimedPoses",
    "FrameGraph",
    "smooth_poses_at",
    "SAMPLE_HOLD_REFUSE",
    "SAMPLE_HOLD_HOLD",
    "NEAREST_HOLD",
    "segment_reach",
]


class Repeat(enum.Enum):
    """What :meth:`TimedPoses.add` does with a sample stamped as the latest one."""

    REFUSE = "refuse"  # dropped (add returns False)
    REPLACE = "replace"  # the newer pose wins
    KEEP = "keep"  # both kept (a NEAREST lookup gives the first of them)


class Backwards(enum.Enum):
    """What :meth:`TimedPoses.add` does with a sample stamped before the latest one."""

    REFUSE = "refuse"  # dropped (add returns False): the caller decides (pose filter)
    RESTART = "restart"  # the buffer starts again on it (a restarted source)


class Outside(enum.Enum):
    """What a lookup gives at a stamp before the first sample or after the last."""

    REFUSE = "refuse"  # None
    HOLD = "hold"  # the end sample (the body stood still before / after)
    REACH = "reach"  # on at the end segment's rates, up to Lookup.reach past the end; None beyond
    #                  (one sample: held, within the reach)


class Between(enum.Enum):
    """What a lookup gives at a stamp within the samples' span."""

    SAMPLE = "sample"  # on a sample: that sample; between two: interpolated
    SEGMENT = "segment"  # interpolated on the segment bisect_left finds (clamped to the ends),
    #                      even on a sample (the pose filter's arithmetic: on a sample it may
    #                      differ from the sample in the last bits)
    NEAREST = "nearest"  # the nearest sample, the earlier one on a tie; never interpolated


@dataclass(frozen=True)
class Lookup:
    """How :meth:`TimedPoses.at` answers a stamp: within the samples (``between``), before
    the first (``before``) and after the last (``after``); ``reach``: how far beyond an end
    :attr:`Outside.REACH` goes (the stamps' unit, >= 0)."""

    between: Between = Between.SAMPLE
    before: Outside = Outside.HOLD
    after: Outside = Outside.REFUSE
    reach: int = 0

    def __post_init__(self):
        if self.reach < 0:
            raise ValueError(f"Lookup.reach must be >= 0, got {self.reach}")


# The named policies of the users (module docstring table).
SAMPLE_HOLD_REFUSE = Lookup(Between.SAMPLE, Outside.HOLD, Outside.REFUSE)  # a truth, never extrapolated
SAMPLE_HOLD_HOLD = Lookup(Between.SAMPLE, Outside.HOLD, Outside.HOLD)  # a truth, held past its end
NEAREST_HOLD = Lookup(Between.NEAREST, Outside.HOLD, Outside.HOLD)  # the viewer's robot pose


def segment_reach(reach: int) -> Lookup:
    """The pose filter's robot pose at an image stamp: interpolated on a segment, or
    extrapolated from the end pair by at most ``reach``; None beyond."""
    return Lookup(Between.SEGMENT, Outside.REACH, Outside.REACH, int(reach))


class TimedPoses:
    """Stamped poses ``(stamp, a_T_b (4, 4))`` of one moving transform, in stamp order; at
    most ``maxlen`` (the oldest fall out; None: unbounded, for offline analysis only).
    ``repeat`` and ``backwards``: what :meth:`add` does with a stamp equal to / before the
    latest. Poses are kept as given (float arrays) and never changed; lookups return new
    arrays."""

    def __init__(
        self,
        maxlen: int | None = 4096,
        *,
        repeat: Repeat = Repeat.REFUSE,
        backwards: Backwards = Backwards.REFUSE,
    ) -> None:
        if maxlen is not None and maxlen < 1:
            raise ValueError(f"TimedPoses maxlen must be >= 1 or None, got {maxlen}")
        self._stamps: deque[int] = deque(maxlen=maxlen)
        self._poses: deque[np.ndarray] = deque(maxlen=maxlen)
        self.repeat = repeat
        self.backwards = backwards

    def __len__(self) -> int:
        return len(self._stamps)

    @property
    def first_ns(self) -> int | None:
        return self._stamps[0] if self._stamps else None

    @property
    def last_ns(self) -> int | None:
        return self._stamps[-1] if self._stamps else None

    @property
    def latest(self) -> tuple[int, np.ndarray] | None:
        """(stamp, pose) of the latest sample (the pose as kept: do not change it)."""
        return (self._stamps[-1], self._poses[-1]) if self._stamps else None

    def add(self, stamp, a_T_b) -> bool:
        """Add a sample; False when it was dropped (by ``repeat`` or ``backwards``)."""
        stamps = self._stamps
        if stamps and stamp <= stamps[-1]:
            if stamp == stamps[-1]:
                if self.repeat is Repeat.REFUSE:
                    return False
                if self.repeat is Repeat.REPLACE:
                    self._poses[-1] = np.asarray(a_T_b, dtype=float)
                    return True
            elif self.backwards is Backwards.REFUSE:
                return False
            else:  # time went backwards (a restarted source): start again
                self.clear()
        stamps.append(int(stamp))
        self._poses.append(np.asarray(a_T_b, dtype=float))
        return True

    def clear(self) -> None:
        self._stamps.clear()
        self._poses.clear()

    def covers(self, stamp) -> bool:
        """Whether a sample at or after ``stamp`` exists (the path up to it is known)."""
        return bool(self._stamps) and self._stamps[-1] >= stamp

    def forget_before(self, stamp) -> None:
        """Drop the samples no longer needed for stamps >= ``stamp`` (keeps the last one at
        or before it)."""
        stamps, poses = self._stamps, self._poses
        while len(stamps) >= 2 and stamps[1] <= stamp:
            stamps.popleft()
            poses.popleft()

    def at(self, stamp, lookup: Lookup) -> np.ndarray | None:
        """The pose (4, 4) at ``stamp`` as ``lookup`` says; None when it has none."""
        stamps, poses = self._stamps, self._poses
        n = len(stamps)
        if n == 0:
            return None
        if stamp < stamps[0]:
            side, end = lookup.before, 0
        elif stamp > stamps[-1]:
            side, end = lookup.after, n - 1
        else:
            side = None
        if side is not None:
            if side is Outside.REFUSE:
                return None
            if side is Outside.HOLD:
                return poses[end].copy()
            if abs(stamp - stamps[end]) > lookup.reach:  # REACH
                return None
            if n == 1:
                return poses[0].copy()
        elif n == 1:
            return poses[0].copy()
        i = bisect_left(stamps, stamp)
        between = lookup.between
        if between is Between.NEAREST:
            if i >= n:
                return poses[-1].copy()
            if i > 0 and stamp - stamps[i - 1] <= stamps[i] - stamp:
                i -= 1
            return poses[i].copy()
        if between is Between.SAMPLE and i < n and stamps[i] == stamp:
            return poses[i].copy()
        i = min(max(i, 1), n - 1)
        t0, t1 = stamps[i - 1], stamps[i]
        if t1 == t0:  # two samples of one stamp (Repeat.KEEP): no segment between them
            return poses[i].copy()
        # s beyond [0, 1] extrapolates at the segment's rates (Outside.REACH)
        return interpolate_transform(poses[i - 1], poses[i], (stamp - t0) / (t1 - t0), assume_valid=True)


def smooth_poses_at(stamps: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 4, 4) a smooth track through the stamped ``poses`` (M, 4, 4) (``stamps`` (M,),
    increasing, M >= 4) at the times ``t`` (N,): position on a cubic spline (scipy's
    ``make_interp_spline``, k = 3), orientation by scipy's ``Slerp``; times outside the
    stamps are clamped to them (:attr:`Outside.HOLD`). Floats in, any time unit."""
    from scipy.interpolate import make_interp_spline  # only the offline estimate needs it

    stamps = np.asarray(stamps)
    poses = np.asarray(poses, dtype=float)
    tc = np.clip(t, stamps[0], stamps[-1])
    out = np.tile(np.eye(4), (len(tc), 1, 1))
    out[:, :3, 3] = make_interp_spline(stamps, poses[:, :3, 3], k=3)(tc)
    out[:, :3, :3] = Slerp(stamps, Rotation.from_matrix(poses[:, :3, :3]))(tc).as_matrix()
    return out


class FrameGraph:
    """Named frames in a tree rooted at ``root``: each other frame has one parent, and its
    edge ``parent_T_child`` is static (:meth:`add_static`) or timed (:meth:`add_timed`: a
    :class:`TimedPoses` and the :class:`Lookup` that answers it). Frames are listed in the
    order they were added (:attr:`frames`, :attr:`edges`)."""

    def __init__(self, root: str = "world") -> None:
        self.root = root
        self._parent: dict[str, str] = {}
        self._static: dict[str, np.ndarray] = {}
        self._timed: dict[str, tuple[TimedPoses, Lookup]] = {}

    @property
    def frames(self) -> tuple[str, ...]:
        return (self.root, *self._parent)

    @property
    def edges(self) -> tuple[tuple[str, str], ...]:
        """(parent, child) of every edge, in the order they were added."""
        return tuple((p, c) for c, p in self._parent.items())

    def parent(self, frame: str) -> str | None:
        self._check(frame)
        return self._parent.get(frame)

    def _check(self, frame: str) -> None:
        if frame != self.root and frame not in self._parent:
            raise GeometryError(f"frame {frame!r} is not in the frame graph (frames: {', '.join(self.frames)})")

    def _attach(self, parent: str, child: str) -> None:
        self._check(parent)
        if child == self.root:
            raise GeometryError(f"frame {child!r} is the root of the frame graph: it has no parent")
        known = self._parent.get(child)
        if known is not None and known != parent:
            raise GeometryError(f"frame {child!r} already hangs from {known!r}, not {parent!r}")
        self._timed.pop(child, None)
        self._static.pop(child, None)
        self._parent[child] = parent

    def add_static(self, parent: str, child: str, parent_T_child) -> None:
        """A fixed edge (or a new value of one: a changed D, a new hand-eye)."""
        T = np.array(parent_T_child, dtype=float)
        if T.shape != (4, 4):
            raise GeometryError(f"{parent}_T_{child} must be (4, 4), got {T.shape}")
        self._attach(parent, child)
        self._static[child] = T

    def add_timed(self, parent: str, child: str, poses: TimedPoses, lookup: Lookup) -> TimedPoses:
        """A moving edge: ``poses`` holds ``parent_T_child`` at stamps, ``lookup`` answers
        it. Returns ``poses`` (its owner adds the samples)."""
        self._attach(parent, child)
        self._timed[child] = (poses, lookup)
        return poses

    def set_lookup(self, child: str, lookup: Lookup) -> None:
        """Answer the timed edge to ``child`` with ``lookup`` from now on (a new reach)."""
        poses, _ = self._timed[child]
        self._timed[child] = (poses, lookup)

    def _edge(self, child: str, stamp) -> np.ndarray | None:
        T = self._static.get(child)
        if T is not None:
            return T
        poses, lookup = self._timed[child]
        if stamp is None:
            raise GeometryError(f"{self._parent[child]}_T_{child} moves: its lookup needs a stamp")
        return poses.at(stamp, lookup)

    def path(self, frame: str) -> tuple[str, ...]:
        """The frames from the root down to ``frame`` (both included)."""
        self._check(frame)
        chain = [frame]
        while chain[-1] != self.root:
            chain.append(self._parent[chain[-1]])
        return tuple(reversed(chain))

    def _chain(self, frames: tuple[str, ...], stamp) -> np.ndarray | None:
        """frames[0]_T_frames[-1] down the tree, composed left to right; None when a timed
        edge on the way has no pose at ``stamp``; None for no edge (the same frame). May be a
        kept array: do not change it."""
        out = None
        for child in frames[1:]:
            T = self._edge(child, stamp)
            if T is None:
                return None
            out = T if out is None else out @ T
        return out

    def lookup(self, a: str, b: str, stamp=None) -> np.ndarray | None:
        """``a_T_b`` (4, 4) at ``stamp`` (needed when a timed edge is on the way), through the
        nearest common ancestor ``c``: ``inverse(c_T_a) @ c_T_b``, or ``c_T_b`` when ``a`` is
        ``c``, or ``inverse(c_T_a)`` when ``b`` is; None when a timed edge on the way has no
        pose at ``stamp``. A new array."""
        pa, pb = self.path(a), self.path(b)
        k = 0  # pa[:k] == pb[:k]: the common ancestor is pa[k - 1]
        while k < min(len(pa), len(pb)) and pa[k] == pb[k]:
            k += 1
        down_a, down_b = pa[k - 1:], pb[k - 1:]
        c_T_b = self._chain(down_b, stamp) if len(down_b) > 1 else None
        if len(down_b) > 1 and c_T_b is None:
            return None
        if len(down_a) == 1:  # a is the common ancestor
            return np.eye(4) if c_T_b is None else np.array(c_T_b)
        c_T_a = self._chain(down_a, stamp)
        if c_T_a is None:
            return None
        a_T_c = invert_transform(c_T_a)
        return a_T_c if c_T_b is None else a_T_c @ c_T_b
