"""The camera-to-robot time offset, from the robot's own motion seen by the camera (issue 32.4).

Each measurement of the target is taken at an image's stamp ``s`` on the camera's clock;
the pipeline places it in the world with the robot's flange at that stamp:
``world_T_tob = world_T_flange(s) @ flange_T_camera @ camera_T_tob``.  If the image's
true instant is ``s - offset`` (stamps ``offset`` late: ``offset > 0``), the flange used
is where the robot was ``offset`` later, and the target's world track gets the robot's
own motion over ``offset`` added to it: the target seems to move with the robot.

The estimate aligns the measured target's track with the robot's motion: it takes the
offset ``d`` for which the track ``world_T_flange(s_i - d) @ flange_T_camera @
camera_T_tob_i`` moves least from one image to the next (least squares of its first
differences, robustly: Huber).  To first order the track is ``p_i(0) - d b_i`` (``b_i``
the velocity of the flange-fixed point where the target was seen), so the sum is
quadratic in ``d``; it is solved and iterated about itself, and its 1-sigma is the larger
of the formal one and the scatter of the estimates of five stretches of the data.

It wants a target that does not move while the robot does: the hand-eye stage's moves
between its poses, the target on its fixture (:mod:`humanpt.twin.cal_handeye`; 5 ms
injected on the twin: 5.04 +- 0.03 ms).  While the servo tracks a moving target, the
robot's motion follows the target's (the same corners and stops a moment later) and
the smoothest track is not the true one: on the twin's trapezium the tracking data gave
+3.4 ms with no offset and +6.7 ms with 5 ms (a smoothness criterion on second
differences), so the tracking data are not used.

Pure: arrays in, a :class:`TimeOffset` out; mm, s inside, ms at the edges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from humanpt.geometry.frames import smooth_poses_at

__all__ = ["TimeOffset", "TimeOffsetError", "estimate_time_offset", "apply_to_rig"]


class TimeOffsetError(ValueError):
    """Too little data to estimate the offset; says why."""


@dataclass(frozen=True)
class TimeOffset:
    """``offset_ms``: how late the image stamps are on the robot's clock (the image was
    taken ``offset_ms`` before its stamp); ``sigma_ms`` its 1-sigma standard error;
    ``measurements`` used; ``leak_mm_per_ms``: the RMS of the robot's motion that one ms of
    offset puts into the target's track (how observable the offset was)."""

    offset_ms: float
    sigma_ms: float
    measurements: int
    leak_mm_per_ms: float

    def summary_lines(self) -> list[str]:
        return [f"camera-to-robot time offset: {self.offset_ms:+.2f} ms +- {self.sigma_ms:.2f} ms (1 sigma; "
                f"images {'late' if self.offset_ms >= 0 else 'early'} on the robot's clock), from "
                f"{self.measurements} measurements while the robot moved (1 ms moves the target's track "
                f"{self.leak_mm_per_ms:.4f} mm RMS)"]


def _track(robot_t_s, world_T_flange_mm, flange_T_camera_mm, s_s, camera_p_tob_mm, d_s) -> np.ndarray:
    """(N, 3) the target's world positions with the offset ``d_s`` taken out of the stamps;
    the flange on the smooth track through the robot's states (geometry.frames: a cubic
    spline in position, slerp in orientation, clamped to the states)."""
    F = smooth_poses_at(robot_t_s, world_T_flange_mm, s_s - d_s) @ flange_T_camera_mm
    return np.einsum("nij,nj->ni", F[:, :3, :3], camera_p_tob_mm) + F[:, :3, 3]


def _differences(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N - 1, 3) the track's velocity between neighbouring measurements times the mean
    step (mm): what it moved from one image to the next, as if the images were even."""
    return np.diff(p, axis=0) / np.diff(t)[:, None] * float(np.mean(np.diff(t)))


def estimate_time_offset(meas_stamp_ns: np.ndarray, camera_T_tob_mm: np.ndarray, robot_stamp_ns: np.ndarray,
                         world_T_flange_mm: np.ndarray, flange_T_camera_mm: np.ndarray, *,
                         max_offset_ms: float = 50.0, iterations: int = 3) -> TimeOffset:
    """The offset (module doc) from measurements (stamps (N,) ns on the camera's clock,
    ``camera_T_tob_mm`` (N, 4, 4)) and the robot's states (stamps (M,) ns, ``world_T_flange_mm``
    (M, 4, 4)) over the same stretch of tracking, with the rig's ``flange_T_camera_mm``.
    Only measurements within the robot's states (``max_offset_ms`` inside their ends) are
    used.  :class:`TimeOffsetError` when fewer than 20 are, or the robot did not move."""
    s = np.asarray(meas_stamp_ns, dtype=np.int64)
    r = np.asarray(robot_stamp_ns, dtype=np.int64)
    if len(r) < 4:
        raise TimeOffsetError(f"{len(r)} robot states; the offset needs the robot's motion (at least 4 states)")
    order = np.argsort(r, kind="stable")
    r, F = r[order], np.asarray(world_T_flange_mm, dtype=float)[order]
    keep = np.r_[True, np.diff(r) > 0]
    r, F = r[keep], F[keep]
    t0 = int(r[0])
    rt = (r - t0) * 1e-9
    st = (s - t0) * 1e-9
    margin = max_offset_ms * 1e-3
    inside = (st >= rt[0] + margin) & (st <= rt[-1] - margin)
    o = np.argsort(st[inside], kind="stable")
    st = st[inside][o]
    m = np.asarray(camera_T_tob_mm, dtype=float)[inside][o][:, :3, 3]
    uniq = np.r_[True, np.diff(st) > 0]
    st, m = st[uniq], m[uniq]
    if len(st) < 20:
        raise TimeOffsetError(f"{len(st)} measurements while the robot's states cover them; at least 20 needed")
    C = np.asarray(flange_T_camera_mm, dtype=float)
    d, sigma, leak = _solve(rt, F, C, st, m, margin, iterations)
    # The second differences of neighbouring measurements share them (and a servo's or a
    # hand's slow wander is no white noise): the formal sigma is too small.  The scatter of
    # the estimates of BLOCKS contiguous stretches says how well the data pin it down.
    blocks = [b for b in np.array_split(np.arange(len(st)), BLOCKS) if len(b) >= 20]
    ds = []
    for b in blocks:
        try:
            ds.append(_solve(rt, F, C, st[b], m[b], margin, iterations)[0])
        except TimeOffsetError:
            continue
    if len(ds) >= 3:
        sigma = max(sigma, float(np.std(ds, ddof=1)) / math.sqrt(len(ds)))
    return TimeOffset(offset_ms=d * 1e3, sigma_ms=sigma * 1e3, measurements=len(st), leak_mm_per_ms=leak)


BLOCKS = 5


def _solve(rt, F, C, st, m, margin, iterations) -> tuple[float, float, float]:
    """(offset s, its formal sigma s, leak mm/ms) of one stretch of measurements."""
    d, h = 0.0, 1e-3  # s; the derivative taken over 1 ms
    sigma, leak = math.inf, 0.0
    for _ in range(max(1, iterations)):
        a = _differences(_track(rt, F, C, st, m, d), st)
        b = (_differences(_track(rt, F, C, st, m, d + h), st) - a) / h  # d(track')/dd
        bb = float(np.sum(b * b))
        if not math.isfinite(bb) or math.sqrt(bb / b.size) * 1e-3 < 1e-6:  # under 1 nm a ms: nothing to see
            raise TimeOffsetError("the robot did not move while the target was measured: no offset to see")
        # Robustly (Huber): where the target itself turns or stops, its own second
        # differences are large and the robot's answer to them follows: those few samples
        # would pull the estimate; the many where only the robot's motion leaks decide it.
        res0 = np.abs(a - np.median(a, axis=0)).ravel()
        scale = max(1.4826 * float(np.median(res0)), 1e-9)
        fit = least_squares(lambda x, a=a, b=b: (a + b * x[0]).ravel(), [0.0], loss="huber", f_scale=scale)
        step = float(fit.x[0])
        d = float(np.clip(d + step, -margin, margin))
        res = (a + b * step).ravel()
        w = np.where(np.abs(res) <= scale, 1.0, scale / np.maximum(np.abs(res), 1e-300))  # Huber's weights
        bw = float(np.sum(w * b.ravel() ** 2))
        dof = max(int(np.sum(w > 0)) - 1, 1)
        sigma = math.sqrt(float(np.sum(w * res * res)) / dof / bw)
        leak = math.sqrt(bb / len(b)) * 1e-3
    return d, sigma, leak


def apply_to_rig(rig, result: TimeOffset, date: str):
    """``rig`` with its ``[timing]`` set to the estimate (and how it was obtained)."""
    import dataclasses

    from humanpt.geometry.rig import Calibration, Timing

    return dataclasses.replace(rig, timing=Timing(
        camera_time_offset_ms=round(float(result.offset_ms), 4),
        calibration=Calibration(method="servo-alignment", date=date,
                                note=f"{result.measurements} measurements while tracking",
                                sigma={"camera_time_offset_ms": round(float(result.sigma_ms), 4)})))
