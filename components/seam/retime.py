"""A seam in time: a constant feed rate with bounded acceleration and jerk (issue 21.2).

The seam is cut into *runs* at its corners (a direction change above the fit's
``corner_deg``) and dwells: the torch stops at a corner (a weld's corner is a stop, not a
blend) and holds still for a dwell's duration.  Along a run the feed is constant: the
requested ``speed_mm_s``, lowered if the torch would turn faster than
``max_angular_deg_s`` on any of its segments, and never above ``max_speed_mm_s`` (the
paper's step controller: 100 mm/s, 60 deg/s).  A run starts and ends at rest through a
cycloidal speed ramp, ``v(t) = V (t/T - sin(2 pi t/T) / (2 pi))``, whose acceleration
peaks at ``2 V/T`` and jerk at ``2 pi V/T^2``: ``T`` is the least that keeps both within
``accel_mm_s2`` and ``jerk_mm_s3``; a run too short for two ramps at ``V`` gets a lower
``V``.  The torch turns with the distance along each segment (slerp between the
segment's end orientations).  Samples every ``cycle_ms`` (the controller's cycle).

The robot's limits bind its flange, not the tool's tip: given the tool
(``flange_T_tool_x``), the flange's own motion is planned within ``limit_share`` of
them (the rest is the servo's, for its corrections).  A torch that turns swings the
flange about the tip (``w x r``, r from the tip to the flange): along a run the feed is
lowered until the flange's speed ``V |dp_flange/ds|`` (the largest over the run, sampled
every millimetre and degree) stays within ``limit_share * max_speed_mm_s``, and the ramps'
acceleration and jerk by the same factor; a turn on the spot at a corner turns no faster
than the flange may swing (``limit_share * max_speed_mm_s / |w^ x r|``), its angular
acceleration and jerk bounded likewise by ``accel_mm_s2`` and ``jerk_mm_s3`` over the
lever.  Without a tool the flange is the tool's frame (no swing).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from humanpt.geometry.transforms import invert_transform, transform_from_x
from humanpt.runtime.files import atomic_open
from humanpt.seam import limits
from humanpt.seam.fit import Seam, Segment
from humanpt.seam.sanitise import shown

__all__ = ["RetimeConfig", "RetimeError", "Timed", "retime", "write_csv", "read_csv", "peaks"]

# The most samples a re-timed seam may have (about 39 h at the 28 ms cycle).
MAX_SAMPLES = 5_000_000

CSV_HEADER = ("index", "t_s", "x_mm", "y_mm", "z_mm", "psi_deg", "theta_deg", "phi_deg", "speed_mm_s")


class RetimeError(ValueError):
    """Parameters or a seam that cannot be re-timed; says why."""


@dataclass(frozen=True)
class RetimeConfig:
    speed_mm_s: float = 20.0  # the feed along the seam
    accel_mm_s2: float = 200.0
    jerk_mm_s3: float = 2000.0
    max_speed_mm_s: float = limits.MAX_SPEED_MM_S  # the paper's limits (the gateway's defaults, 100 mm/s)
    max_angular_deg_s: float = limits.MAX_ANGULAR_DEG_S  # (60 deg/s)
    angular_accel_deg_s2: float = 120.0  # for a turn on the spot at a corner
    angular_jerk_deg_s3: float = 1200.0
    cycle_ms: float = 28.0  # the controller's cycle (the Puma's ALTER period)
    dwells: bool = True  # hold still for each dwell of the seam
    # The tool on the flange (x, y, z mm, Z-Y-X deg: the controller's flange_T_tool_x); None:
    # the flange is the tool's frame.  The flange's motion is planned within limit_share of
    # max_speed_mm_s and max_angular_deg_s (see the module doc).
    flange_T_tool_x: tuple[float, float, float, float, float, float] | None = None
    limit_share: float = 1.0

    def __post_init__(self):
        for name in ("speed_mm_s", "accel_mm_s2", "jerk_mm_s3", "max_speed_mm_s", "max_angular_deg_s",
                     "angular_accel_deg_s2", "angular_jerk_deg_s3", "cycle_ms"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise RetimeError(f"{name} must be a positive number, got {v!r}")
        for name, hi in (("max_speed_mm_s", limits.SPEED_CEILING_MM_S), ("accel_mm_s2", limits.ACCEL_CEILING_MM_S2),
                         ("jerk_mm_s3", 100 * limits.ACCEL_CEILING_MM_S2), ("max_angular_deg_s", 3600.0),
                         ("angular_accel_deg_s2", 36_000.0), ("angular_jerk_deg_s3", 3_600_000.0),
                         ("cycle_ms", 1000.0)):
            if getattr(self, name) > hi:
                raise RetimeError(f"{name} must be at most {hi:g}, got {getattr(self, name):g}")
        if self.cycle_ms < 0.1:
            raise RetimeError(f"cycle_ms must be at least 0.1, got {self.cycle_ms:g}")
        if not (isinstance(self.limit_share, (int, float)) and 0.1 <= self.limit_share <= 1.0):
            raise RetimeError(f"limit_share must be within [0.1, 1], got {self.limit_share!r}")
        if self.flange_T_tool_x is not None:
            x = self.flange_T_tool_x
            if (not isinstance(x, (tuple, list)) or len(x) != 6
                    or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in x)):
                raise RetimeError(f"flange_T_tool_x must be six finite numbers (x, y, z mm, Z-Y-X deg), got {x!r}")
            if math.hypot(*x[:3]) > limits.MAX_TOOL_MM:
                raise RetimeError(f"flange_T_tool_x: the tool is {math.hypot(*x[:3]):g} mm from the flange; "
                                  f"at most {limits.MAX_TOOL_MM:g}")
        if self.speed_mm_s > self.max_speed_mm_s:
            raise RetimeError(f"speed_mm_s {self.speed_mm_s:g} is above max_speed_mm_s {self.max_speed_mm_s:g}")


@dataclass(frozen=True)
class Timed:
    """The re-timed seam: ``t_s`` (K,), ``x`` (K, 6) mm and Z-Y-X deg, ``speed_mm_s`` (K,)
    along the path; ``feeds_mm_s`` the constant feed of each run."""

    t_s: np.ndarray
    x: np.ndarray
    speed_mm_s: np.ndarray
    feeds_mm_s: tuple[float, ...]

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1]) if len(self.t_s) else 0.0


def _turn_deg(seg: Segment) -> float:
    r0 = Rotation.from_euler("ZYX", seg.start_ypr_deg, degrees=True)
    r1 = Rotation.from_euler("ZYX", seg.end_ypr_deg, degrees=True)
    return math.degrees((r0.inv() * r1).magnitude())


def _tool_p_flange_mm(cfg: RetimeConfig) -> np.ndarray | None:
    """Where the flange's origin is in the tool's frame (3,) mm; None without a tool."""
    if cfg.flange_T_tool_x is None:
        return None
    flange_T_tool = transform_from_x(np.asarray(cfg.flange_T_tool_x, dtype=float))
    return invert_transform(flange_T_tool)[:3, 3]


def _flange_gain(seg: Segment, tool_p_flange: np.ndarray | None) -> float:
    """The largest |dp_flange / ds| along a segment (>= 0; 1 without a tool or a turn):
    how much faster than the tool the flange moves, sampled every mm and every degree."""
    if tool_p_flange is None or seg.length_mm <= 0:
        return 1.0
    n = max(2, int(math.ceil(max(seg.length_mm, _turn_deg(seg)))) + 1)
    f = np.linspace(0.0, 1.0, n)
    rots = Slerp([0.0, 1.0], Rotation.from_euler("ZYX", [seg.start_ypr_deg, seg.end_ypr_deg], degrees=True))(f)
    flange = seg.points_at(f) + rots.apply(tool_p_flange)
    ds = seg.length_mm / (n - 1)
    return max(1.0, float(np.linalg.norm(np.diff(flange, axis=0), axis=1).max()) / ds)


def _swing_lever_mm(r0: Rotation, r1: Rotation, tool_p_flange: np.ndarray | None) -> float:
    """The flange's largest distance from the axis of a turn on the spot from ``r0`` to
    ``r1`` (the tool's orientations; the axis through the tool's tip): the flange swings
    at that many mm per radian; 0 without a tool."""
    if tool_p_flange is None:
        return 0.0
    axis = (r1 * r0.inv()).as_rotvec()  # the world frame's axis (R(a) = exp(a axis) R0)
    if np.linalg.norm(axis) < 1e-12:
        return 0.0
    axis = axis / np.linalg.norm(axis)
    r = Slerp([0.0, 1.0], Rotation.concatenate([r0, r1]))(np.linspace(0.0, 1.0, 33)).apply(tool_p_flange)
    return float(np.linalg.norm(np.cross(axis, r), axis=1).max())


def _ramp_time(v: float, accel: float, jerk: float) -> float:
    return max(2 * v / accel, math.sqrt(2 * math.pi * v / jerk))


def _run_profile(length: float, v_max: float, accel: float, jerk: float) -> tuple[float, float]:
    """(V, T): the run's feed and ramp time so that two ramps fit in ``length``."""
    v = v_max
    if v * _ramp_time(v, accel, jerk) > length:  # ramps of V T / 2 each
        lo, hi = 0.0, v_max
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if mid * _ramp_time(mid, accel, jerk) <= length else (lo, mid)
        v = lo
    return v, _ramp_time(v, accel, jerk)


def _duration(length: float, v: float, accel: float, jerk: float) -> float:
    T = _ramp_time(v, accel, jerk)
    return 2 * T + max(length - v * T, 0.0) / v


def _on_cycles(length: float, v_max: float, accel: float, jerk: float, dt: float
               ) -> tuple[float, float, np.ndarray]:
    """(V, T, t): the profile over ``length`` sampled at every cycle, t = 0, dt, ... up to
    the first cycle at or after its end (where it stands still at the end)."""
    v, T = _run_profile(length, v_max, accel, jerk)
    cycles = _duration(length, v, accel, jerk) / dt
    if not cycles <= MAX_SAMPLES:
        raise RetimeError(f"a run of {length:.6g} at {v:.6g}/s takes {cycles:.3g} cycles of {dt * 1e3:g} ms; "
                          f"at most {MAX_SAMPLES} samples")
    n = max(int(math.ceil(cycles - 1e-9)), 1)
    return v, T, np.arange(n + 1) * dt


def _s_of_t(t: np.ndarray, length: float, v: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Distance and speed along a run at times ``t`` (0..duration)."""
    cruise = max(length - v * T, 0.0) / v if v > 0 else 0.0
    dur = 2 * T + cruise
    s, sp = np.zeros_like(t), np.zeros_like(t)
    w = 2 * math.pi / T
    up = t < T
    s[up] = v * (t[up] ** 2 / (2 * T) + (np.cos(w * t[up]) - 1) / (w * w * T))
    sp[up] = v * (t[up] / T - np.sin(w * t[up]) / (2 * math.pi))
    mid = (t >= T) & (t <= T + cruise)
    s[mid] = v * T / 2 + v * (t[mid] - T)
    sp[mid] = v
    down = t > T + cruise
    td = np.clip(dur - t[down], 0.0, T)  # time left: the ramp mirrored
    s[down] = length - v * (td ** 2 / (2 * T) + (np.cos(w * td) - 1) / (w * w * T))
    sp[down] = v * (td / T - np.sin(w * td) / (2 * math.pi))
    return np.clip(s, 0.0, length), sp


def _turn_on_spot(x_all: list, t_all: list, v_all: list, ypr_to: np.ndarray, cfg: RetimeConfig) -> None:
    """Append samples that turn the torch, standing still, to ``ypr_to`` (deg) within the
    angular limits (the same cycloidal ramps, in degrees)."""
    last = x_all[-1][-1]
    r0 = Rotation.from_euler("ZYX", last[3:], degrees=True)
    r1 = Rotation.from_euler("ZYX", ypr_to, degrees=True)
    turn = math.degrees((r0.inv() * r1).magnitude())
    if turn < 1e-6:
        return
    w_max, alpha, jerk = cfg.limit_share * cfg.max_angular_deg_s, cfg.angular_accel_deg_s2, cfg.angular_jerk_deg_s3
    lever = _swing_lever_mm(r0, r1, _tool_p_flange_mm(cfg))
    if lever > 0:  # the flange swings at lever mm per radian: within its own limits
        w_max = min(w_max, math.degrees(cfg.limit_share * cfg.max_speed_mm_s / lever))
        alpha = min(alpha, math.degrees(cfg.accel_mm_s2 / lever))
        jerk = min(jerk, math.degrees(cfg.jerk_mm_s3 / lever))
    w, T, t = _on_cycles(turn, w_max, alpha, jerk, cfg.cycle_ms * 1e-3)
    t = t[1:]
    a, _ = _s_of_t(t, turn, w, T)
    ypr = Slerp([0.0, 1.0], Rotation.concatenate([r0, r1]))(a / turn).as_euler("ZYX", degrees=True)
    x_all.append(np.column_stack([np.repeat(last[None, :3], len(t), axis=0), ypr]))
    t_all.append(t_all[-1][-1] + t)
    v_all.append(np.zeros(len(t)))


def retime(seam: Seam, config: RetimeConfig | None = None) -> Timed:
    """Sample ``seam`` in time (see the module doc).  Raises :class:`RetimeError` for a
    seam without length."""
    cfg = config or RetimeConfig()
    tool_p_flange = _tool_p_flange_mm(cfg)
    segs = seam.segments
    if not segs or sum(s.length_mm for s in segs) <= 0:
        raise RetimeError("the seam has no length to move along")
    corner_after = {c.before for c in seam.corners}
    # dwells after the segment whose last point is just before them
    dwell_after: dict[int, float] = {}
    if cfg.dwells:
        for d in seam.dwells:
            k = min(range(len(segs)), key=lambda i: abs(segs[i].last - d.first))
            dwell_after[k] = dwell_after.get(k, 0.0) + d.duration_s
    runs, cur = [], []
    for i in range(len(segs)):
        cur.append(i)
        if i in corner_after or i in dwell_after or i == len(segs) - 1:
            runs.append(cur)
            cur = []
    dt = cfg.cycle_ms * 1e-3
    t_all, x_all, v_all, feeds = [], [], [], []
    t0 = 0.0
    for run in runs:
        lengths = np.array([segs[i].length_mm for i in run])
        total = float(lengths.sum())
        v_cap = min(cfg.speed_mm_s, cfg.max_speed_mm_s)
        gain = max(_flange_gain(segs[i], tool_p_flange) for i in run)
        if tool_p_flange is not None:  # the flange's speed within its share of the limit
            v_cap = min(v_cap, cfg.limit_share * cfg.max_speed_mm_s / gain)
        for i, L in zip(run, lengths, strict=True):
            turn = _turn_deg(segs[i])
            if turn > 1e-9 and L > 0:
                v_cap = min(v_cap, cfg.limit_share * cfg.max_angular_deg_s * L / turn)
        v, T, t = _on_cycles(total, v_cap, cfg.accel_mm_s2 / gain, cfg.jerk_mm_s3 / gain, dt)
        s, sp = _s_of_t(t, total, v, T)
        bounds = np.concatenate([[0.0], np.cumsum(lengths)])
        pos = np.zeros((len(t), 3))
        ypr = np.zeros((len(t), 3))
        for j, i in enumerate(run):
            seg = segs[i]
            m = (s >= bounds[j]) & ((s <= bounds[j + 1]) if j == len(run) - 1 else (s < bounds[j + 1]))
            if not m.any():
                continue
            f = (s[m] - bounds[j]) / lengths[j] if lengths[j] > 0 else np.zeros(m.sum())
            pos[m] = seg.points_at(f)
            rots = Rotation.from_euler("ZYX", [seg.start_ypr_deg, seg.end_ypr_deg], degrees=True)
            ypr[m] = Slerp([0.0, 1.0], rots)(np.clip(f, 0, 1)).as_euler("ZYX", degrees=True)
        if t_all:  # a corner: turn the torch on the spot from the last run's end orientation
            _turn_on_spot(x_all, t_all, v_all, ypr[0], cfg)
            t0 = float(t_all[-1][-1])
        start = 0 if not t_all else 1  # a run starts where the last one ended: no repeated sample
        t_all.append(t0 + t[start:])
        x_all.append(np.column_stack([pos, ypr])[start:])
        v_all.append(sp[start:])
        feeds.append(v)
        t0 += float(t[-1])
        hold = dwell_after.get(run[-1], 0.0)
        if hold > 0:
            k = int(math.ceil(hold / dt - 1e-9))
            th = t0 + np.arange(1, k + 1) * dt
            t_all.append(th)
            x_all.append(np.repeat(x_all[-1][-1:], k, axis=0))
            v_all.append(np.zeros(k))
            t0 = float(th[-1])
    return Timed(np.concatenate(t_all), np.vstack(x_all), np.concatenate(v_all), tuple(feeds))


def peaks(timed: Timed) -> dict[str, float]:
    """The largest speed (mm/s), acceleration (mm/s^2), jerk (mm/s^3) and angular speed
    (deg/s) of the samples, by finite differences (what the robot will be asked for)."""
    t, p = timed.t_s, timed.x[:, :3]
    if len(t) < 4:
        return {"speed_mm_s": 0.0, "accel_mm_s2": 0.0, "jerk_mm_s3": 0.0, "angular_deg_s": 0.0}
    dt = np.diff(t)
    v = np.diff(p, axis=0) / dt[:, None]
    a = np.diff(v, axis=0) / dt[1:, None]
    j = np.diff(a, axis=0) / dt[2:, None]
    r = Rotation.from_euler("ZYX", timed.x[:, 3:], degrees=True)
    w = np.degrees((r[:-1].inv() * r[1:]).magnitude()) / dt
    return {"speed_mm_s": float(np.linalg.norm(v, axis=1).max()), "accel_mm_s2": float(np.linalg.norm(a, axis=1).max()),
            "jerk_mm_s3": float(np.linalg.norm(j, axis=1).max()), "angular_deg_s": float(w.max())}


def write_csv(path, timed: Timed, overwrite: bool = False):
    """The samples as CSV (:data:`CSV_HEADER`; mm, deg, s); never replaces a file unless
    ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise RetimeError(f"{path}: exists; give --overwrite to replace it")
    with atomic_open(path, "w", newline="") as f:  # a new temporary file, never through a planted link
        w = csv.writer(f)
        w.writerow(CSV_HEADER)
        for k, (t, x, v) in enumerate(zip(timed.t_s, timed.x, timed.speed_mm_s, strict=True)):
            w.writerow([k, f"{t:.6f}", *(f"{c:.6f}" for c in x), f"{v:.4f}"])
    return path


def read_csv(path) -> Timed:
    """A timed CSV written by :func:`write_csv` (``humanpt path retime``); RetimeError
    naming the file and line for anything else.  ``feeds_mm_s`` holds the largest speed."""
    path = Path(path)
    name = shown(path)
    try:
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise RetimeError(f"{name}: cannot read ({shown(e)})") from None
    if not rows or tuple(rows[0]) != CSV_HEADER:
        raise RetimeError(f"{name}: not a timed path (header {', '.join(CSV_HEADER)}; humanpt path retime)")
    try:
        data = np.array([[float(v) for v in r[1:]] for r in rows[1:] if r], dtype=float)
    except ValueError as e:
        raise RetimeError(f"{name}: a value that is not a number ({shown(e)})") from None
    if data.ndim != 2 or len(data) == 0 or data.shape[1] != len(CSV_HEADER) - 1 or not np.all(np.isfinite(data)):
        raise RetimeError(f"{name}: no samples, or a row without {len(CSV_HEADER)} finite numbers")
    for col, (lo, hi, what) in {0: (0.0, limits.MAX_TIME_S, "t_s"), 1: (-limits.MAX_ABS_MM, limits.MAX_ABS_MM, "x_mm"),
                                2: (-limits.MAX_ABS_MM, limits.MAX_ABS_MM, "y_mm"),
                                3: (-limits.MAX_ABS_MM, limits.MAX_ABS_MM, "z_mm"),
                                4: (-limits.MAX_ABS_DEG, limits.MAX_ABS_DEG, "psi_deg"),
                                5: (-limits.MAX_ABS_DEG, limits.MAX_ABS_DEG, "theta_deg"),
                                6: (-limits.MAX_ABS_DEG, limits.MAX_ABS_DEG, "phi_deg"),
                                7: (0.0, limits.SPEED_CEILING_MM_S, "speed_mm_s")}.items():
        bad = np.flatnonzero((data[:, col] < lo) | (data[:, col] > hi))
        if len(bad):
            raise RetimeError(f"{name}:{int(bad[0]) + 2}: {what} {data[bad[0], col]:g} is outside [{lo:g}, {hi:g}]")
    if np.any(np.diff(data[:, 0]) < 0):
        raise RetimeError(f"{name}: the times go backwards")
    return Timed(data[:, 0], data[:, 1:7], data[:, 7], (float(data[:, 7].max()),))
