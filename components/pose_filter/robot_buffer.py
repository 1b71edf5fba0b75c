"""The robot's pose at an image's capture stamp, from the robot states around it."""

from __future__ import annotations

from bisect import bisect_left
from collections import deque

import numpy as np

from humanpt.pose_filter.fastmath import matrix_of, quat_of, rotvec_of, slerp


class RobotPoseBuffer:
    """Recent (stamp_ns, world_T_flange (4, 4)) pairs, in stamp order."""

    def __init__(self, maxlen: int = 64):
        self._items: deque[tuple[int, np.ndarray]] = deque(maxlen=maxlen)
        self._stamps: deque[int] = deque(maxlen=maxlen)
        self._quats: deque = deque(maxlen=maxlen)  # quat_of each rotation, once needed

    def add(self, stamp_ns: int, world_T_flange: np.ndarray) -> None:
        if self._items and stamp_ns <= self._items[-1][0]:
            return  # out of order or duplicate: keep the buffer monotonic
        self._items.append((int(stamp_ns), np.asarray(world_T_flange, dtype=float)))
        self._stamps.append(int(stamp_ns))
        self._quats.append(None)

    def __len__(self) -> int:
        return len(self._items)

    @property
    def latest(self) -> tuple[int, np.ndarray] | None:
        return self._items[-1] if self._items else None

    def _quat(self, i: int):
        q = self._quats[i]
        if q is None:
            q = self._quats[i] = quat_of(self._items[i][1][:3, :3])
        return q

    def at(self, stamp_ns: int, max_extrapolation_ns: int) -> np.ndarray | None:
        """world_T_flange at ``stamp_ns``: interpolated (linear + slerp) between the two
        states around it, or extrapolated from the last two by at most
        ``max_extrapolation_ns``; None when out of reach."""
        items = self._items
        if not items:
            return None
        if len(items) == 1:
            t0, T0 = items[0]
            return T0.copy() if abs(stamp_ns - t0) <= max_extrapolation_ns else None
        if (
            stamp_ns < items[0][0] - max_extrapolation_ns
            or stamp_ns > items[-1][0] + max_extrapolation_ns
        ):
            return None
        i = bisect_left(self._stamps, stamp_ns)  # np.searchsorted's index
        i = min(max(i, 1), len(items) - 1)
        (t0, T0), (t1, T1) = items[i - 1], items[i]
        s = (stamp_ns - t0) / (t1 - t0)
        T = np.eye(4)
        p0, p1 = T0[:3, 3].tolist(), T1[:3, 3].tolist()
        T[:3, 3] = [a + s * (b - a) for a, b in zip(p0, p1, strict=True)]
        if 0.0 <= s <= 1.0:
            # = Slerp([0, 1], Rotation.from_matrix([R0, R1]))(s).as_matrix()
            T[:3, :3] = slerp(T0[:3, :3], T1[:3, :3], s, self._quat(i - 1), self._quat(i))
        else:  # extrapolate the relative rotation
            dR = rotvec_of(T1[:3, :3] @ T0[:3, :3].T)
            T[:3, :3] = matrix_of(dR * s) @ T0[:3, :3]
        return T
