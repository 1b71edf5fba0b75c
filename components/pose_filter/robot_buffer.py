"""The robot's pose at an image's capture stamp, from the robot states around it."""

from __future__ import annotations

from bisect import bisect_left
from collections import deque

import numpy as np

from humanpt.geometry.transforms import interpolate_transform


class RobotPoseBuffer:
    """Recent (stamp_ns, world_T_flange (4, 4)) pairs, in stamp order."""

    def __init__(self, maxlen: int = 64):
        self._items: deque[tuple[int, np.ndarray]] = deque(maxlen=maxlen)
        self._stamps: deque[int] = deque(maxlen=maxlen)

    def add(self, stamp_ns: int, world_T_flange: np.ndarray) -> bool:
        """Append a state; False (and nothing kept) when its stamp is not after the latest:
        the buffer stays in stamp order."""
        if self._items and stamp_ns <= self._items[-1][0]:
            return False
        self._items.append((int(stamp_ns), np.asarray(world_T_flange, dtype=float)))
        self._stamps.append(int(stamp_ns))
        return True

    def clear(self) -> None:
        self._items.clear()
        self._stamps.clear()

    def __len__(self) -> int:
        return len(self._items)

    @property
    def latest(self) -> tuple[int, np.ndarray] | None:
        return self._items[-1] if self._items else None

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
        # s beyond [0, 1] extrapolates at the rates between the two states
        return interpolate_transform(T0, T1, (stamp_ns - t0) / (t1 - t0), assume_valid=True)
