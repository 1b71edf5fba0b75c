"""controller core on scripted inputs, with a perfect robot that applies each command: both
laws converge, the limits hold, lost/position-only/hold/return modes, recording, driver
calibration and playback."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry.rig import viewing_world_T_flange
from humanpt.geometry.transforms import transform_from_x, x_from_transform
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, from_vector3, header, pose, vector3

DT_NS = 28_000_000
TARGET_X = (236.132, 1248.772, 85.284, -2.598, -0.883, -4.535)


def T_m(x):
    T = transform_from_x(np.asarray(x, dtype=float))
    T[:3, 3] *= 1e-3
    return T


def T_mm(T):
    T = np.array(T, dtype=float)
    T[:3, 3] *= 1e3
    return T


def start_flange(target_x, offset_mm=(0, 0, 0), rot_deg=(0, 0, 0)):
    F = viewing_world_T_flange(transform_from_x(np.asarray(target_x, dtype=float)))
    F[:3, 3] += offset_mm
    F[:3, :3] = Rotation.from_euler("ZYX", rot_deg, degrees=True).as_matrix() @ F[:3, :3]
    F[:3, 3] *= 1e-3
    return F


def robot_step(world_T_flange, d_t_m, d_r_rad):
    """What the robot does with a command (ALTER world mode, as sim_robot applies it): turn
    by the rotation vector ``d_r_rad`` (3,) about the flange origin, axes in the world, and
    move by ``d_t_m`` (3,) in the world. Written here with scipy, independently of the
    controller's own prediction (``law.apply_step``), so that a wrong prediction shows."""
    T = np.array(world_T_flange, dtype=float)
    T[:3, :3] = Rotation.from_rotvec(d_r_rad).as_matrix() @ T[:3, :3]
    T[:3, 3] += d_t_m
    return T


class Rig:
    """A perfect robot and a perfectly known target, cycle by cycle."""

    def __init__(self, core, flange, tob_fn, status_fn=None):
        self.core, self.flange, self.tob_fn = core, flange, tob_fn
        self.status_fn = status_fn or (lambda k: pb.TOB_STATUS_FULL)
        self.k = 0
        self.outs: list[tuple[str, object]] = []
        self.flanges = []
        self.pending: dict[int, pb.FlangeCommand] = {}
        self.answered: list[bool] = []
        self.at_cycle: dict[int, np.ndarray] = {}  # the robot's flange at the start of each cycle
        self.covariance: np.ndarray | None = None  # the filter states' covariance, if any
        self.shift_cycles = 0  # the stamps' time base moved by this many cycles (a clock step)

    def command(self, verb, **args):
        msg = pb.Command(header=header(self.k * DT_NS), component="controller", verb=verb,
                         args_json=json.dumps(args))
        self.outs += self.core.step(self.k * DT_NS, "console/command", msg)

    def step(self, n=1):
        for _ in range(n):
            t = (self.k + self.shift_cycles) * DT_NS
            self.at_cycle[self.k] = self.flange.copy()
            self.core.step(t, "robot_gateway/robot_state", pb.RobotState(
                header=header(t, self.k, "world"), world_T_flange=pose(self.flange), cycle=self.k))
            T, v, w = self.tob_fn(self.k * DT_NS)  # the world in true time; the stamps in the clock's
            st = pb.TobState(header=header(t, self.k, "world"), world_T_tob=pose(T), status=self.status_fn(self.k),
                             linear_velocity_m_s=vector3(v), angular_velocity_rad_s=vector3(w), cycle=self.k,
                             # as the filter says right after a new measurement (one per cycle here)
                             after_measurement=True, world_T_tob_at_measurement=pose(T), measurement_stamp_ns=t)
            if self.covariance is not None:  # (12, 12), as the filter publishes it
                st.covariance.extend(np.ravel(self.covariance).tolist())
                st.covariance_dim = 12
            outs = self.core.step(t + 1, "pose_filter/tob_state", st)
            self.outs += outs
            for cmd in (m for tp, m in outs if tp == "controller/command"):
                self.pending[cmd.cycle] = cmd
            # As the gateway: cycle k is answered with the command for cycle k (commanded
            # one cycle ahead by default), else the robot holds.
            cmd = self.pending.pop(self.k, None)
            self.answered.append(cmd is not None)
            if cmd is not None:
                self.flange = robot_step(self.flange, from_vector3(cmd.d_translation_m),
                                         from_vector3(cmd.d_rotation_rad))
            self.flanges.append(self.flange.copy())
            self.k += 1

    def of(self, topic):
        return [m for tp, m in self.outs if tp == topic]

    def d_error(self, t_ns=None):
        """(|G - D| mm, angle between the frames deg) now."""
        T, _, _ = self.tob_fn(self.k * DT_NS if t_ns is None else t_ns)
        D = self.flange @ self.core.flange_T_desired
        angle = Rotation.from_matrix(T[:3, :3] @ D[:3, :3].T).magnitude()
        return np.linalg.norm(T[:3, 3] - D[:3, 3]) * 1e3, np.degrees(angle)


def static(T):
    return lambda t: (T, np.zeros(3), np.zeros(3))


@pytest.mark.parametrize("ahead", [True, False])
def test_commands_each_cycle_one_ahead_from_the_predicted_flange(ahead):
    """command_ahead: the state of cycle k commands cycle k + 1, from the flange pose that
    cycle k's step leads to; every cycle then has its command in time."""
    core = ControllerCore(ControllerConfig(command_ahead=ahead))
    rig = Rig(core, start_flange(TARGET_X, (20, -10, 15), (3, -2, 4)), static(T_m(TARGET_X)))
    rig.step(60)
    cmds = rig.of("controller/command")
    assert [c.cycle for c in cmds] == (list(range(1, 61)) if ahead else list(range(60)))
    # Ahead, only the very first cycle goes unanswered (the robot holds it).
    assert rig.answered == ([False] + [True] * 59 if ahead else [True] * 60)
    # Each command was worked out from where the robot's flange really is in the cycle it
    # commands: the error it reports (|G - D| and the angle between G and D, D = flange @
    # flange_T_desired) is the one at the robot's own flange in that cycle.
    G = T_m(TARGET_X)
    statuses = rig.of("controller/status")
    assert [s.cycle for s in statuses] == [c.cycle for c in cmds]
    for s in statuses[:-1]:  # the last commands a cycle the rig has not reached
        D = rig.at_cycle[s.cycle] @ core.flange_T_desired
        assert s.error_translation_m == pytest.approx(np.linalg.norm(G[:3, 3] - D[:3, 3]), abs=1e-9)
        angle = Rotation.from_matrix(G[:3, :3] @ D[:3, :3].T).magnitude()
        assert s.error_rotation_rad == pytest.approx(angle, abs=1e-9)
    e_mm, e_deg = rig.d_error()
    assert e_mm < 0.1 and e_deg < 0.3, (e_mm, e_deg)


@pytest.mark.parametrize("which", ["thetau", "paper"])
def test_static_target_converges_and_holds(which):
    core = ControllerCore(ControllerConfig(law=which))
    rig = Rig(core, start_flange(TARGET_X, (30, -20, 25), (4, -3, 5)), static(T_m(TARGET_X)))
    rig.step(200)
    e_mm, e_deg = rig.d_error()
    # Within the deadbands (0.1 mm, 0.3 deg) of the thetau law; the paper's law has none.
    assert e_mm < 0.1 and e_deg < (0.3 if which == "thetau" else 0.05), (e_mm, e_deg)
    # Per-cycle limits held all along (100 mm/s, 60 deg/s at 28 ms).
    assert len(rig.of("controller/command")) == 200
    for cmd in rig.of("controller/command"):
        assert np.linalg.norm(from_vector3(cmd.d_translation_m)) <= 2.8e-3 + 1e-12
        assert np.linalg.norm(from_vector3(cmd.d_rotation_rad)) <= np.radians(60) * 0.028 + 1e-12
    assert any(s.saturated for s in rig.of("controller/status"))  # the 45 mm start error saturates


def arc(t_ns, speed_deg_s=10.0):
    """The paper's rotating base: centre (147.5, 1378.5, 448) mm, radius 246 mm."""
    a = np.radians(50.0 - speed_deg_s * t_ns * 1e-9)
    c = np.array([147.5, 1378.5, 448.0]) * 1e-3
    p = c + 0.246 * np.array([np.cos(a), np.sin(a), 0.0])
    v = 0.246 * np.radians(speed_deg_s) * np.array([np.sin(a), -np.cos(a), 0.0])
    T = T_m((0, 0, 0, -2.6, -0.9, -4.5))
    T[:3, 3] = p
    return T, v, np.zeros(3)


def test_feed_forward_removes_the_lag_on_a_moving_target():
    lag = {}
    for ff in (True, False):
        core = ControllerCore(ControllerConfig(feed_forward=ff))
        rig = Rig(core, start_flange(x_from_transform(T_mm(arc(0)[0]))), arc)
        rig.step(150)
        lag[ff] = rig.d_error()[0]
    # Without feed-forward the lag is about speed / gain = 42.9 mm/s / 4 /s ~ 11 mm.
    assert lag[False] > 5.0
    assert lag[True] < 0.5, lag


def test_lost_target_holds_within_one_cycle_or_returns():
    core = ControllerCore(ControllerConfig())
    lost_from = 8  # while it still converges
    rig = Rig(core, start_flange(TARGET_X, (20, 0, 0)), static(T_m(TARGET_X)),
              status_fn=lambda k: pb.TOB_STATUS_FULL if k < lost_from else pb.TOB_STATUS_LOST)
    rig.step(60)
    cmds = rig.of("controller/command")
    assert np.linalg.norm(from_vector3(cmds[lost_from - 1].d_translation_m)) > 0
    assert len(cmds) == 60
    for c in cmds[lost_from:]:
        assert c.mode == pb.CONTROL_MODE_LOST
        assert from_vector3(c.d_translation_m).tolist() == [0, 0, 0]
        assert from_vector3(c.d_rotation_rad).tolist() == [0, 0, 0]
    start = start_flange(TARGET_X, (20, 0, 0))
    core = ControllerCore(ControllerConfig(lost_action="return"))
    rig = Rig(core, start, static(T_m(TARGET_X)),
              status_fn=lambda k: pb.TOB_STATUS_FULL if k < lost_from else pb.TOB_STATUS_LOST)
    rig.step(lost_from + 200)
    assert np.linalg.norm(rig.flange[:3, 3] - start[:3, 3]) < 1e-5  # back at the start pose


def test_position_only_moves_without_rotating():
    core = ControllerCore(ControllerConfig())
    rig = Rig(core, start_flange(TARGET_X, (10, 5, 0), (3, 0, 0)), static(T_m(TARGET_X)),
              status_fn=lambda k: pb.TOB_STATUS_POSITION_ONLY)
    R0 = rig.flange[:3, :3].copy()
    rig.step(150)
    np.testing.assert_allclose(rig.flange[:3, :3], R0, atol=1e-12)
    p_d = (rig.flange @ core.flange_T_desired)[:3, 3]
    assert np.linalg.norm(p_d - T_m(TARGET_X)[:3, 3]) < 1e-4  # within the 0.1 mm deadband
    assert {s.mode for s in rig.of("controller/status")} == {pb.CONTROL_MODE_POSITION_ONLY}


def test_hold_and_track_commands_and_bad_commands():
    core = ControllerCore(ControllerConfig())
    rig = Rig(core, start_flange(TARGET_X, (20, 0, 0)), static(T_m(TARGET_X)))
    rig.command("hold")
    rig.step(5)
    held = rig.of("controller/command")
    assert len(held) == 5 and all(from_vector3(c.d_translation_m).tolist() == [0, 0, 0] for c in held)
    rig.command("track")
    rig.step(1)
    assert np.linalg.norm(from_vector3(rig.of("controller/command")[-1].d_translation_m)) > 0
    rig.command("warp")
    rig.outs += core.step(0, "console/command", pb.Command(verb="playback", args_json="[1, 2]"))
    codes = [m.code for m in rig.of("controller/events")]
    assert codes.count("bad_command") == 2


def test_recording_every_n_cycles_with_the_tip():
    # recording_spacing_mm = 0: every recording_delay_cycles only, the first after as many.
    core = ControllerCore(ControllerConfig(recording_delay_cycles=10, has_driver=True, recording_spacing_mm=0.0))
    rig = Rig(core, start_flange(TARGET_X), static(T_m(TARGET_X)))
    rig.step(5)
    rig.command("record_start")
    rig.step(100)
    rig.command("record_stop")
    rig.step(30)
    pts = rig.of("controller/path")
    assert [p.index for p in pts] == list(range(10))
    p = pts[0]
    assert p.has_tip
    tip = from_pose(p.world_T_tip)
    np.testing.assert_allclose(tip[:3, 3], (T_m(TARGET_X) @ np.array([0, 0, 0.06, 1]))[:3], atol=1e-12)
    assert json.loads([m for m in rig.of("controller/events") if m.code == "record_stopped"][0].text) == {"points": 10}


def straight(speed_mm_s):
    """A target moving along world x at ``speed_mm_s`` from TARGET_X (its orientation fixed)."""
    def f(t_ns):
        T = T_m(TARGET_X)
        v = np.array([speed_mm_s * 1e-3, 0.0, 0.0])
        T[:3, 3] += v * t_ns * 1e-9
        return T, v, np.zeros(3)
    return f


def test_recording_starts_at_the_first_measurement_then_keeps_its_delay_when_still():
    """Issue 32.3: the first point at the first measurement after record_start (it came 10
    cycles, 0.28 s, later); a still target still gets a point every recording_delay_cycles."""
    core = ControllerCore(ControllerConfig(recording_delay_cycles=10, has_driver=True))
    rig = Rig(core, start_flange(TARGET_X), static(T_m(TARGET_X)))
    rig.step(5)
    rig.command("record_start")
    rig.step(100)
    pts = rig.of("controller/path")
    assert [p.header.stamp_ns // DT_NS for p in pts] == list(range(5, 105, 10))


@pytest.mark.parametrize("speed_mm_s, every", [(20.0, 2), (60.0, 1)])
def test_recording_is_as_dense_as_the_speed_needs(speed_mm_s, every):
    """Issue 32.3: at 60 mm/s a point every 10 cycles (28 ms) was 16.8 mm from the last; with
    recording_spacing_mm = 1 a point comes whenever the target moved 1 mm: at 20 mm/s (0.56
    mm a cycle) every 2nd measurement (1.12 mm apart), at 60 mm/s (1.68 mm a cycle) every one."""
    core = ControllerCore(ControllerConfig(recording_delay_cycles=10, recording_spacing_mm=1.0))
    rig = Rig(core, start_flange(TARGET_X), straight(speed_mm_s))
    rig.step(3)
    rig.command("record_start")
    rig.step(60)
    pts = rig.of("controller/path")
    cycles = [p.header.stamp_ns // DT_NS for p in pts]
    assert cycles == list(range(3, 63, every))
    x_mm = np.array([from_pose(p.world_T_tob)[0, 3] * 1e3 for p in pts])
    np.testing.assert_allclose(np.diff(x_mm), speed_mm_s * 0.028 * every, atol=1e-6)


def test_recording_goes_on_across_a_clock_step_back():
    """A -2 s step of the clock (NTP) moves every later stamp back: the path used to take no
    point until the stamps passed the last one again (2 s of seam lost); now a stamp far
    behind the last point's is a new time base, said once, and the recording goes on."""
    core = ControllerCore(ControllerConfig(recording_delay_cycles=10, recording_spacing_mm=1.0))
    rig = Rig(core, start_flange(TARGET_X), straight(60.0))
    rig.shift_cycles = 200  # (stamps 5.6 s on: room for the step back)
    rig.step(3)
    rig.command("record_start")
    rig.step(20)
    before = len(rig.of("controller/path"))
    rig.shift_cycles -= round(2e9 / DT_NS)  # -2 s
    rig.step(20)
    pts = rig.of("controller/path")
    assert len(pts) - before == 20  # every measurement after the step, as before it (60 mm/s: each one)
    assert [m.code for m in rig.of("controller/events")].count("stamps_back") == 1
    stamps = [p.header.stamp_ns for p in pts[before:]]
    assert stamps == sorted(stamps)


def test_driver_calibration_recovers_the_tip():
    tip_tob_m = np.array([0.004, -0.003, 0.075])
    pivot_w = np.array([0.25, 1.25, 0.05])

    def pivoting(t_ns):
        s = t_ns * 1e-9
        R = Rotation.from_euler("ZYX", [40 * np.sin(0.7 * s), 18 * np.sin(1.3 * s), 15 * np.cos(0.9 * s)],
                                degrees=True).as_matrix()
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = pivot_w - R @ tip_tob_m  # the tip stays on the pivot point
        return T, np.zeros(3), np.zeros(3)

    core = ControllerCore(ControllerConfig(calibration_samples=40))
    rig = Rig(core, start_flange(x_from_transform(T_mm(pivoting(0)[0]))), pivoting)
    rig.command("calibrate", pivot_mm=(pivot_w * 1e3).tolist())
    rig.step(600)
    done = [m for m in rig.of("controller/events") if m.code == "calibration_done"]
    assert done, [m.code for m in rig.of("controller/events")]
    res = json.loads(done[0].text)
    np.testing.assert_allclose(res["tob_t_tip_mm"], tip_tob_m * 1e3, atol=0.01)
    np.testing.assert_allclose(res["world_p_pivot_mm"], pivot_w * 1e3, atol=0.01)
    np.testing.assert_allclose(res["paper_tob_t_tip_mm"], tip_tob_m * 1e3, atol=0.01)
    np.testing.assert_allclose(core.rig.tip.tob_t_tip_mm, tip_tob_m * 1e3, atol=0.01)
    assert core.rig.tip.calibration.method == "pivot" and core.rig.tip.calibration.sigma["tob_t_tip_mm"] < 0.01
    assert core.mode == pb.CONTROL_MODE_TRACK


def test_playback_follows_the_recorded_path():
    core = ControllerCore(ControllerConfig(recording_delay_cycles=2, has_driver=True))
    rig = Rig(core, start_flange(x_from_transform(T_mm(arc(0)[0]))), arc)
    rig.step(20)
    rig.command("record_start")
    rig.step(300)
    rig.command("record_stop")
    path = [from_pose(p.world_T_tip)[:3, 3] for p in rig.of("controller/path")]
    rig.command("playback", speed_mm_s=30.0)
    tool_tips = []
    for _ in range(1500):
        rig.step(1)
        if core.mode != pb.CONTROL_MODE_PLAYBACK:
            break
        if not core.playback["approach"]:
            tool_tips.append((rig.flange @ core.flange_T_tool)[:3, 3])
    assert "playback_done" in [m.code for m in rig.of("controller/events")]
    path = np.array(path)
    # Distance of each tool tip to the recorded polyline.
    d = []
    for p in tool_tips:
        seg_a, seg_b = path[:-1], path[1:]
        ab = seg_b - seg_a
        s = np.clip(np.einsum("ij,ij->i", p - seg_a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        d.append(np.min(np.linalg.norm(seg_a + s[:, None] * ab - p, axis=1)))
    assert len(d) > 100 and max(d) * 1e3 < 0.5, max(d) * 1e3


def test_config_rejects_unstable_gains():
    # k dt < 0.5 at the link's cycle (the cell's config checks it: tests/runtime/test_one_cycle.py)
    with pytest.raises(ValueError, match="gain_translation_1_s"):
        ControllerConfig(gain_translation_1_s=40.0).check_cycle(28_000_000)  # 40 x 0.028 = 1.12
    ControllerConfig(gain_translation_1_s=40.0).check_cycle(4_000_000)  # 40 x 0.004 = 0.16
    with pytest.raises(ValueError, match="gain_rotation_1_s"):
        ControllerConfig(gain_rotation_1_s=0.0)


def test_a_filter_state_that_overtakes_its_robot_state_still_commands_the_next_cycle():
    """On the bus the filter's state for cycle k may reach the controller before the robot
    state k itself: the flange at k then follows from k - 1 and the step sent for it, and the
    command is for k + 1 as if the robot state had come first (no cycle left without one)."""

    def run(swap_at):
        core = ControllerCore(ControllerConfig())
        flange = start_flange(TARGET_X, (5, -3, 4), (1, -1, 2))
        tob = T_m(TARGET_X)
        pending, cmds = {}, []
        for k in range(8):
            t = k * DT_NS
            rs = pb.RobotState(header=header(t, k, "world"), world_T_flange=pose(flange), cycle=k)
            st = pb.TobState(header=header(t, k, "world"), world_T_tob=pose(tob), status=pb.TOB_STATUS_FULL,
                             linear_velocity_m_s=vector3(np.zeros(3)), angular_velocity_rad_s=vector3(np.zeros(3)),
                             cycle=k)
            order = [("pose_filter/tob_state", st), ("robot_gateway/robot_state", rs)] if k == swap_at else \
                [("robot_gateway/robot_state", rs), ("pose_filter/tob_state", st)]
            for topic, m in order:
                for tp, out in core.step(t + 1, topic, m):
                    if tp == "controller/command":
                        pending[out.cycle] = out
                        cmds.append(out)
            cmd = pending.pop(k, None)
            if cmd is not None:
                flange = robot_step(flange, from_vector3(cmd.d_translation_m), from_vector3(cmd.d_rotation_rad))
        return cmds

    plain, swapped = run(None), run(4)
    assert [c.cycle for c in swapped] == [c.cycle for c in plain] == list(range(1, 9))
    for a, b in zip(plain, swapped, strict=True):
        np.testing.assert_allclose(from_vector3(a.d_translation_m), from_vector3(b.d_translation_m), atol=1e-12)
        np.testing.assert_allclose(from_vector3(a.d_rotation_rad), from_vector3(b.d_rotation_rad), atol=1e-12)


def test_the_cycle_counter_wraps_without_losing_a_command():
    core = ControllerCore(ControllerConfig())
    flange, tob = start_flange(TARGET_X), T_m(TARGET_X)
    cycles = []
    for k in (0xFFFFFFFE, 0xFFFFFFFF, 0, 1):
        t = 1_000_000_000 + len(cycles) * DT_NS
        core.step(t, "robot_gateway/robot_state", pb.RobotState(header=header(t, 0, "world"),
                                                                world_T_flange=pose(flange), cycle=k))
        st = pb.TobState(header=header(t, 0, "world"), world_T_tob=pose(tob), status=pb.TOB_STATUS_FULL,
                         linear_velocity_m_s=vector3(np.zeros(3)), angular_velocity_rad_s=vector3(np.zeros(3)),
                         cycle=k)
        cycles += [m.cycle for tp, m in core.step(t + 1, "pose_filter/tob_state", st) if tp == "controller/command"]
    assert cycles == [0xFFFFFFFF, 0, 1, 2]


def test_position_only_cycles_are_recorded_held_and_playback_interpolates_them():
    """Issue 18.2: with one or two sources the path goes on (orientation_held), with the
    state's covariance; playback of the recorded path takes the held orientations from the
    measured ones around them, not the (drifting) held ones."""
    def drifting(t_ns):  # a still target whose *held* orientation the filter lets drift
        T = T_m(TARGET_X)
        k = round(t_ns / DT_NS)
        if 20 <= k < 40:
            T[:3, :3] = Rotation.from_euler("z", 3.0 * (k - 19), degrees=True).as_matrix() @ T[:3, :3]
        return T, np.zeros(3), np.zeros(3)

    core = ControllerCore(ControllerConfig(recording_delay_cycles=1, has_driver=True, record_on_start=True))
    rig = Rig(core, start_flange(TARGET_X), drifting,
              status_fn=lambda k: pb.TOB_STATUS_POSITION_ONLY if 20 <= k < 40 else pb.TOB_STATUS_FULL)
    cov = np.diag([1e-8, 2e-8, 3e-8, 1e-4, 2e-4, 3e-4, 1, 1, 1, 1, 1, 1])
    rig.covariance = cov
    rig.step(60)
    pts = rig.of("controller/path")
    held = [p.orientation_held for p in pts]
    cycles = [p.header.stamp_ns // DT_NS for p in pts]
    assert cycles == list(range(60)) and held == [20 <= k < 40 for k in cycles]  # none missing
    np.testing.assert_allclose(np.reshape(pts[30].position_covariance_m2, (3, 3)), cov[:3, :3])
    np.testing.assert_allclose(np.reshape(pts[30].rotation_covariance_rad2, (3, 3)), cov[3:6, 3:6])
    assert len(pts[30].tip_position_covariance_m2) == 9
    rig.command("playback", speed_mm_s=20.0)
    tips = core.playback["tips"]
    angles = [np.degrees(Rotation.from_matrix(t[:3, :3] @ T_m(TARGET_X)[:3, :3].T).magnitude()) for t in tips]
    assert max(angles) < 1e-6, max(angles)  # the held (drifted by up to 60 deg) ones interpolated


def _timed_line(core):
    """A 60 mm line along world x from where the tool is: 30 mm in 3 s, then 30 mm in 1 s
    (10 then 30 mm/s), with the tool's orientation; points every 5 mm."""
    rig = Rig(core, start_flange(TARGET_X), static(T_m(TARGET_X)))
    tool = x_from_transform(T_mm(rig.flange @ core.flange_T_tool))
    xs = np.arange(0.0, 60.1, 5.0)
    times = np.where(xs <= 30, xs / 10.0, 3.0 + (xs - 30) / 30.0)
    points = [[tool[0] + x, *tool[1:]] for x in xs]
    return rig, points, times.tolist()


def _play(rig, core, max_cycles=2000, on_cycle=None):
    """Step until playback ends; (cycles from the approach's end to playback_done, tool tips)."""
    started, tips = None, []
    for k in range(max_cycles):
        rig.step(1)
        if on_cycle is not None:
            on_cycle(k)
        if core.mode != pb.CONTROL_MODE_PLAYBACK:
            break
        if not core.playback["approach"]:
            started = k if started is None else started
            tips.append((rig.flange @ core.flange_T_tool)[:3, 3] * 1e3)
    assert "playback_done" in [m.code for m in rig.of("controller/events")]
    return k - started, np.array(tips)


def test_timed_playback_keeps_the_timing_and_rate_scales_it():
    dt = 28e-3  # the link's cycle: ALTER's (the robot states here carry none: the fallback)
    core = ControllerCore(ControllerConfig())
    rig, points, times = _timed_line(core)
    rig.command("playback", points=points, times_s=times)
    cycles, tips = _play(rig, core)
    assert abs(cycles * dt - 4.0) < 0.5, cycles * dt  # the timing's 4 s (plus settling)
    v = np.linalg.norm(np.diff(tips, axis=0), axis=1) / dt
    assert 8 < np.median(v[: int(2.5 / dt)]) < 12 and np.max(v) < 36  # 10 mm/s, then 30 (its lag allowed)
    core = ControllerCore(ControllerConfig())
    rig, points, times = _timed_line(core)
    rig.command("playback", points=points, times_s=times)
    rig.command("playback_rate", rate=2.0)
    cycles, _ = _play(rig, core)
    assert abs(cycles * dt - 2.0) < 0.5, cycles * dt


def test_pause_stands_on_the_path_and_resume_goes_on():
    core = ControllerCore(ControllerConfig())
    rig, points, times = _timed_line(core)
    rig.command("playback", points=points, times_s=times)
    seen = {}

    def pause_then_resume(k):
        if core.playback and not core.playback["approach"]:
            seen.setdefault("start", k)
            if k == seen["start"] + 40:
                rig.command("playback_pause")
            if k == seen["start"] + 80:  # 40 cycles paused: the last 20 must not move
                seen["still_mm"] = np.linalg.norm(rig.flange[:3, 3] - seen["at"]) * 1e3
                rig.command("playback_resume")
            if k == seen["start"] + 60:
                seen["at"] = rig.flange[:3, 3].copy()

    _play(rig, core, on_cycle=pause_then_resume)
    codes = [m.code for m in rig.of("controller/events")]
    assert codes.index("playback_paused") < codes.index("playback_resumed") < codes.index("playback_done")
    assert seen["still_mm"] < 0.05


@pytest.mark.parametrize("args, needle", [
    ({"points": [[0, 0, 0, 0, 0, 0]] * 3, "times_s": [0, 1]}, "one time per point"),
    ({"points": [[0, 0, 0, 0, 0, 0]] * 2, "times_s": [1, 0]}, "never decreasing"),
    ({"points": [[0, 0, 0, 0, 0, 0], [50, 0, 0, 0, 0, 0]], "times_s": [0, 0.1]}, "max_speed_mm_s"),  # 500 mm/s
    ({"times_s": [0, 1]}, "no points given"),
])
def test_bad_timings_are_refused(args, needle):
    core = ControllerCore(ControllerConfig())
    outs = core.step(0, "console/command", pb.Command(verb="playback", args_json=json.dumps(args)))
    ev = [m for t, m in outs if t == "controller/events"]
    assert [e.code for e in ev] == ["bad_command"] and needle in ev[0].text and core.playback is None


def test_pause_without_a_playback_is_refused():
    core = ControllerCore(ControllerConfig())
    for verb in ("playback_pause", "playback_resume"):
        outs = core.step(0, "console/command", pb.Command(verb=verb))
        assert [m.code for t, m in outs if t == "controller/events"] == ["bad_command"]
