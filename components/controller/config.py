"""Controller configuration (the paper's GUI options are the live parameters)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np

from humanpt.geometry.rig import DEFAULT_DZ_MM
from humanpt.runtime import cell_limits
from humanpt.runtime.config import Deg, Mm, Range, RateDegS, SpeedMmS, live

# The robot gateway's workspace envelope is the authority (it clips every step at it); a
# playback is checked against the same box before anything moves.  The controller does not
# load the gateway's package (tests/test_boundaries.py): it reads the keys from the cell's
# [robot_gateway] table, and its defaults are the gateway's (humanpt.runtime.cell_limits).
ENVELOPE_KEYS = ("envelope_min_mm", "envelope_max_mm")

X6 = tuple[float, float, float, float, float, float]
# The paper's K (Section 5, V_F = K E_F) as a 6x6 matrix: rows and columns (x, y, z, rx, ry,
# rz) in the flange frame, the error as a translation (m) and a small rotation vector (rad).
# (1000: the scalar gains' bound; the loop check at the link's cycle is far tighter.)
KEntry = Annotated[float, Range(-1000, 1000, "1/s; m/(rad s), rad/(m s) off the blocks")]
KRow = tuple[KEntry, KEntry, KEntry, KEntry, KEntry, KEntry]
Matrix6 = tuple[KRow, KRow, KRow, KRow, KRow, KRow]
# With one cycle of delay in the loop the gains must keep |k dt| below this (the scalar
# gains' check, and each eigenvalue of a gain matrix).
GAIN_DT_LIMIT = 0.5


@dataclass(frozen=True)
class ControllerConfig:
    """``[controller]``: the visual servo, path recording, driver calibration, playback.
    The hand-eye transform and the driver tip come from the rig."""

    law: Literal["thetau", "paper"] = live("thetau", "thetau (default) or the paper's Section 5 law")
    dz_mm: Annotated[float, Range(10, 5000, "mm")] = live(DEFAULT_DZ_MM, "distance of the desired point D from the camera (GUI: dz offset)")
    gain_translation_1_s: Annotated[float, Range(1e-3, 1000, "1/s")] = live(4.0, "K for translation")
    gain_rotation_1_s: Annotated[float, Range(1e-3, 1000, "1/s")] = live(4.0, "K for rotation")
    # K as the paper's 6x6 weight matrix (None: diag(gain_translation_1_s x 3,
    # gain_rotation_1_s x 3), the default); both laws take it in the flange frame.
    gain_matrix_1_s: Matrix6 | None = live(
        None, "K as a 6x6 matrix, flange frame, (x, y, z, rx, ry, rz) in m and rad (none: the two gains' diagonal)")
    feed_forward: bool = live(True, "add the target's filtered velocity (thetau law)")
    # The thetau law compares the flange and the target at the same instant: the robot
    # state's stamp plus this lead (the time until the command takes effect beyond one
    # cycle); the feed-forward then moves the flange with the target over the cycle.
    lead_ms: Annotated[float, Range(-1000, 1000, "ms")] = live(0.0, "extra look-ahead of the target pose for the thetau law")
    # Below these errors (and a still target) the flange is left alone: chasing the
    # measurement noise would only shake the camera (and the robot's quantised pose).
    deadband_mm: Annotated[float, Range(0, 100, "mm")] = live(0.1, "no correction while |G - D| is below this and the target is still")
    deadband_deg: Annotated[float, Range(0, 90, "deg")] = live(0.3, "no rotation while the angle error is below this and the target does not turn")
    still_mm_s: Annotated[float, Range(0, 100, "mm/s")] = live(1.0, "the target counts as still below this speed")
    still_deg_s: Annotated[float, Range(0, 100, "deg/s")] = live(0.5, "the target counts as not turning below this rate")
    max_speed_mm_s: SpeedMmS = live(100.0, "translation speed limit (the paper's step controller)")
    max_rotation_deg_s: RateDegS = live(60.0, "rotation speed limit")
    # What gives when the demanded flange motion exceeds those limits (a quick torch turn
    # swings the flange, 700 mm from D, far faster than 100 mm/s): position_first keeps D on
    # G (G at the image centre, at its depth) and lets the orientation lag; scale shrinks the
    # whole step (the flange falls behind and G drifts out of the image).
    saturation: Literal["position_first", "scale"] = live(
        "position_first", "at the speed limits: keep G at D and let the orientation lag, or scale the whole step")
    # position_first takes over once G is this far from D (within it the step is scaled as
    # with "scale": the orientation keeps its priority while G is near the image centre;
    # 10 mm at 600 mm is ~17 px in the image).
    position_first_beyond_mm: Annotated[float, Range(0, 1000, "mm")] = live(
        10.0, "position_first: engage once |G - D| exceeds this")
    # The cycle (dt, per-cycle limits) is the robot link's, taken from each robot state
    # (RobotState.cycle_period_ns; humanpt.runtime.cycle): the controller has none of its own.
    # Command cycle k + 1 as soon as the state of cycle k is in (from where cycle k's step
    # will have put the flange): the gateway then answers each STATUS at once instead of
    # waiting on three bus hops within its reply deadline.
    command_ahead: bool = live(True, "command each ALTER cycle one cycle ahead (no bus wait at the gateway)")
    lost_action: Literal["hold", "return"] = live("hold", "target lost: stop on current location, or return")
    # The paper's "return to an initial prespecified state": the flange pose (world frame,
    # mm and deg, X = (x, y, z, psi, theta, phi)) that "return" and the lost action
    # "return" go to; None: the first robot pose the controller saw.  Inside the envelope.
    return_flange_x: tuple[Mm, Mm, Mm, Deg, Deg, Deg] | None = live(
        None, "flange pose (world, mm/deg) to return to (none: the first robot pose)")
    start_mode: Literal["track", "hold"] = "track"
    recording_delay_cycles: Annotated[int, Range(1, 100000, "cycles")] = live(10, "a path point every N cycles (GUI: recording delay)")
    # A point also at the first measurement after record_start and whenever the point moved
    # this far: about this far apart at any speed (60 mm/s with a point every 10 cycles left
    # 17 mm between points, too sparse for `humanpt path fit`: an arc's chords; 1-2 mm apart a
    # hand's tremor, correlated over millimetres, looks like shape to it: a 1 mm recording of
    # the realistic trapezium thinned to 2 mm fitted as 24 pieces, to 4 mm as 4 lines); 0: every
    # recording_delay_cycles only, as recordings before it.
    recording_spacing_mm: Annotated[float, Range(0, 1000, "mm")] = live(
        4.0, "a path point whenever the point moved this far (0: every recording_delay_cycles only)")
    record_on_start: bool = False
    # The paper stores the raw state vector of step 10; humanpt's path point is the filter's
    # estimate.  With this on each point also carries the perception's own X_WG of the same
    # image (PathPoint.world_T_tob_raw, and the tip through it), from the pose filter.
    record_raw: bool = live(False, "store the unfiltered X_WG (the paper's raw state vector) in each path point too")
    has_driver: bool = live(False, "record the driver tip P as well as G")
    calibration_samples: Annotated[int, Range(6, 100000, "samples")] = live(60, "N samples for the driver-tip calibration (GUI)")
    calibration_min_spread_deg: Annotated[float, Range(0, 90, "deg")] = 1.5
    flange_T_tool_x: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (0.0, 0.0, 200.0, 0.0, 0.0, 0.0)
    playback_speed_mm_s: SpeedMmS = live(20.0, "tool speed along a played-back path")
    playback_max_lag_mm: Annotated[float, Range(1e-3, 1000, "mm")] = 2.0
    # Every point of a playback (the flange, tool point and flange_T_tool) must lie inside
    # the robot gateway's workspace envelope, or the playback is refused before anything
    # moves.  From a config file these are the [robot_gateway] section's (cell_defaults)
    # unless [controller] sets its own (a smaller box); at run time they may only shrink.
    envelope_min_mm: tuple[Mm, Mm, Mm] = live(
        cell_limits.ENVELOPE_MIN_MM, "playback workspace box, world frame, lower corner of the flange (mm)",
        stricter="higher")
    envelope_max_mm: tuple[Mm, Mm, Mm] = live(
        cell_limits.ENVELOPE_MAX_MM, "playback workspace box, world frame, upper corner of the flange (mm)",
        stricter="lower")

    @classmethod
    def cell_defaults(cls, sections: Mapping[str, Mapping[str, Any]], source: str = "config") -> dict[str, Any]:
        """What the cell's other sections set for the controller: the robot gateway's
        workspace envelope, as far as [robot_gateway] sets it (else both take the same
        defaults); checked as the controller's own keys."""
        table = sections.get("robot_gateway", {})
        return {k: table[k] for k in ENVELOPE_KEYS if k in table}

    def __post_init__(self):
        for name in ("dz_mm", "max_speed_mm_s", "max_rotation_deg_s", "playback_speed_mm_s",
                     "playback_max_lag_mm", "gain_translation_1_s", "gain_rotation_1_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.recording_delay_cycles < 1:
            raise ValueError("recording_delay_cycles must be >= 1")
        if not all(lo < hi for lo, hi in zip(self.envelope_min_mm, self.envelope_max_mm, strict=True)):
            raise ValueError(f"envelope_min_mm {self.envelope_min_mm} must be below envelope_max_mm "
                             f"{self.envelope_max_mm} on every axis")
        if self.calibration_samples < 6:
            raise ValueError("calibration_samples must be >= 6 (the pivot fit has 6 unknowns)")
        if self.return_flange_x is not None:
            p = np.asarray(self.return_flange_x[:3], dtype=float)
            lo, hi = np.asarray(self.envelope_min_mm), np.asarray(self.envelope_max_mm)
            for j, axis in enumerate("xyz"):
                if not lo[j] <= p[j] <= hi[j]:
                    side, limit = ("below", lo[j]) if p[j] < lo[j] else ("above", hi[j])
                    raise ValueError(f"return_flange_x puts the flange at {axis} {p[j]:g} mm, {side} the workspace "
                                     f"envelope's {'min' if side == 'below' else 'max'} {limit:g} mm")

    def gain_matrix(self) -> np.ndarray | None:
        """K (6, 6), flange frame, SI; None for the default diagonal of the two gains."""
        return None if self.gain_matrix_1_s is None else np.asarray(self.gain_matrix_1_s, dtype=float)

    def gain_eigenvalues(self) -> np.ndarray:
        """The eigenvalues (1/s) of K: the two gains, or the matrix's."""
        K = self.gain_matrix()
        if K is None:
            return np.array([self.gain_translation_1_s] * 3 + [self.gain_rotation_1_s] * 3, dtype=complex)
        return np.linalg.eigvals(K)

    def check_cycle(self, cycle_period_ns: int) -> None:
        """The gains at the cell's cycle (the link's; ``ConfigFile.component`` calls this):
        with one cycle of delay in the loop, k * dt must stay well below 1 for stability."""
        dt_s = cycle_period_ns * 1e-9
        for name in ("gain_translation_1_s", "gain_rotation_1_s"):
            g = getattr(self, name)
            if not g * dt_s < GAIN_DT_LIMIT:
                raise ValueError(f"{name} = {g} must be < {GAIN_DT_LIMIT / dt_s:.1f} at the link's {dt_s * 1e3:g} ms cycle")
        if self.gain_matrix_1_s is not None:
            why = gain_matrix_refusal(self.gain_matrix(), dt_s)
            if why:
                raise ValueError(f"gain_matrix_1_s {why} at the link's {dt_s * 1e3:g} ms cycle")


def gain_matrix_refusal(K: np.ndarray, dt_s: float) -> str | None:
    """Why the loop with gain matrix ``K`` (6, 6, 1/s) is not stable at the cycle ``dt_s``,
    or None.  With one cycle of delay the error obeys e[k+1] = e[k] - dt K e[k-1]: for each
    eigenvalue l of K the roots of z^2 - z + l dt must lie inside the unit circle, and, as
    for the scalar gains, |l dt| < GAIN_DT_LIMIT (a diagonal K is refused exactly when a
    scalar gain of its diagonal would be)."""
    if not np.all(np.isfinite(K)):
        return "has a value that is not finite"
    for lam in np.linalg.eigvals(K):
        a = complex(lam) * dt_s
        roots = np.roots([1.0, -1.0, a])
        if not abs(a) < GAIN_DT_LIMIT:
            return (f"has an eigenvalue {_fmt_complex(lam)} 1/s: |l dt| = {abs(a):.3g} must be < {GAIN_DT_LIMIT:g} "
                    f"(|l| < {GAIN_DT_LIMIT / dt_s:.1f} 1/s)")
        if not np.max(np.abs(roots)) < 1.0:
            return (f"has an eigenvalue {_fmt_complex(lam)} 1/s that makes the delayed loop unstable "
                    f"(a root |z| = {np.max(np.abs(roots)):.4f} >= 1: its real part must be > 0)")
    return None


def _fmt_complex(lam: complex) -> str:
    lam = complex(lam)
    return f"{lam.real:g}" if abs(lam.imag) < 1e-12 else f"{lam.real:g}{lam.imag:+g}j"
