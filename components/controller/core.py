"""controller core: the pseudo stereo visual servo (paper §5), path recording, driver-tip
calibration (§4.1) and playback.

Once per ALTER cycle (on each ``pose_filter/tob_state``, which the filter publishes for
every robot state) it computes the flange correction and publishes it on
``controller/command``, with a ``controller/status``: by default (``command_ahead``) for
the NEXT cycle, from where this cycle's step will have put the flange, so the gateway has
each cycle's command before that cycle's STATUS arrives (a cycle with nothing sent for
it, e.g. the first, is predicted with the gateway's velocity hold or zero).  Modes:

* track: D (on the camera axis at dz) follows G; position-only when one or two sources
  are seen; when the target is lost, hold ("stop on current location") or return to the
  start pose, by the ``lost_action`` parameter;
* hold, return: by command;
* calibrate: track while collecting N poses of the TOB pivoting on its driver tip, then
  solve the tip (least-squares pivot; and the paper's eq. 10-13 when P' is given);
* playback: the tool tip follows a path (the one just recorded, or one given).

Commands (``console/command``, verb and JSON args): track, hold, return, record_start,
record_stop, save {"file", "overwrite"}, calibrate {"samples", "pivot_mm"}, playback {"points",
"speed_mm_s"}, stop.  Every command's arguments are checked (:func:`check_command`: known
names, types, physical ranges, a plain file name for save); a bad one gets a ``bad_command``
event and changes nothing.  Recording: while on, a ``controller/path`` point (G and, with a
driver, the tip P) is published at the first measurement after record_start, then at every
measurement that is ``recording_spacing_mm`` from the last point and at least every
``recording_delay_cycles`` cycles (``recording_spacing_mm = 0``: only every
``recording_delay_cycles`` cycles, the first after as many), also with one or two sources (the
orientation then flagged ``orientation_held``), with the filter's covariance; the shell
appends it to the path file.  Each ``controller/status`` reports how much of the field of
view was left (``fov_margin_px``) and G's offset in the image; at the speed limits the
servo keeps G near D first (``saturation``, :func:`humanpt.controller.law.position_first`).
"""

from __future__ import annotations

import dataclasses
import json
import re
from typing import Annotated, Any

import numpy as np

from humanpt.controller import law, playback
from humanpt.controller.config import ControllerConfig
from humanpt.controller.playback import MAX_ARGS_CHARS, MAX_PLAYBACK_POINTS
from humanpt.geometry.calibration import calibrate_tip_paper, calibrate_tip_pivot
from humanpt.geometry.errors import GeometryError
from humanpt.geometry.rig import Calibration, Rig, Tip, flange_T_desired
from humanpt.geometry.transforms import (
    interpolate_transform,
    invert_transform,
    rotation_angle_rad,
    transform_from_x,
    x_from_transform,
)
from humanpt.geometry.units import to_m, to_mm
from humanpt.runtime import cycle as cell_cycle
from humanpt.runtime.config import ConfigError, Mm, Range, SpeedMmS, coerce
from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import MessageError, from_pose, from_vector3, pose, vector3

T_CMD, T_STATUS, T_PATH = "controller/command", "controller/status", "controller/path"


def _next(cycle: int) -> int:
    """The ALTER cycle after ``cycle`` (a uint32 counter: it wraps)."""
    return (cycle + 1) & 0xFFFFFFFF


def _prev(cycle: int) -> int:
    return (cycle - 1) & 0xFFFFFFFF


def flange_T_desired_mm(c: ControllerConfig, rig: Rig | None = None) -> np.ndarray:
    """The desired frame D in the flange frame (4, 4), mm, of a controller configured by
    ``c`` on ``rig`` (None: the nominal rig): on the camera's optical axis at dz, parallel
    to the camera (Section 5), as far as the rig's hand-eye transform knows."""
    return flange_T_desired((Rig() if rig is None else rig).hand_eye.flange_T_camera_mm(), c.dz_mm)


def flange_T_desired_m(c: ControllerConfig, rig: Rig | None = None) -> np.ndarray:
    """:func:`flange_T_desired_mm` in metres."""
    return to_m(flange_T_desired_mm(c, rig))


def _pose_covariance(st: pb.TobState) -> np.ndarray | None:
    """The (6, 6) covariance of [p (m), r (rad)] of a filter state (the upper-left block of
    its [p, r, v, w] covariance), or None when it carries none (or a malformed one)."""
    n = st.covariance_dim
    if n < 6 or len(st.covariance) != n * n:
        return None
    return np.asarray(st.covariance, dtype=float).reshape(n, n)[:6, :6]


def tip_position_covariance(cov_pr: np.ndarray, world_p_tip_from_g: np.ndarray) -> np.ndarray:
    """(3, 3) covariance of the tip's position P = p + R t, from the (6, 6) covariance of
    [p, r] (r: a small world-frame rotation, R' = exp(r) R) and the tip's offset from G in
    the world frame, R t (3,): first order, dP = dp + dr x (R t) = [I, -[R t]x] [dp; dr]."""
    a = np.asarray(world_p_tip_from_g, dtype=float)
    skew = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    J = np.hstack([np.eye(3), -skew])
    return J @ cov_pr @ J.T


# Measurement stamps this far behind the last path point's are a clock step back, not a late
# measurement (the filter delivers in order; late ones are milliseconds, not seconds).
CLOCK_STEP_BACK_NS = 500_000_000

class ControllerCore(Core):
    name = "controller"
    realtime = True  # on the robot link's cycle (a command per cycle): see runtime.tuning.tune_realtime
    config_type = ControllerConfig
    ports = (
        Port("pose_filter/tob_state", pb.TobState, "_cycle"),
        Port("robot_gateway/robot_state", pb.RobotState, "_on_robot_state"),
        Port("console/command", pb.Command, "_on_console"),
        # The shell's path writer reports what a save did (a local input).
        Port("path_file", pb.Event, "_on_path_file"),
    )

    uses_rig = True  # the hand-eye transform (where D is) and the driver tip
    _last_mode: int | None = None  # the mode of the last command (an event says each change)

    def __init__(self, config: ControllerConfig, rig: Rig | None = None):
        super().__init__(config, Rig() if rig is None else rig)
        self.mode = pb.CONTROL_MODE_TRACK if config.start_mode == "track" else pb.CONTROL_MODE_HOLD
        self.robot: tuple[int, int, np.ndarray] | None = None  # (cycle, stamp_ns, world_T_flange m)
        self.start_world_T_flange: np.ndarray | None = None
        self.recording = config.record_on_start
        self.path: list[pb.PathPoint] = []
        # The recorded path as a playback needs it, kept as each point is recorded: (6,)
        # mm/deg of the tip (G without a driver), held-orientation flag, stamp.
        self._path_x: list[np.ndarray] = []
        self._path_held: list[bool] = []
        self._path_stamps: list[int] = []
        self.path_index = 0
        self.path_last_stamp_ns: int | None = None
        self.cycles_since_point = 0
        self.cal_samples: list[tuple[np.ndarray, np.ndarray]] = []  # (world_T_tob m, world_T_flange m)
        self.cal_target = 0
        self.cal_pivot_mm: np.ndarray | None = None
        self.playback: dict | None = None
        self.saturated_cycles = 0
        self._position_first = False  # the last step was position_first's (law.thetau_step's hysteresis)
        self._last_cycle: int | None = None
        self._sent: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # cycle -> the step last sent for it
        # The cell's one cycle (ns): the link's, from the latest robot state that carries it
        # (runtime/cycle.py); until then, or from states carrying none, the fallback.
        self.cycle_period_ns = cell_cycle.FALLBACK_NS
        self._derive(config)

    def _derive(self, c: ControllerConfig) -> None:
        self.flange_T_camera = self.rig.hand_eye.flange_T_camera_m()
        self.psvs = self.rig.params()
        self.tob_p_sources_mm = np.asarray(self.rig.target_model().source_positions_mm, dtype=float)
        self.camera_p_d_mm = np.array([0.0, 0.0, c.dz_mm])
        self.flange_T_desired = flange_T_desired_m(c, self.rig)
        self.flange_T_tool = to_m(transform_from_x(np.asarray(c.flange_T_tool_x)))
        self.tool_T_flange = invert_transform(self.flange_T_tool)
        self.tob_T_tip = to_m(self.rig.tip.tob_T_tip_mm())
        self.dt = cell_cycle.ms(self.cycle_period_ns) * 1e-3
        self.max_step_m = c.max_speed_mm_s * 1e-3 * self.dt
        self.max_step_rad = np.radians(c.max_rotation_deg_s) * self.dt
        self.K = c.gain_matrix()  # the 6x6 gain matrix, or None: the two gains

    def on_config_changed(self, old, new) -> None:
        self._derive(new)

    def check_config(self, config: ControllerConfig) -> None:
        """A gain changed at run time must stay stable at the cycle the robot runs."""
        config.check_cycle(self.cycle_period_ns)

    def use_cycle(self, cycle_period_ns: int) -> None:
        """Run at this cycle (ns): a robot state's, or what an old recording's config said
        (its robot states carry none; runtime.replay)."""
        if cycle_period_ns != self.cycle_period_ns:
            self.cycle_period_ns = cycle_period_ns
            self._derive(self.config)

    # -- inputs ------------------------------------------------------------------------------
    def _on_path_file(self, t_ns: int, msg: pb.Event) -> list[Output]:
        return [self.event(t_ns, msg.severity, msg.code, msg.text)]

    def _on_robot_state(self, t_ns: int, msg: pb.RobotState) -> list[Output]:
        try:
            T = from_pose(msg.world_T_flange)
        except MessageError as e:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_robot_state", str(e))]
        self.robot = (msg.cycle, msg.header.stamp_ns, T)
        period_ns = cell_cycle.from_state(msg.cycle_period_ns)
        if period_ns is not None:
            self.use_cycle(period_ns)
        if self.start_world_T_flange is None:
            self.start_world_T_flange = T.copy()
        return []

    def _on_console(self, t_ns: int, msg: pb.Command) -> list[Output]:
        if msg.component not in ("", self.name):
            return []
        return self._command(t_ns, msg.verb, msg.args_json)

    # -- one ALTER cycle ----------------------------------------------------------------------
    def _cycle(self, t_ns: int, st: pb.TobState) -> list[Output]:
        if self.robot is None:
            return []
        cycle, stamp, world_T_flange = self.robot
        c = self.config
        if c.command_ahead and st.cycle == _next(cycle):
            # The filter's state for the next cycle overtook that cycle's robot state on
            # the bus: where the flange is then follows from this cycle and its step.
            world_T_flange = law.apply_step(world_T_flange, *self._step_answering(cycle))
            cycle, stamp = _next(cycle), stamp + self.cycle_period_ns
        ahead_s = 0.0
        base = self._step_answering(cycle) if c.command_ahead else self._sent.get(cycle)
        if (st.after_measurement or c.command_ahead) and base is not None:
            # Command the next cycle now, from where this cycle's step will have put the
            # flange, so the gateway can answer that cycle's status at once (after a new
            # image: with the freshest information).
            world_T_flange = law.apply_step(world_T_flange, *base)
            cycle, stamp = _next(cycle), stamp + self.cycle_period_ns
            ahead_s = self.dt
        outs: list[Output] = []
        valid = st.status in (pb.TOB_STATUS_FULL, pb.TOB_STATUS_POSITION_ONLY)
        world_T_tob = v_tob = w_tob = None
        if valid:
            try:
                world_T_tob = from_pose(st.world_T_tob)
                v_tob, w_tob = from_vector3(st.linear_velocity_m_s), from_vector3(st.angular_velocity_rad_s)
            except MessageError as e:
                outs.append(self.event(t_ns, pb.SEVERITY_WARNING, "bad_tob_state", str(e)))
                valid = False
        if valid and c.law == "thetau" and c.feed_forward:
            # The filter predicts ahead for the paper's law; with feed-forward the error is
            # taken at the robot's instant (+ lead) and the velocity carries the next cycle.
            world_T_tob = law.extrapolate(world_T_tob, v_tob, w_tob, (stamp + c.lead_ms * 1e6 - st.header.stamp_ns) * 1e-9)
        elif valid and ahead_s:
            # The filter predicted to this cycle; the command is for the next one.
            world_T_tob = law.extrapolate(world_T_tob, v_tob, w_tob, ahead_s)
        zero = np.zeros(3)
        step = law.Step(zero, zero, False, 0.0, 0.0)
        mode = self.mode
        desired = world_T_flange
        if self.mode in (pb.CONTROL_MODE_TRACK, pb.CONTROL_MODE_CALIBRATE):
            if not valid:
                mode = pb.CONTROL_MODE_LOST
                if c.lost_action == "return" and self.return_world_T_flange() is not None:
                    step, desired = self._goto(world_T_flange, self.return_world_T_flange())
            else:
                position_only = st.status == pb.TOB_STATUS_POSITION_ONLY
                if position_only:
                    mode = pb.CONTROL_MODE_POSITION_ONLY
                step = self._servo(world_T_flange, world_T_tob, v_tob, w_tob, position_only)
                desired = law.desired_flange(world_T_tob, self.flange_T_desired)
                if (self.mode == pb.CONTROL_MODE_CALIBRATE and not position_only and st.after_measurement
                        and st.HasField("world_T_tob_at_measurement")):
                    # The filter's pose at the image's instant: what was measured, with no
                    # prediction in it (a predicted pose lags or leads the pivoting target).
                    outs += self._calibration_sample(t_ns, from_pose(st.world_T_tob_at_measurement), world_T_flange)
        elif self.mode == pb.CONTROL_MODE_RETURN and self.return_world_T_flange() is not None:
            step, desired = self._goto(world_T_flange, self.return_world_T_flange())
        elif self.mode == pb.CONTROL_MODE_PLAYBACK:
            step, desired, done = self._playback_step(world_T_flange)
            if done:
                self.mode = pb.CONTROL_MODE_HOLD
                outs.append(self.event(t_ns, pb.SEVERITY_INFO, "playback_done", "playback reached the path's end"))
        if mode != getattr(self, "_last_mode", None):
            outs.append(self.event(t_ns, pb.SEVERITY_INFO, "mode", f"mode {pb.ControlMode.Name(mode)}"))
            self._last_mode = mode
        self.saturated_cycles += int(step.saturated)
        self._position_first = step.position_first
        cmd = pb.FlangeCommand(header=self.next_header(T_CMD, stamp, "world"), cycle=cycle,
                               d_translation_m=vector3(step.d_translation_m),
                               d_rotation_rad=vector3(step.d_rotation_rad), mode=mode,
                               measurement_stamp_ns=st.measurement_stamp_ns)
        outs.append((T_CMD, cmd))
        self._sent.pop(cycle, None)
        self._sent[cycle] = (step.d_translation_m, step.d_rotation_rad)
        while len(self._sent) > 4:  # the latest few cycles (any gaps, restarts or wraps)
            del self._sent[next(iter(self._sent))]
        # The filter may send several states per cycle (a new image re-commands it): count
        # cycles, not states, for the recording delay.
        new_cycle = cycle != self._last_cycle
        self._last_cycle = cycle
        # Recording goes on with one or two sources (position-only): the position is still
        # measured, the orientation held (flagged); the covariance says how well each is known.
        if self.recording and valid and new_cycle:
            self.cycles_since_point = min(self.cycles_since_point + 1, c.recording_delay_cycles)
            # The filter's estimate at its last measurement: no prediction in the path.
            if st.HasField("world_T_tob_at_measurement") and st.measurement_stamp_ns:
                at, T = st.measurement_stamp_ns, from_pose(st.world_T_tob_at_measurement)
            else:
                at, T = st.header.stamp_ns, from_pose(st.world_T_tob)
            # One point per measurement (no image since the last point: wait for one). A
            # stamp far behind the last point's is a new time base (the camera's machine
            # stepped its clock back), not an old measurement: the path goes on from it.
            last = self.path_last_stamp_ns
            stepped_back = last is not None and last - at > CLOCK_STEP_BACK_NS
            if stepped_back:
                outs.append(self.event(t_ns, pb.SEVERITY_WARNING, "stamps_back",
                                       f"measurement stamps went back {(last - at) / 1e9:.3f} s (a clock step?): "
                                       "the path goes on from the new stamps"))
            if (last is None or at > last or stepped_back) and self._point_due(T):
                self.cycles_since_point = 0
                raw = None
                if c.record_raw and st.HasField("world_T_tob_measured") and at == st.measurement_stamp_ns:
                    raw = from_pose(st.world_T_tob_measured)  # the same image's X_WG before the filter
                outs.append(self._path_point(at, T, st.status == pb.TOB_STATUS_POSITION_ONLY,
                                             _pose_covariance(st), raw))
        fov = img = 0.0
        if valid:
            camera_T_tob_mm = to_mm(invert_transform(world_T_flange @ self.flange_T_camera) @ world_T_tob)
            fov = law.fov_margin_px(self.psvs, camera_T_tob_mm, self.tob_p_sources_mm)
            img = law.image_offset_px(self.psvs, camera_T_tob_mm[:3, 3], self.camera_p_d_mm)
        status = pb.ControllerStatus(
            header=self.next_header(T_STATUS, stamp, "world"), mode=mode,
            visible=3 if st.status == pb.TOB_STATUS_FULL else (1 if st.status == pb.TOB_STATUS_POSITION_ONLY else 0),
            error_translation_m=step.error_translation_m, error_rotation_rad=step.error_rotation_rad,
            recording=self.recording, path_points=len(self.path), calibration_samples=len(self.cal_samples),
            cycle=cycle, saturated=step.saturated, world_T_desired=pose(desired), fov_margin_px=fov,
            image_error_px=img, rotation_scale=step.rotation_scale)
        outs.append((T_STATUS, status))
        return outs

    def _step_answering(self, cycle: int) -> tuple[np.ndarray, np.ndarray]:
        """The step the gateway answers ``cycle`` with: the one sent for it, else its
        velocity hold (the freshest older step), else zero (nothing sent yet)."""
        return (self._sent.get(cycle) or self._sent.get(_prev(cycle)) or self._sent.get(_prev(_prev(cycle)))
                or (np.zeros(3), np.zeros(3)))

    def _servo(self, world_T_flange, world_T_tob, v_tob, w_tob, position_only) -> law.Step:
        c = self.config
        if c.law == "paper":
            return law.paper_step(world_T_flange, world_T_tob, self.flange_T_desired, k_t=c.gain_translation_1_s,
                                  k_r=c.gain_rotation_1_s, dt_s=self.dt, max_step_m=self.max_step_m,
                                  max_step_rad=self.max_step_rad, position_only=position_only, K=self.K)
        return law.thetau_step(world_T_flange, world_T_tob, self.flange_T_desired, v_tob_m_s=v_tob,
                               w_tob_rad_s=w_tob, k_t=c.gain_translation_1_s, k_r=c.gain_rotation_1_s,
                               dt_s=self.dt, max_step_m=self.max_step_m, max_step_rad=self.max_step_rad,
                               feed_forward=c.feed_forward, position_only=position_only,
                               deadband_m=c.deadband_mm * 1e-3, deadband_rad=np.radians(c.deadband_deg),
                               still_m_s=c.still_mm_s * 1e-3, still_rad_s=np.radians(c.still_deg_s),
                               saturation=c.saturation, position_first_beyond_m=c.position_first_beyond_mm * 1e-3,
                               engaged=self._position_first, K=self.K)

    def return_world_T_flange(self) -> np.ndarray | None:
        """Where "return" (and the lost action "return") takes the flange (m): the
        prespecified ``return_flange_x`` (checked inside the envelope by the config), else
        the first robot pose seen (None before any)."""
        x = self.config.return_flange_x
        if x is None:
            return self.start_world_T_flange
        return to_m(transform_from_x(np.asarray(x, dtype=float)))

    def _goto(self, world_T_flange, world_T_target, v_ff=None, w_ff=None, together: bool = False):
        """A saturated step towards a flange pose (no vision).  ``v_ff`` (3,) m/s and
        ``w_ff`` (3,) rad/s: the target's own motion (world frame, the flange origin's
        velocity and the frame's angular velocity), fed forward so that a moving target is
        followed without the lag v / K (w / K in orientation).  ``together``: at the
        limits the translation and the rotation are scaled by the same factor (a played
        tool stays on its path, only slower), else each by its own (law.saturate)."""
        c = self.config
        e_t, e_r = law.pose_error(world_T_flange, world_T_target)
        v = c.gain_translation_1_s * e_t + (v_ff if v_ff is not None else 0.0)
        w = c.gain_rotation_1_s * e_r + (w_ff if w_ff is not None else 0.0)
        d_t, d_r, sat = law.saturate(v * self.dt, w * self.dt, self.max_step_m, self.max_step_rad, together=together)
        return law.Step(d_t, d_r, sat, float(np.linalg.norm(e_t)), float(np.linalg.norm(e_r))), world_T_target

    # -- recording ------------------------------------------------------------------------------
    def _point_due(self, world_T_tob: np.ndarray) -> bool:
        """Is a path point due at this measurement?  Every ``recording_delay_cycles`` cycles;
        with ``recording_spacing_mm`` > 0 also the first measurement after record_start and
        every one whose point (the tip, else G) is that far from the last point, so the path
        is as dense as the speed needs (the fit wants a point every few mm)."""
        c = self.config
        if self.cycles_since_point >= c.recording_delay_cycles:
            return True
        if c.recording_spacing_mm <= 0:
            return False
        if not self._path_x:
            return True
        world_T_point = world_T_tob @ self.tob_T_tip if c.has_driver else world_T_tob
        return bool(np.linalg.norm(world_T_point[:3, 3] * 1e3 - self._path_x[-1][:3]) >= c.recording_spacing_mm)

    def _path_point(self, stamp_ns: int, world_T_tob: np.ndarray, orientation_held: bool,
                    cov_pr: np.ndarray | None, world_T_tob_raw: np.ndarray | None = None) -> Output:
        """A path point of G (and the tip) at ``stamp_ns``; ``cov_pr`` (6, 6): the filter's
        covariance of [p (m), r (rad)] (world frame), None when the state carries none;
        ``world_T_tob_raw``: the same measurement's pose before the filter (``record_raw``)."""
        pt = pb.PathPoint(header=self.next_header(T_PATH, stamp_ns, "world"), index=self.path_index,
                          world_T_tob=pose(world_T_tob), has_tip=self.config.has_driver,
                          orientation_held=orientation_held)
        if self.config.has_driver:
            pt.world_T_tip.CopyFrom(pose(world_T_tob @ self.tob_T_tip))
        if world_T_tob_raw is not None:
            pt.world_T_tob_raw.CopyFrom(pose(world_T_tob_raw))
            if self.config.has_driver:
                pt.world_T_tip_raw.CopyFrom(pose(world_T_tob_raw @ self.tob_T_tip))
        if cov_pr is not None:
            pt.position_covariance_m2.extend(cov_pr[:3, :3].ravel().tolist())
            pt.rotation_covariance_rad2.extend(cov_pr[3:, 3:].ravel().tolist())
            if self.config.has_driver:
                tip = tip_position_covariance(cov_pr, world_T_tob[:3, :3] @ self.tob_T_tip[:3, 3])
                pt.tip_position_covariance_m2.extend(tip.ravel().tolist())
        self.path_index += 1
        self.path_last_stamp_ns = stamp_ns
        self.path.append(pt)
        world_T_point = world_T_tob @ self.tob_T_tip if self.config.has_driver else world_T_tob
        self._path_x.append(x_from_transform(to_mm(world_T_point)))
        self._path_held.append(orientation_held)
        self._path_stamps.append(stamp_ns)
        return T_PATH, pt

    # -- calibration ----------------------------------------------------------------------------
    def _calibration_sample(self, t_ns, world_T_tob, world_T_flange) -> list[Output]:
        if len(self.cal_samples) >= self.cal_target:
            return []
        if self.cal_samples:
            # Only keep poses that differ (a pivot fit needs rotation diversity).
            last = self.cal_samples[-1][0]
            angle = np.degrees(rotation_angle_rad(world_T_tob[:3, :3] @ last[:3, :3].T, assume_valid=True))
            if angle < self.config.calibration_min_spread_deg:
                return []
        self.cal_samples.append((world_T_tob.copy(), world_T_flange.copy()))
        if len(self.cal_samples) < self.cal_target:
            return []
        return self._finish_calibration(t_ns)

    def _finish_calibration(self, t_ns) -> list[Output]:
        tobs = np.array([to_mm(a) for a, _ in self.cal_samples])
        self.mode = pb.CONTROL_MODE_TRACK
        try:
            res = calibrate_tip_pivot(tobs)
        except (GeometryError, ValueError) as e:
            return [self.event(t_ns, pb.SEVERITY_ERROR, "calibration_failed", f"pivot calibration failed: {e}")]
        tip = np.asarray(res.tob_t_tip_mm, dtype=float)
        result = {"method": "pivot", "tob_t_tip_mm": tip.round(4).tolist(),
                  "world_p_pivot_mm": np.asarray(res.world_p_pivot_mm).round(4).tolist(),
                  "residual_rms_mm": round(float(res.residual_rms_mm), 5), "samples": len(tobs)}
        outs = []
        if self.cal_pivot_mm is not None:
            flanges = np.array([to_mm(f) for _, f in self.cal_samples])
            cams = np.array([invert_transform(to_mm(self.flange_T_camera)) @ invert_transform(f) @ t
                             for f, t in zip(flanges, tobs, strict=True)])
            try:
                paper = calibrate_tip_paper(flanges, to_mm(self.flange_T_camera), cams, self.cal_pivot_mm)
                result["paper_tob_t_tip_mm"] = np.asarray(paper.tob_t_tip_mm).round(4).tolist()
                result["paper_residual_rms_mm"] = round(float(paper.residual_rms_mm), 5)
            except (GeometryError, ValueError) as e:
                outs.append(self.event(t_ns, pb.SEVERITY_WARNING, "calibration_paper_failed", str(e)))
        # The calibrated tip replaces the rig's from now on (a rig file is written by the
        # shell or `humanpt calibrate tip`; the core only knows its inputs).
        sigma = float(np.max(np.asarray(res.tob_t_tip_sigma_mm, dtype=float)))
        stamp = np.datetime64(int(t_ns), "ns").astype("datetime64[s]")
        self.rig = dataclasses.replace(self.rig, tip=Tip(
            tob_t_tip_mm=tuple(float(v) for v in tip),
            calibration=Calibration(method="pivot", date=f"{stamp}Z", note=f"{len(tobs)} samples, residual RMS "
                                    f"{float(res.residual_rms_mm):.3f} mm", sigma={"tob_t_tip_mm": round(sigma, 6)})))
        self.config = dataclasses.replace(self.config, has_driver=True)
        self._derive(self.config)
        outs.append(self.event(t_ns, pb.SEVERITY_INFO, "calibration_done", json.dumps(result)))
        return outs

    # -- playback -------------------------------------------------------------------------------
    def _start_playback(self, points_mm_deg: np.ndarray, speed_mm_s: float, times_s: np.ndarray | None = None,
                        world_T_tool_mm: np.ndarray | None = None) -> None:
        """Play ``points_mm_deg`` (N, 6) tool poses at ``speed_mm_s`` along them, or, with
        ``times_s`` (N,) (a re-timed seam: humanpt path retime), reaching each point at its
        time from the start (the feed, its ramps and stops are the timing's).
        ``world_T_tool_mm`` (N, 4, 4): the poses as transforms, when the caller has them."""
        tips = to_m(transform_from_x(np.asarray(points_mm_deg, dtype=float).reshape(-1, 6))
                    if world_T_tool_mm is None else world_T_tool_mm)
        flanges = tips @ invert_transform(self.flange_T_tool)
        seg = np.linalg.norm(np.diff(tips[:, :3, 3], axis=0), axis=1)
        self.playback = {"flanges": flanges, "tips": tips, "s": np.r_[0.0, np.cumsum(seg)], "pos": 0.0,
                         "speed": speed_mm_s * 1e-3, "approach": True, "paused": False, "rate": 1.0,
                         "times": None if times_s is None else np.asarray(times_s, dtype=float) - times_s[0],
                         "tau": 0.0}

    def _too_fast(self, points_mm_deg: np.ndarray, times_s: np.ndarray) -> bool:
        """Would the timing move the tool faster than max_speed_mm_s anywhere (1 % slack)?"""
        d = np.linalg.norm(np.diff(points_mm_deg[:, :3], axis=0), axis=1)
        dt = np.diff(times_s)
        moving = d > 1e-9
        return bool(np.any(moving & (d > 1.01 * self.config.max_speed_mm_s * np.maximum(dt, 0.0))))

    def _carrot(self, s: float) -> np.ndarray:
        """The flange pose (4, 4) m when the tool is at arc length s (m) along the path
        (an untimed playback: the tool moves at a constant speed along its points)."""
        pb_ = self.playback
        S, tips = pb_["s"], pb_["tips"]
        if len(S) == 1 or s <= 0:
            return pb_["flanges"][0]
        i = int(np.clip(np.searchsorted(S, s) - 1, 0, len(S) - 2))
        L = S[i + 1] - S[i]
        a = 0.0 if L <= 0 else min(1.0, (s - S[i]) / L)
        return interpolate_transform(tips[i], tips[i + 1], a) @ self.tool_T_flange

    def _carrot_at(self, tau: float) -> np.ndarray:
        """The flange pose (4, 4) m when the tool is where a timed playback puts it at
        ``tau`` (s from its start): linear in time between the points, position and
        orientation alike (a turn on the spot, where the arc length stands still, turns
        at the timing's rate; playback.thin keeps the points within its tolerance of that)."""
        pb_ = self.playback
        T, tips = pb_["times"], pb_["tips"]
        if len(T) == 1 or tau <= T[0]:
            return pb_["flanges"][0]
        if tau >= T[-1]:
            return pb_["flanges"][-1]
        i = int(np.clip(np.searchsorted(T, tau, side="right") - 1, 0, len(T) - 2))
        span = T[i + 1] - T[i]
        a = 0.0 if span <= 0 else min(1.0, (tau - T[i]) / span)
        return interpolate_transform(tips[i], tips[i + 1], a, assume_valid=True) @ self.tool_T_flange

    def _playback_step(self, world_T_flange):
        pb_ = self.playback
        if pb_ is None:
            return law.Step(np.zeros(3), np.zeros(3), False, 0.0, 0.0), world_T_flange, True
        if pb_["approach"]:
            # Go to the path's first point first, then start the carrot.
            step, desired = self._goto(world_T_flange, pb_["flanges"][0])
            if step.error_translation_m < 0.2e-3 and step.error_rotation_rad < np.radians(0.2):
                pb_["approach"] = False
            return step, desired, False
        timed = pb_["times"] is not None
        # The carrot now and one commanded cycle on: its displacement over the cycle is fed
        # forward, translation and rotation (playback.feed_forward).  On a link that moves
        # the flange by each cycle's step this is the motion exact to the cycle, its
        # acceleration included: a robot on the carrot stays on it, turning as it turns.
        hop = self.dt * pb_["rate"]
        if timed:
            target, ahead = self._carrot_at(pb_["tau"]), self._carrot_at(pb_["tau"] + hop)
        else:
            target = self._carrot(pb_["pos"])
            ahead = self._carrot(min(pb_["s"][-1], pb_["pos"] + pb_["speed"] * hop))
        if pb_["paused"]:  # stand at the carrot: no feed-forward, no progress
            step, desired = self._goto(world_T_flange, target)
            return step, desired, False
        v, w = playback.feed_forward(target, ahead, self.dt)
        step, desired = self._goto(world_T_flange, target, v_ff=v, w_ff=w, together=True)
        if step.error_translation_m < self.config.playback_max_lag_mm * 1e-3:
            if timed:
                pb_["tau"] = min(pb_["times"][-1], pb_["tau"] + hop)
                pb_["pos"] = float(np.interp(pb_["tau"], pb_["times"], pb_["s"]))
            else:
                pb_["pos"] = min(pb_["s"][-1], pb_["pos"] + pb_["speed"] * hop)
        else:
            # The carrot waits for the lagging robot: then no feed-forward either, or the
            # robot would settle v / K past the waiting carrot (5 mm at 20 mm/s, K = 4/s),
            # beyond the lag that lets the carrot go on: playback would never end.
            step, desired = self._goto(world_T_flange, target)
        at_end = pb_["tau"] >= pb_["times"][-1] if timed else pb_["pos"] >= pb_["s"][-1]
        done = at_end and step.error_translation_m < 0.1e-3
        return step, desired, done

    def _recorded_points(self) -> np.ndarray:
        """(N, 6) mm/deg of the recorded path (the tip's when recorded), held orientations
        interpolated from the measured ones around them (pathfile.fill_held_orientation)."""
        from humanpt.controller.pathfile import fill_held_orientation

        if not self._path_x:
            return np.zeros((0, 6))
        return fill_held_orientation(np.array(self._path_x), np.array(self._path_held, dtype=bool),
                                     np.array(self._path_stamps, dtype=np.int64))

    def _playback_command(self, t_ns: int, args: dict[str, Any]) -> list[Output]:
        """Start a playback of the checked arguments (at most MAX_PLAYBACK_POINTS points,
        check_command), or refuse it with one ``bad_command`` event: a speed above the
        limit, no points, a timing faster than max_speed_mm_s, or a point that would put the
        flange outside the workspace envelope.  Array operations only: bounded work on the
        realtime thread."""
        c = self.config

        def refuse(text: str) -> list[Output]:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_command", f"playback: {text}")]

        speed = args.get("speed_mm_s", c.playback_speed_mm_s)
        if speed > c.max_speed_mm_s:
            return refuse(f"speed_mm_s {speed:g} is above the controller's max_speed_mm_s {c.max_speed_mm_s:g}")
        times = args.get("times_s")
        if "points" in args:
            pts = args["points"]
        elif len(self.path) > MAX_PLAYBACK_POINTS:
            return refuse(f"the recorded path has {len(self.path)} points; the controller plays at most "
                          f"{MAX_PLAYBACK_POINTS}: save it, fit a seam (humanpt path fit) and play that")
        else:
            pts = self._recorded_points()
        if len(pts) < 1:
            return refuse("no points given and no path recorded")
        world_T_tool_mm = transform_from_x(pts)
        flange_p_mm = (world_T_tool_mm @ invert_transform(to_mm(self.flange_T_tool)))[:, :3, 3]
        why = playback.envelope_refusal(pts, None, c.envelope_min_mm, c.envelope_max_mm, flange_p_mm=flange_p_mm)
        if why is not None:
            return refuse(why)
        if times is not None and self._too_fast(pts, times):
            return refuse(f"the timing asks for more than max_speed_mm_s {c.max_speed_mm_s:g}")
        self._start_playback(pts, speed, times, world_T_tool_mm)
        self.mode = pb.CONTROL_MODE_PLAYBACK
        how = f"timed, {times[-1] - times[0]:.1f} s" if times is not None else f"at {speed:g} mm/s"
        return [self.event(t_ns, pb.SEVERITY_INFO, "playback_started", f"{len(pts)} points {how}")]

    # -- commands ---------------------------------------------------------------------------------
    def _command(self, t_ns: int, verb: str, args_json: str) -> list[Output]:
        try:
            args = check_command(verb, args_json)
        except ConfigError as e:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_command", f"{verb}: {e}")]
        info = lambda code, text: [self.event(t_ns, pb.SEVERITY_INFO, code, text)]  # noqa: E731
        if verb == "track":
            self.mode = pb.CONTROL_MODE_TRACK
            return info("command", "track")
        if verb in ("hold", "stop"):
            self.mode = pb.CONTROL_MODE_HOLD
            self.playback = None
            return info("command", "hold (stop on current location)")
        if verb == "return":
            self.mode = pb.CONTROL_MODE_RETURN
            x = self.config.return_flange_x
            where = "the start pose" if x is None else "the return pose [" + ", ".join(f"{v:g}" for v in x) + "]"
            return info("command", f"return to {where}")
        if verb == "record_start":
            self.recording, self.path, self.path_index, self.cycles_since_point = True, [], 0, 0
            self._path_x, self._path_held, self._path_stamps = [], [], []
            # The first point is the first measurement taken after the start (its stamp past
            # this command's), not one taken before it that arrives after.
            self.path_last_stamp_ns = t_ns - 1
            return info("record_started", json.dumps({"has_tip": self.config.has_driver}))
        if verb == "record_stop":
            self.recording = False
            return info("record_stopped", json.dumps({"points": len(self.path)}))
        if verb == "save":
            return info("save", json.dumps({"file": args["file"], "overwrite": args.get("overwrite", False),
                                            "points": len(self.path)}))
        if verb == "calibrate":
            n = args.get("samples", self.config.calibration_samples)
            self.cal_samples, self.cal_target = [], n
            pivot = args.get("pivot_mm")
            self.cal_pivot_mm = None if pivot is None else np.asarray(pivot, dtype=float)
            self.mode = pb.CONTROL_MODE_CALIBRATE
            return info("calibration_started", f"pivot the target on its driver tip: {n} samples")
        if verb == "playback":
            return self._playback_command(t_ns, args)
        if verb in ("playback_pause", "playback_resume", "playback_rate"):
            if self.playback is None or self.mode != pb.CONTROL_MODE_PLAYBACK:
                return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_command", f"{verb}: no playback running")]
            if verb == "playback_rate":
                self.playback["rate"] = float(args.get("rate", 1.0))
                return info("playback_rate", f"playback at {self.playback['rate']:g} x its speed")
            self.playback["paused"] = verb == "playback_pause"
            if self.playback["paused"]:
                return info("playback_paused", "playback paused (standing on the path)")
            return info("playback_resumed", "playback resumed")
        raise AssertionError(f"check_command let {verb!r} through")  # pragma: no cover


# -- console command arguments ---------------------------------------------------------------------
_NO_ARGS: dict[str, Any] = {}
# A playback's points and times are checked with array operations (playback.check_points,
# check_times): a per-element check of 2000 points took most of a 28 ms cycle.
_POINTS, _TIMES = object(), object()
# verb -> {argument: type (with its range)}; every argument is optional.
COMMAND_ARGS: dict[str, dict[str, Any]] = {
    "track": _NO_ARGS, "hold": _NO_ARGS, "stop": _NO_ARGS, "return": _NO_ARGS,
    "record_start": _NO_ARGS, "record_stop": _NO_ARGS,
    "save": {"file": str, "overwrite": bool},
    "calibrate": {"samples": Annotated[int, Range(6, 100_000, "samples")], "pivot_mm": tuple[Mm, Mm, Mm]},
    "playback": {"points": _POINTS, "speed_mm_s": SpeedMmS, "times_s": _TIMES},
    "playback_pause": _NO_ARGS, "playback_resume": _NO_ARGS,
    "playback_rate": {"rate": Annotated[float, Range(0.05, 2.0, "x")]},
}
# A saved path's name: a plain file name in the run's paths/ directory (no directories, no
# dot files), so that a console command can never write elsewhere.
_FILE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")


def check_command(verb: str, args_json: str) -> dict[str, Any]:
    """The checked arguments of console command ``verb`` (JSON object text), typed and in
    range (a playback's points an (N, 6) array, its times (N,)); :class:`ConfigError`
    naming the argument otherwise.  The text is bounded (MAX_ARGS_CHARS) before it is
    parsed, a playback's points (MAX_PLAYBACK_POINTS) before they are converted."""
    if verb not in COMMAND_ARGS:
        raise ConfigError(f"unknown verb {verb!r}; known: {', '.join(COMMAND_ARGS)}")
    if len(args_json) > MAX_ARGS_CHARS:
        raise ConfigError(f"arguments of {len(args_json)} characters; the controller takes at most "
                          f"{MAX_ARGS_CHARS} (a playback of at most {MAX_PLAYBACK_POINTS} points)")
    try:
        args = json.loads(args_json) if args_json else {}
    except (ValueError, RecursionError) as e:
        raise ConfigError(f"arguments are not JSON: {e}") from None
    if not isinstance(args, dict):
        raise ConfigError("arguments must be a JSON object")
    spec = COMMAND_ARGS[verb]
    unknown = sorted(set(args) - set(spec))
    if unknown:
        raise ConfigError(f"unknown argument {unknown[0]!r}; {verb} takes "
                          f"{', '.join(spec) if spec else 'no arguments'}")
    checked = {k: coerce(spec[k], v, k) for k, v in args.items() if spec[k] not in (_POINTS, _TIMES)}
    booleans = "true" in args_json or "false" in args_json  # (else no per-element look for them)
    if "points" in args:
        checked["points"] = playback.check_points(args["points"], "points", booleans)
    if "times_s" in args:
        if "points" not in checked:
            raise ConfigError("times_s: no points given; times_s needs points, one time per point")
        checked["times_s"] = playback.check_times(args["times_s"], len(checked["points"]), "times_s", booleans)
    if verb == "save":
        name = checked.get("file", "")
        if not _FILE_NAME.fullmatch(name):
            raise ConfigError(f"file {name!r}: give a plain file name (letters, digits, '.', '_', '-'; "
                              "no directories): paths are saved in the run's paths/ directory")
        if "." not in name:
            checked["file"] = name + ".csv"
    return checked
