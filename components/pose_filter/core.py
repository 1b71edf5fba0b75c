"""pose_filter core: tob measurements + robot states -> filtered world_T_tob per ALTER cycle.

For each measurement (camera_T_tob at the image's capture stamp) the robot's flange pose
at that stamp is interpolated from the robot states around it, giving
``world_T_tob = world_T_flange @ flange_T_camera @ camera_T_tob`` (paper §4 step 8).  The
Kalman filter (kalman.py) is advanced to the capture stamp and updated; a measurement
whose Mahalanobis distance is beyond the gate is rejected and reported, and after
``reset_after_rejects`` rejections in a row the filter restarts on the measurements
(the target really moved).  Position-only measurements (one or two sources) update the
position of G, placed from the visible sources and the predicted orientation.

On every robot state (one per ALTER cycle), and again after every accepted measurement,
the state predicted one link cycle past the latest robot state's stamp (the cycle the state
carries, ``RobotState.cycle_period_ns``) is published
as ``pose_filter/tob_state`` for that cycle (the controller re-commands the cycle with it).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from humanpt.geometry.frames import FrameGraph, TimedPoses, segment_reach
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import rotvec_from_matrix
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.kalman import PoseIMM, PoseKalman
from humanpt.runtime import cycle as cell_cycle
from humanpt.runtime.core import Core, Output, Port, count_decades
from humanpt.runtime.limiter import EventLimiter, suffix
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import MessageError, from_pose, from_vector3, pose

TOPIC_STATE = "pose_filter/tob_state"
STILL_DRIFT_WINDOW = 15  # measurements (0.5 s at 30 images/s) whose mean offset shows a drift
EVENT_INTERVAL_NS = 1_000_000_000  # at most one event of a code per second of input time (rate-limited codes)


class PoseFilterCore(Core):
    name = "pose_filter"
    realtime = True  # on the robot link's cycle (a state per cycle): see runtime.tuning.tune_realtime
    config_type = PoseFilterConfig
    ports = (
        Port("perception/tob", pb.TobMeasurement, "_on_tob"),
        Port("robot_gateway/robot_state", pb.RobotState, "_on_robot_state"),
        Port("clock_step", pb.Event, "_on_clock_step"),  # the wall clock stepped (runtime/clock.py)
    )

    uses_rig = True  # the hand-eye transform and the target's triangle
    # Snapshots (runtime/snapshot.py): the still target's filter is made when the target stops.
    state_types = (PoseKalman,)

    def __init__(self, config: PoseFilterConfig, rig: Rig | None = None):
        super().__init__(config, Rig() if rig is None else rig)
        # The cell's frames (geometry.frames): world -> flange from the robot states (m), kept
        # in stamp order (a repeated or earlier stamp is refused: _on_robot_state decides),
        # looked up at an image's stamp on the segment around it or extrapolated from the last
        # two states by at most max_extrapolation_ms; flange -> camera the rig's hand-eye.
        self.frames = FrameGraph()
        self.robot = self.frames.add_timed("world", "flange", TimedPoses(config.robot_history),
                                           segment_reach(int(config.max_extrapolation_ms * 1e6)))
        # The prediction horizon (ns): the link's cycle, from the latest robot state that
        # carries it (runtime/cycle.py); until then, or from states carrying none, the fallback.
        self.horizon_ns = cell_cycle.FALLBACK_NS
        self._backwards = 0  # robot states in a row stamped before the latest one
        self._rejected_states: dict[str, int] = {}
        self._build(config)
        self.kf: PoseIMM | PoseKalman = (
            PoseIMM(self._noises, config.manoeuvre_every_s, config.manoeuvre_lasts_s) if config.imm
            else PoseKalman(self._accel, self._ang_accel))
        self.rejects_in_a_row = 0
        # The latest measurements gated out in a row (stamp ns, world_T_tob): the filter
        # restarts on them only if they agree with each other (the target really jumped),
        # never on a burst of inconsistent wrong poses (wrong pairings, reflections).
        self._rejected: deque[tuple[int, np.ndarray, np.ndarray, bool]] = deque(maxlen=config.reset_after_rejects)
        self._manoeuvring = False  # a manoeuvre mode probability above 0.5
        # "manoeuvre", "no_robot_pose", "out_of_order": at most one a second of input time,
        # the next one saying how many were held back (robot states stamped 2 s off gave
        # 24 444 "no_robot_pose" in 4 s, issue 29).
        self._limiter = EventLimiter(EVENT_INTERVAL_NS)
        self.manoeuvres = 0
        self.gated_total = 0
        self.accepted = 0
        self.last_measurement_ns: int | None = None
        self.last_status = pb.TOB_STATUS_LOST
        # Tracking hysteresis: LOST as soon as no measurement came for lost_after_ms, but once
        # lost, tracked again only after reacquire_measurements accepted in a row, none more
        # than lost_after_ms after the one before (a track that keeps dropping out stays
        # LOST instead of flapping: 48 LOST/TRACK switches in 4 s, issue 29).
        self._tracking = False  # published as tracked (once a measurement is in)
        self._lost_once = False  # the track was lost after the first acquisition
        self._run = 0  # measurements accepted in a row, each within lost_after_ms of the one before
        self._cycle: tuple[int, int] | None = None  # (stamp ns, cycle) of the latest robot state
        self._fresh = False
        self._pose_at_measurement: tuple[tuple[int, int], pb.Pose] | None = None
        # The latest full measurement's own world pose, before the filter (the paper's raw
        # state vector, step 10): (stamp ns, pose); published with the states for its stamp.
        self._measured: tuple[int, pb.Pose] | None = None
        # While the target is still: the filter that averages it (zero-velocity updates,
        # calm process noise), started from the moving model, which runs on regardless.
        self.still_kf: PoseKalman | None = None
        self._waiting_said = False  # "waiting_for_robot" said once
        # Measurements newer than the latest robot state: (time received, message).
        self._pending: deque[tuple[int, pb.TobMeasurement]] = deque()
        self._slow_since_ns: int | None = None  # first measurement of the current slow run
        self._off_in_a_row = 0  # measurements off a still estimate, in a row
        # The latest offsets (mm, deg vectors) of measurements from the still estimate: a slow
        # drift shows in their mean long before any one of them is off by the release distance.
        self._offsets: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=STILL_DRIFT_WINDOW)

    def _build(self, c: PoseFilterConfig) -> None:
        self.flange_T_camera_m = self.rig.hand_eye.flange_T_camera_m()
        self.frames.add_static("flange", "camera", self.flange_T_camera_m)
        self.frames.set_lookup("flange", segment_reach(int(c.max_extrapolation_ms * 1e6)))
        # The rig's camera-to-robot time offset (calibration.timing; > 0: an image was taken
        # that long before its stamp): each measurement is placed at its capture time on the
        # robot's clock, where the robot's pose is looked up and the filter updated.
        self.capture_shift_ns = int(round(self.rig.timing.camera_time_offset_ms * 1e6))
        self._accel = c.accel_sigma_mm_s2 * 1e-3
        self._ang_accel = np.radians(c.ang_accel_sigma_deg_s2)
        self._noises = ((self._accel, self._ang_accel),
                        (c.manoeuvre_accel_sigma_mm_s2 * 1e-3, np.radians(c.manoeuvre_ang_accel_sigma_deg_s2)))
        # Variances of a full pose in the camera frame: p across, across, along; r tilt, tilt, spin.
        self._var_pose_camera = np.array([(c.sigma_position_mm * 1e-3) ** 2] * 2 + [(c.sigma_depth_mm * 1e-3) ** 2]
                                         + [np.radians(c.sigma_rotation_deg) ** 2] * 2 + [np.radians(c.sigma_spin_deg) ** 2])
        self._var_pose_paper = np.array([(c.paper_sigma_position_mm * 1e-3) ** 2] * 3
                                        + [np.radians(c.paper_sigma_rotation_deg) ** 2] * 3)
        self.R_position = np.eye(3) * (c.sigma_position_only_mm * 1e-3) ** 2
        # Zero-velocity pseudo-measurement noise: a still target's speed is ~0 to this.
        self.R_still = np.diag([(0.01e-3) ** 2] * 3 + [np.radians(0.01) ** 2] * 3)
        self.tob_p_sources_m = self.rig.target_model().source_positions_mm * 1e-3

    def on_config_changed(self, old, new) -> None:
        self._build(new)
        if isinstance(self.kf, PoseIMM):
            self.kf.set_noises(self._noises, new.manoeuvre_every_s, new.manoeuvre_lasts_s)
        for kf in (self.kf, self.still_kf):
            if isinstance(kf, PoseKalman):
                kf.accel_sigma, kf.ang_accel_sigma = self._accel, self._ang_accel
        if new.reset_after_rejects != self._rejected.maxlen:
            self._rejected = deque(self._rejected, maxlen=new.reset_after_rejects)
        if self.still_kf is not None:
            self.still_kf.q_scale = new.still_q_scale

    # ------------------------------------------------------------------------------------
    def _on_tob(self, t_ns: int, msg: pb.TobMeasurement) -> list[Output]:
        self._fresh = False
        latest = self.robot.latest
        if (self.config.wait_for_robot_ms > 0 and latest is not None
                and msg.status in (pb.TOB_STATUS_FULL, pb.TOB_STATUS_POSITION_ONLY)
                and msg.header.stamp_ns - self.capture_shift_ns > latest[0]):
            # The robot state of the image's instant is still on its way (a serial line's
            # frame time, a bus hop): hold the measurement until it is in, so the robot pose
            # is interpolated, not extrapolated from the states before (which is off
            # whenever the robot accelerates).  Older held ones go first, in stamp order.
            self._pending.append((t_ns, msg))
            outs = self._release_pending(t_ns, keep=2)
            return self._after_measurements(t_ns, outs)
        outs = self._release_pending(t_ns, keep=0) + self._on_measurement(t_ns, msg)
        return self._after_measurements(t_ns, outs)

    def _after_measurements(self, t_ns: int, outs: list[Output]) -> list[Output]:
        if self._fresh and self._cycle is not None:
            # A new measurement: the state for the current cycle again, at once, so the
            # controller's command for the coming cycle uses it (image-to-command latency
            # is processing time, not up to a cycle of waiting).
            topic, st = self._state(t_ns, *self._cycle)
            st.after_measurement = True
            outs.append((topic, st))
        return outs

    def _on_robot_state(self, t_ns: int, msg: pb.RobotState) -> list[Output]:
        try:
            world_T_flange = from_pose(msg.world_T_flange)
        except MessageError as e:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_robot_state", str(e))]
        stamp_ns = msg.header.stamp_ns
        skew_ns = stamp_ns - t_ns
        if abs(skew_ns) > self.config.max_stamp_skew_ms * 1e6:
            return self._reject_robot_state(t_ns, "stamp_skew", (
                f"robot state of cycle {msg.cycle} stamped {skew_ns / 1e9:+.3f} s from this clock "
                f"(more than max_stamp_skew_ms = {self.config.max_stamp_skew_ms:g}): dropped"))
        period_ns = cell_cycle.from_state(msg.cycle_period_ns)
        if period_ns is not None:
            self.horizon_ns = period_ns
        if not self.robot.add(stamp_ns, world_T_flange):
            # Backwards or repeated. A few in a row, each near this clock, is the robot's
            # clock stepping back (a restart, an NTP step): start the buffer again on them.
            self._backwards += 1
            if self._backwards < 3:
                return self._reject_robot_state(t_ns, "stamp_backwards", (
                    f"robot state of cycle {msg.cycle} stamped {(stamp_ns - self.robot.latest[0]) / 1e6:+.1f} "
                    "ms from the latest one: dropped"))
            self.robot.clear()
            self.robot.add(stamp_ns, world_T_flange)
            self._backwards = 0
            self._cycle = (stamp_ns, msg.cycle)
            return [self.event(t_ns, pb.SEVERITY_WARNING, "robot_clock_reset",
                               "three robot states in a row stamped before the latest: the robot's clock "
                               "went back; the robot pose buffer starts again"),
                    self._state(t_ns, stamp_ns, msg.cycle)]
        self._backwards = 0
        self._cycle = (stamp_ns, msg.cycle)
        outs = self._release_pending(t_ns)
        return [*outs, self._state(t_ns, stamp_ns, msg.cycle)]

    def _on_clock_step(self, t_ns: int, msg: pb.Event) -> list[Output]:
        """The wall clock stepped by ``msg.text`` ns: the times kept by input time (how long a
        measurement has waited for the robot, the event limiter) move with it. Stamps do not:
        they name instants in the time base they were taken in."""
        try:
            step = int(msg.text)
        except ValueError:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_input", f"clock_step {msg.text[:40]!r} is not a "
                               "step in ns: ignored")]
        self._pending = deque((t_in + step, m) for t_in, m in self._pending)
        self._limiter.shift(step)
        return []

    def use_cycle(self, cycle_period_ns: int) -> None:
        """Predict this far (ns) past a robot state: a state's cycle, or what an old
        recording's config said (its robot states carry none; runtime.replay)."""
        self.horizon_ns = int(cycle_period_ns)

    # -- measurements waiting for the robot pose at their stamp ------------------------
    def _release_pending(self, t_ns: int, keep: int | None = None) -> list[Output]:
        """Use the held measurements that the robot states now bracket (interpolation), or
        that waited ``wait_for_robot_ms``, or beyond the newest ``keep``: those extrapolate
        as before."""
        outs: list[Output] = []
        wait_ns = self.config.wait_for_robot_ms * 1e6
        latest = self.robot.latest
        while self._pending:
            t_in, m = self._pending[0]
            bracketed = latest is not None and latest[0] >= m.header.stamp_ns - self.capture_shift_ns
            if not (bracketed or t_ns - t_in >= wait_ns or (keep is not None and len(self._pending) > keep)):
                break
            self._pending.popleft()
            outs += self._on_measurement(t_ns, m)
        return outs

    def _reject_robot_state(self, t_ns: int, why: str, text: str) -> list[Output]:
        """An event for the 1st, 10th, 100th... robot state rejected for ``why``."""
        n = count_decades(self._rejected_states, why)
        if n is None:
            return []
        return [self.event(t_ns, pb.SEVERITY_WARNING, "robot_state_rejected", f"{text} ({n} so far)")]

    def _state(self, t_ns: int, robot_stamp_ns: int, cycle: int) -> Output:
        c = self.config
        target_ns = robot_stamp_ns + self.horizon_ns
        lost = (self.last_measurement_ns is None
                or robot_stamp_ns - self.last_measurement_ns > c.lost_after_ms * 1e6)
        if lost and self._tracking:
            self._tracking, self._lost_once, self._run = False, True, 0
        status = pb.TOB_STATUS_LOST if lost or not self._tracking or not self.kf.initialised else self.last_status
        out = pb.TobState(header=self.next_header(TOPIC_STATE, target_ns, "world"), status=status,
                          gated_outliers=self.gated_total, cycle=cycle, measurements=self.accepted)
        if self.kf.initialised:
            T, vel, P = self.active.predicted(target_ns)
            out.world_T_tob.CopyFrom(pose(T))
            vx, vy, vz, wx, wy, wz = vel.tolist()
            out.linear_velocity_m_s.CopyFrom(pb.Vector3(x=vx, y=vy, z=vz))
            out.angular_velocity_rad_s.CopyFrom(pb.Vector3(x=wx, y=wy, z=wz))
            out.covariance.extend(P.ravel().tolist())
            out.covariance_dim = P.shape[0]
            out.measurement_stamp_ns = self.last_measurement_ns or 0
            if self.last_measurement_ns is not None:
                out.world_T_tob_at_measurement.CopyFrom(self._pose_at(self.last_measurement_ns))
                if self._measured is not None and self._measured[0] == self.last_measurement_ns:
                    out.world_T_tob_measured.CopyFrom(self._measured[1])
        return TOPIC_STATE, out

    def _pose_at(self, stamp_ns: int) -> pb.Pose:
        """The filter's pose at ``stamp_ns`` as a message, kept until the filter changes
        (every robot state between two measurements asks for the same one)."""
        kf = self.active
        key = (kf.version, stamp_ns)
        if self._pose_at_measurement is None or self._pose_at_measurement[0] != key:
            self._pose_at_measurement = (key, pose(kf.predicted_pose(stamp_ns)))
        return self._pose_at_measurement[1]

    def _on_measurement(self, t_ns: int, msg: pb.TobMeasurement) -> list[Output]:
        if msg.status not in (pb.TOB_STATUS_FULL, pb.TOB_STATUS_POSITION_ONLY):
            return []
        stamp = msg.header.stamp_ns - self.capture_shift_ns  # the capture, on the robot's clock
        if stamp < 0:
            # Taken before the time base began (an image of the first few ms, moved back by the
            # rig's camera-to-robot offset): no robot state can place it, and no stamp says it.
            return []
        world_T_camera = self.frames.lookup("world", "camera", stamp)
        if world_T_camera is None:
            if len(self.robot) == 0:
                # Start-up: images before the robot's first state (its link is coming up).
                if self._waiting_said:
                    return []
                self._waiting_said = True
                return [self.event(t_ns, pb.SEVERITY_INFO, "waiting_for_robot",
                                   "no robot state yet: measurements dropped until the first one")]
            return self._limited(t_ns, pb.SEVERITY_WARNING, "no_robot_pose",
                                 f"no robot state near the image stamp {stamp} ns; measurement dropped")
        if self.kf.initialised and stamp < self.kf.t_ns:
            return self._limited(t_ns, pb.SEVERITY_DEBUG, "out_of_order",
                                 f"measurement at {stamp} ns is older than the filter ({self.kf.t_ns} ns)")
        try:
            if msg.status == pb.TOB_STATUS_FULL:
                world_T_tob = world_T_camera @ from_pose(msg.camera_T_tob)
                self._measured = (stamp, pose(world_T_tob))  # step 10's X_WG, unfiltered
                # The paper's method's errors (to 3 deg, not white) look like manoeuvres.
                calm_only = msg.method == pb.PERCEPTION_METHOD_PAPER and not self.config.paper_manoeuvres
                return self._update_full(t_ns, stamp, world_T_tob, self._pose_noise(world_T_camera[:3, :3], msg.method),
                                         calm_only)
            points = np.array([from_vector3(p) for p in msg.points_camera_m], dtype=float)
            if points.size == 0 or not np.all(np.isfinite(points)):
                return []
            world_p = points @ world_T_camera[:3, :3].T + world_T_camera[:3, 3]
            return self._update_position(t_ns, stamp, world_p)
        except MessageError as e:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_measurement", str(e))]

    def _pose_noise(self, world_R_camera: np.ndarray, method: int) -> np.ndarray:
        """(6, 6) covariance (m^2, rad^2, world frame) of a full pose measured by a camera
        turned as ``world_R_camera`` with perception method ``method``."""
        var = self._var_pose_paper if method == pb.PERCEPTION_METHOD_PAPER else self._var_pose_camera
        R = np.zeros((6, 6))
        for k in (0, 3):
            R[k:k + 3, k:k + 3] = (world_R_camera * var[k:k + 3]) @ world_R_camera.T
        return R

    def _update_full(self, t_ns: int, stamp: int, world_T_tob: np.ndarray, R_pose: np.ndarray,
                     calm_only: bool = False) -> list[Output]:
        if not self.kf.initialised:
            self.kf.reset(stamp, world_T_tob, calm_only)
            self._end_still()
            self._accepted(stamp, pb.TOB_STATUS_FULL)
            return [self.event(t_ns, pb.SEVERITY_INFO, "filter_start", "filter started on a full pose")]
        if self.last_measurement_ns is not None and stamp - self.last_measurement_ns > self.config.lost_after_ms * 1e6:
            self._end_still()  # lost and found again: not known to be still any more
        self.kf.predict_to(stamp)
        # Right after a gated measurement only the calm model may let one in: the manoeuvring
        # model's reach grows with the gap (~20 mm after five frames), so a burst of wrong
        # poses would get in; a real jump is caught by the restart on consistent rejects.
        gate = self.kf.update_pose(world_T_tob, R_pose, self.config.gate_chi2_pose,
                                   manoeuvre_gates=self.rejects_in_a_row == 0, calm_only=calm_only)
        # (The still check reads only the still filter and whether the moving one gated.)
        outs = self._check_still_moved(t_ns, stamp, world_T_tob, inside=gate.accepted)
        outs += self._after_gate(t_ns, stamp, gate, pb.TOB_STATUS_FULL, (world_T_tob, R_pose, calm_only))
        if gate.accepted:
            outs += self._still_update(t_ns, stamp, world_T_tob, R_pose)
        return outs

    # -- a still target ---------------------------------------------------------------
    @property
    def active(self) -> PoseKalman:
        """The filter whose estimate is published: the still one while the target is still."""
        return self.still_kf if self.still_kf is not None else self.kf

    def _end_still(self) -> None:
        if self.still_kf is not None:
            self._pose_at_measurement = None  # another filter gives the estimate now
        self.still_kf = None
        self._slow_since_ns = None
        self._off_in_a_row = 0
        self._offsets.clear()

    def _check_still_moved(self, t_ns: int, stamp: int, world_T_tob: np.ndarray | None,
                           inside: bool = True) -> list[Output]:
        """While still: a measurement (``None``: a position-only one, which ends it) off the
        still estimate beyond the release distances, once inside the moving model's gate or
        twice in a row beyond it, or the mean offset of the latest ones beyond the drift
        distances, means the target moves: the moving model, which has run on all along,
        gives the estimate again at once. ``inside``: the measurement passed the moving
        model's gate."""
        if self.still_kf is None:
            return []
        c = self.config
        off = True
        drift = False
        if world_T_tob is not None:
            T = self.still_kf.predicted_pose(stamp)
            dp_mm = (world_T_tob[:3, 3] - T[:3, 3]) * 1e3
            dr_deg = np.degrees(rotvec_from_matrix(world_T_tob[:3, :3] @ T[:3, :3].T, assume_valid=True))
            off = float(np.linalg.norm(dp_mm)) > c.still_release_mm or float(np.linalg.norm(dr_deg)) > c.still_release_deg
            if inside:
                self._offsets.append((dp_mm, dr_deg))
            n = len(self._offsets)
            if n >= 5:
                # The mean of n offsets, against thresholds for the full window scaled by
                # sqrt(window / n): the same false-alarm rate, an earlier verdict on a drift.
                k = (self._offsets.maxlen / n) ** 0.5
                drift = (float(np.linalg.norm(np.mean([o[0] for o in self._offsets], axis=0))) > k * c.still_drift_mm
                         or float(np.linalg.norm(np.mean([o[1] for o in self._offsets], axis=0)))
                         > k * c.still_drift_deg)
        self._off_in_a_row = self._off_in_a_row + 1 if off else 0
        # Beyond the gate (a glitch, which the gate rejects, or a jump): only twice in a row.
        if not (off and inside) and not drift and self._off_in_a_row < 2:
            return []
        self._end_still()
        return [self.event(t_ns, pb.SEVERITY_INFO, "target_moving", "the still target moves: full motion model")]

    def _still_update(self, t_ns: int, stamp: int, world_T_tob: np.ndarray, R_pose: np.ndarray) -> list[Output]:
        c = self.config
        if not c.still_detect:
            self._end_still()
            return []
        if self.still_kf is not None:
            self.still_kf.predict_to(stamp)
            self.still_kf.update_pose(world_T_tob, R_pose, np.inf)
            self.still_kf.update_zero_velocity(self.R_still)
            return []
        v = self.kf.x[6:12]
        slow = (float(np.linalg.norm(v[:3])) * 1e3 < c.still_mm_s
                and float(np.degrees(np.linalg.norm(v[3:]))) < c.still_deg_s)
        if not slow:
            self._slow_since_ns = None
            return []
        if self._slow_since_ns is None:
            self._slow_since_ns = stamp
        if stamp - self._slow_since_ns < c.still_after_ms * 1e6:
            return []
        self._off_in_a_row = 0
        self.still_kf = self.kf.collapsed()
        self._pose_at_measurement = None
        self.still_kf.q_scale = c.still_q_scale
        self.still_kf.update_zero_velocity(self.R_still)
        return [self.event(t_ns, pb.SEVERITY_INFO, "target_still", "the target is still: averaging it")]

    def _update_position(self, t_ns: int, stamp: int, world_p_m: np.ndarray) -> list[Output]:
        if not self.kf.initialised:
            return []  # a position alone cannot start an orientation
        self.kf.hold_orientation()  # not measured: held, not turned on (kalman.hold_orientation)
        self.kf.predict_to(stamp)
        moved = self._check_still_moved(t_ns, stamp, None)
        T_pred = self.kf.predicted_pose(stamp)
        # Match each visible source to the nearest predicted source; G = source - R @ offset.
        world_sources = self.tob_p_sources_m @ T_pred[:3, :3].T + T_pred[:3, 3]
        g = []
        for p in world_p_m:
            k = int(np.argmin(np.linalg.norm(world_sources - p, axis=1)))
            g.append(p - T_pred[:3, :3] @ self.tob_p_sources_m[k])
        gate = self.kf.update_position(np.mean(g, axis=0), self.R_position / len(g),
                                       self.config.gate_chi2_position, manoeuvre_gates=self.rejects_in_a_row == 0)
        return moved + self._after_gate(t_ns, stamp, gate, pb.TOB_STATUS_POSITION_ONLY, None)

    def _after_gate(self, t_ns, stamp, gate, status, pose) -> list[Output]:
        """``pose``: (world_T_tob, its (6, 6) covariance, calm_only) of a full measurement, or None."""
        if gate.accepted:
            self._accepted(stamp, status)
            return self._manoeuvre_event(t_ns)
        self.gated_total += 1
        self.rejects_in_a_row += 1
        outs = [self.event(t_ns, pb.SEVERITY_WARNING, "outlier",
                           f"measurement at {stamp} ns gated out (Mahalanobis^2 {gate.mahalanobis2:.1f}); "
                           f"{self.rejects_in_a_row} in a row")]
        if pose is None:
            return outs
        self._rejected.append((stamp, *pose))
        if self.rejects_in_a_row >= self.config.reset_after_rejects and self._consistent(self._rejected):
            first_ns, first, _, calm = self._rejected[0]
            self.kf.reset(first_ns, first, calm)
            for ts, T, R, calm in list(self._rejected)[1:]:  # re-run them: it starts with their motion
                self.kf.predict_to(ts)
                self.kf.update_pose(T, R, math.inf, calm_only=calm)
            self._end_still()
            self._accepted(stamp, status)
            outs.append(self.event(t_ns, pb.SEVERITY_WARNING, "filter_reset",
                                   f"the target moved beyond the gate {self.config.reset_after_rejects} times in a row, "
                                   "consistently: filter restarted on it"))
        return outs

    def _consistent(self, measurements) -> bool:
        """Whether poses [(stamp ns, world_T_tob, covariance, calm_only)] form one track: a
        manoeuvring-model filter started on the first one gates none of the others out."""
        c = self.config
        (t0, T0, *_), *rest = measurements
        kf = PoseKalman(*self._noises[1])
        kf.reset(t0, T0)
        for ts, T, R, _ in rest:
            kf.predict_to(ts)
            if not kf.update_pose(T, R, c.gate_chi2_pose).accepted:
                return False
        return True

    def _manoeuvre_event(self, t_ns: int) -> list[Output]:
        """``manoeuvre`` (info) when a manoeuvre mode becomes the likelier one: at most one a
        second, counting those in between."""
        if not isinstance(self.kf, PoseIMM):
            return []
        p_trans, p_rot = self.kf.manoeuvre_probability
        now = max(p_trans, p_rot) > 0.5
        started, self._manoeuvring = now and not self._manoeuvring, now
        if not started:
            return []
        self.manoeuvres += 1
        what = " and ".join(w for w, p in (("moves", p_trans), ("turns", p_rot)) if p > 0.5)
        return self._limited(t_ns, pb.SEVERITY_INFO, "manoeuvre",
                             f"the target {what} abruptly: the manoeuvring model follows it")

    def _limited(self, t_ns: int, severity: int, code: str, text: str) -> list[Output]:
        """The event, unless one of ``code`` went out less than a second of input time ago
        (then it is counted, and the next one says how many were held back)."""
        held = self._limiter.allow(code, t_ns)
        return [] if held is None else [self.event(t_ns, severity, code, text + suffix(held))]

    def _accepted(self, stamp: int, status: int) -> None:
        gap_ok = (self.last_measurement_ns is not None
                  and stamp - self.last_measurement_ns <= self.config.lost_after_ms * 1e6)
        if not gap_ok and self.last_measurement_ns is not None:
            self._lost_once = True  # a gap over lost_after_ms: lost in between
        self._run = self._run + 1 if gap_ok else 1
        self._tracking = not self._lost_once or self._run >= self.config.reacquire_measurements
        self.rejects_in_a_row = 0
        self._rejected.clear()
        self.accepted += 1
        self.last_measurement_ns = stamp
        self.last_status = status
        self._fresh = True
