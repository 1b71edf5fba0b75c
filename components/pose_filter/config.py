"""Pose filter configuration."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from humanpt.runtime.config import Range, live


@dataclass(frozen=True)
class PoseFilterConfig:
    """``[pose_filter]``: world_T_tob from measurements and robot states, Kalman-filtered.
    The hand-eye transform and the target's triangle come from the rig."""

    # Measurement noise of a full pose, in the camera frame, turned into the world with the
    # camera's pose at the image: a stereo pose is far surer of its turn about the camera's
    # axis than of its tilt. What the filter sees is the camera's noise plus the robot's
    # pose at the image (its lag, the image stamps): in the twin's realistic world, closed
    # loop, 1-sigma 0.05 mm across, 0.11 mm along, 0.5 deg tilt, 0.04 deg about the axis,
    # with tails to 0.27 mm, 0.5 mm, 2 deg, 0.15 deg. A noise much below those lets the
    # manoeuvring model follow the robot's lag (spikes of 1-3 mm on the realistic world).
    sigma_position_mm: Annotated[float, Range(1e-4, 100, "mm")] = live(0.3, "1-sigma noise of a measured position across the camera's axis")
    sigma_depth_mm: Annotated[float, Range(1e-4, 100, "mm")] = live(0.3, "1-sigma noise of a measured position along the camera's axis")
    sigma_rotation_deg: Annotated[float, Range(1e-4, 45, "deg")] = live(0.8, "1-sigma noise of a measured orientation about axes across the camera's axis (tilt)")
    sigma_spin_deg: Annotated[float, Range(1e-4, 45, "deg")] = live(0.1, "1-sigma noise of a measured orientation about the camera's axis")
    # The paper's method (perception.method = "paper") is 4-12 times noisier, and its errors
    # are not white: its own isotropic noise (the values tuned for it before the above).
    paper_sigma_position_mm: Annotated[float, Range(1e-4, 100, "mm")] = live(0.3, "1-sigma noise of a position measured by the paper's method")
    paper_sigma_rotation_deg: Annotated[float, Range(1e-4, 45, "deg")] = live(0.8, "1-sigma noise of an orientation measured by the paper's method")
    paper_manoeuvres: bool = live(False, "follow manoeuvres with the paper's method too (its errors, to 3 deg, look like manoeuvres)")
    sigma_position_only_mm: Annotated[float, Range(1e-4, 100, "mm")] = live(1.5, "1-sigma noise of a position from one or two sources")
    # Process noise: white acceleration (how hard the operator's hand can change speed).
    accel_sigma_mm_s2: Annotated[float, Range(1e-3, 1e5, "mm/s^2")] = live(100.0, "white-acceleration noise of the target (hand)")
    ang_accel_sigma_deg_s2: Annotated[float, Range(1e-3, 1e5, "deg/s^2")] = live(10.0, "white angular-acceleration noise (the hand turns smoothly)")
    # Manoeuvres (an interacting multiple model): a second, manoeuvring model whose white
    # acceleration covers a hand's sudden start, stop, corner or turn; per block
    # (translation, rotation) the filter mixes the calm model above and this one by how
    # well each explains the measurements, so a real change of motion is followed within
    # a frame or two instead of being gated out, while smooth motion keeps the calm
    # model's smoothing. A measurement is gated out only if no model explains it.
    imm: bool = True
    manoeuvre_accel_sigma_mm_s2: Annotated[float, Range(1e-3, 1e6, "mm/s^2")] = live(500.0, "white-acceleration noise of the manoeuvring model")
    manoeuvre_ang_accel_sigma_deg_s2: Annotated[float, Range(1e-3, 1e6, "deg/s^2")] = live(300.0, "white angular-acceleration noise of the manoeuvring model")
    manoeuvre_every_s: Annotated[float, Range(1e-3, 1e4, "s")] = live(10.0, "mean time between manoeuvres (how long the calm mode lasts)")
    manoeuvre_lasts_s: Annotated[float, Range(1e-3, 1e4, "s")] = live(0.3, "mean duration of a manoeuvre")
    # A still target (the operator holds it, or it stands on a fixture): once the filtered
    # speed has stayed below still_mm_s / still_deg_s for still_after_ms, a copy of the
    # filter that assumes it stays put (a zero-velocity update with every measurement, the
    # process noise x still_q_scale) gives the estimate: a long average instead of a pose
    # wandering with velocity noise.  A measurement off it by more than still_release_mm /
    # still_release_deg (inside the gate; twice beyond it) ends that: the moving model,
    # which ran on underneath, gives the estimate again at once.
    still_detect: bool = live(True, "detect a still target and average it (zero-velocity updates)")
    still_mm_s: Annotated[float, Range(1e-3, 100, "mm/s")] = live(2.0, "the target may count as still below this filtered speed")
    still_deg_s: Annotated[float, Range(1e-3, 100, "deg/s")] = live(1.0, "... and below this filtered turn rate")
    still_after_ms: Annotated[float, Range(1, 60000, "ms")] = live(300.0, "... for this long")
    still_release_mm: Annotated[float, Range(1e-3, 100, "mm")] = live(0.3, "a still target moved: a measurement this far off")
    still_release_deg: Annotated[float, Range(1e-3, 90, "deg")] = live(0.3, "... or turned this far")
    still_drift_mm: Annotated[float, Range(1e-4, 100, "mm")] = live(0.05, "... or the mean offset of the latest 15 measurements this far")
    still_drift_deg: Annotated[float, Range(1e-4, 90, "deg")] = live(0.1, "... or turned that far on average")
    still_q_scale: Annotated[float, Range(1e-6, 1, "")] = live(0.01, "process noise factor while still")
    # Mahalanobis gate (chi-square, 6 and 3 dof at 99.9 %) and re-acquisition.
    gate_chi2_pose: Annotated[float, Range(0.1, 1e4, "chi2, 6 dof")] = live(22.46)
    gate_chi2_position: Annotated[float, Range(0.1, 1e4, "chi2, 3 dof")] = live(16.27)
    reset_after_rejects: Annotated[int, Range(1, 1000, "measurements")] = live(5, "consecutive gated measurements, consistent with each other, before the filter restarts on them")
    # The prediction horizon is one cycle of the robot link past a robot state's stamp (the
    # cycle being commanded), taken from the state (RobotState.cycle_period_ns;
    # humanpt.runtime.cycle): the filter has no cycle of its own.
    lost_after_ms: Annotated[float, Range(1, 60000, "ms")] = live(250.0, "no measurement for this long: status LOST")
    # Hysteresis: a lost track is tracked again only after this many measurements accepted
    # in a row, none more than lost_after_ms after the one before (the first acquisition is
    # at once). A track that keeps dropping out stays LOST instead of flapping.
    reacquire_measurements: Annotated[int, Range(1, 1000, "measurements")] = live(3, "after LOST, measurements accepted in a row before the status is tracked again")
    # Robot poses at the image stamp: interpolate, or extrapolate at most this far.
    max_extrapolation_ms: Annotated[float, Range(0, 1000, "ms")] = 60.0
    # A measurement newer than the latest robot state waits (at most this long) for the
    # state after it, so that the robot pose at the image is interpolated: extrapolating it
    # from the states before is off by up to 0.6 mm whenever the robot accelerates (a
    # STATUS frame takes 11 ms on a 38 400 baud line).  0: never wait.
    wait_for_robot_ms: Annotated[float, Range(0, 1000, "ms")] = live(60.0, "hold a measurement this long for the robot state after its stamp")
    # Robot states kept for those lookups: 512 is 2 s at RSI's 4 ms (14 s at ALTER's 28 ms).
    # A measurement older than the oldest state is extrapolated backwards from the two
    # oldest, 4 ms apart: with 64 states (256 ms at 4 ms) a 257 ms-old image came out 0.4-0.5
    # mm off (issue 22).
    robot_history: Annotated[int, Range(2, 100000, "states")] = 512
    # A robot state stamped this far from the time it reaches the filter (the receiver's
    # clock) is not believed: a forged future stamp would otherwise lock the buffer.
    max_stamp_skew_ms: Annotated[float, Range(1, 60000, "ms")] = 1000.0

    def __post_init__(self):
        for name in ("sigma_position_mm", "sigma_depth_mm", "sigma_rotation_deg", "sigma_spin_deg", "paper_sigma_position_mm",
                     "paper_sigma_rotation_deg",
                     "sigma_position_only_mm", "accel_sigma_mm_s2",
                     "ang_accel_sigma_deg_s2", "manoeuvre_accel_sigma_mm_s2",
                     "manoeuvre_ang_accel_sigma_deg_s2", "manoeuvre_every_s", "manoeuvre_lasts_s", "gate_chi2_pose", "gate_chi2_position", "lost_after_ms",
                     "still_mm_s", "still_deg_s", "still_after_ms", "still_release_mm", "still_release_deg",
                     "still_drift_mm", "still_drift_deg",
                     "still_q_scale"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.still_q_scale > 1:
            raise ValueError(f"still_q_scale must be within (0, 1], got {self.still_q_scale}")
        if self.max_extrapolation_ms < 0:
            raise ValueError("max_extrapolation_ms must be >= 0")
        if self.reset_after_rejects < 1 or self.robot_history < 2:
            raise ValueError("reset_after_rejects must be >= 1 and robot_history >= 2")
