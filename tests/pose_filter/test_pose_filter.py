"""pose_filter core on scripted inputs: interpolation at the capture stamp, Kalman
smoothing, gating, re-acquisition, position-only updates, angle wrap, loss, bad input.
The filter is built with ``wait_for_robot_ms=0`` (a measurement is used at once, robot pose
extrapolated if need be) where a test reads its outputs right after a measurement; the
wait itself has its own tests."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry.target import TargetModel
from humanpt.geometry.transforms import invert_transform, transform_from_x, x_from_transform
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.pose_filter.kalman import process_noise, transition
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header, pose, vector3

CYCLE_NS = 28_000_000
FRAME_NS = 33_333_333


def T_m(x_mm_deg) -> np.ndarray:
    T = transform_from_x(np.asarray(x_mm_deg, dtype=float))
    T[:3, 3] *= 1e-3
    return T


def x_of(T_m_) -> np.ndarray:
    T = np.array(T_m_, dtype=float)
    T[:3, 3] *= 1e3
    return x_from_transform(T)


class World:
    """A robot moving as ``flange(t)`` and a target as ``tob(t)`` (both world_T_*, metres)."""

    def __init__(self, core: PoseFilterCore, flange, tob, rng=None, sigma_mm=0.0, sigma_deg=0.0):
        self.core, self.flange, self.tob = core, flange, tob
        self.rng = rng or np.random.default_rng(0)
        self.sigma_mm, self.sigma_deg = sigma_mm, sigma_deg
        self.cycle = 0
        self.states: list[pb.TobState] = []
        self.events: list[pb.Event] = []

    def robot_state(self, t_ns):
        msg = pb.RobotState(header=header(t_ns, self.cycle, "world"), world_T_flange=pose(self.flange(t_ns)),
                            cycle=self.cycle)
        self.cycle += 1
        self._take(self.core.step(t_ns, "robot_gateway/robot_state", msg))

    def measurement(self, t_ns, world_T_tob=None, status=pb.TOB_STATUS_FULL, points_tob_m=None):
        world_T_tob = self.tob(t_ns) if world_T_tob is None else world_T_tob
        cam = self.flange(t_ns) @ self.core.flange_T_camera_m
        camera_T_tob = invert_transform(cam) @ world_T_tob
        if self.sigma_mm:
            camera_T_tob[:3, 3] += self.rng.normal(0, self.sigma_mm * 1e-3, 3)
            camera_T_tob[:3, :3] = Rotation.from_rotvec(
                np.radians(self.rng.normal(0, self.sigma_deg, 3))).as_matrix() @ camera_T_tob[:3, :3]
        msg = pb.TobMeasurement(header=header(t_ns, 0, "camera"), status=status)
        if status == pb.TOB_STATUS_FULL:
            msg.camera_T_tob.CopyFrom(pose(camera_T_tob))
        for p in points_tob_m if points_tob_m is not None else []:
            msg.points_camera_m.append(vector3(camera_T_tob[:3, :3] @ p + camera_T_tob[:3, 3]))
        self._take(self.core.step(t_ns + 5_000_000, "perception/tob", msg))

    def _take(self, outs):
        for topic, m in outs:
            (self.states if topic == "pose_filter/tob_state" else self.events).append(m)

    def run(self, t0_ns, t1_ns, measure=True):
        """Robot states every 28 ms and images every 33.3 ms, in time order."""
        tr, ti = t0_ns, t0_ns + 7_000_000
        while min(tr, ti) < t1_ns:
            if tr <= ti:
                self.robot_state(tr)
                tr += CYCLE_NS
            else:
                if measure:
                    self.measurement(ti)
                ti += FRAME_NS


TARGET_X = (236.132, 1248.772, 85.284, -2.598, -0.883, -4.535)


def moving_flange(t_ns):
    """The robot sweeps 60 mm/s along x and turns 10 deg/s about z: a stale robot pose
    would put the target mm off."""
    s = t_ns * 1e-9
    return T_m((200 + 60 * s, 700, 80, 10 * s, 0, 0))


def test_kalman_matrices():
    F = transition(0.5)
    x = np.zeros(12)
    x[6:9] = [1, 2, 3]
    np.testing.assert_allclose((F @ x)[0:3], [0.5, 1.0, 1.5])
    Q = process_noise(0.1, 2.0, 3.0)
    np.testing.assert_allclose(Q, Q.T)
    assert np.all(np.linalg.eigvalsh(Q) >= -1e-15)
    np.testing.assert_allclose(Q[6, 6], 4.0 * 0.1)
    np.testing.assert_allclose(Q[9, 9], 9.0 * 0.1)


def test_uses_the_robot_pose_at_the_capture_stamp():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    truth = T_m(TARGET_X)
    w = World(core, moving_flange, lambda t: truth)
    w.run(0, 2_000_000_000)
    last = w.states[-1]
    assert last.status == pb.TOB_STATUS_FULL
    err_mm = np.linalg.norm(from_pose(last.world_T_tob)[:3, 3] - truth[:3, 3]) * 1e3
    assert err_mm < 1e-3, err_mm  # exact data: only interpolation could spoil it


def test_static_target_converges_and_smooths_noise():
    # A calm process model (the target is still), the noise the world below adds, and no
    # prediction ahead: pure smoothing.
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0, accel_sigma_mm_s2=5.0, ang_accel_sigma_deg_s2=3.0,
                                           sigma_position_mm=0.3, sigma_depth_mm=0.3, sigma_rotation_deg=0.8, sigma_spin_deg=0.8))
    core.use_cycle(0)  # (the World's robot states carry no cycle: this horizon stays)
    truth = T_m(TARGET_X)
    w = World(core, moving_flange, lambda t: truth, np.random.default_rng(3), sigma_mm=0.3, sigma_deg=0.8)
    w.run(0, 6_000_000_000)
    xs = np.array([x_of(from_pose(s.world_T_tob)) for s in w.states[-60:]])
    err = xs - np.asarray(TARGET_X)
    # A raw measurement's mean absolute error is 0.8 sigma: 0.24 mm and 0.64 deg.
    assert np.all(np.abs(err[:, :3]).mean(axis=0) < 0.7 * 0.24), np.abs(err).mean(axis=0)
    assert np.all(np.abs(err[:, 3:]).mean(axis=0) < 0.7 * 0.64), np.abs(err).mean(axis=0)
    P = np.array(w.states[-1].covariance).reshape(12, 12)
    assert np.sqrt(P[0, 0]) * 1e3 < 0.3


def test_prediction_ahead_follows_a_constant_velocity():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    core.use_cycle(56_000_000)  # two ALTER cycles ahead (the World's states carry no cycle)

    def tob(t):
        return T_m((100 + 50 * t * 1e-9, 1200, 80, 5 * t * 1e-9, 0, 0))

    w = World(core, lambda t: T_m((100, 700, 80, 0, 0, 0)), tob)
    w.run(0, 4_000_000_000)
    st = w.states[-1]
    want = tob(st.header.stamp_ns)
    got = from_pose(st.world_T_tob)
    assert np.linalg.norm(got[:3, 3] - want[:3, 3]) * 1e3 < 0.05
    np.testing.assert_allclose(np.array([st.linear_velocity_m_s.x]), [0.05], atol=1e-3)
    np.testing.assert_allclose(st.angular_velocity_rad_s.z, np.radians(5), atol=1e-3)


def test_outlier_is_gated_and_reported_then_a_real_jump_is_reacquired():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0, reset_after_rejects=3))
    truth = T_m(TARGET_X)
    w = World(core, lambda t: T_m((200, 700, 80, 0, 0, 0)), lambda t: truth)
    w.run(0, 2_000_000_000)
    before = from_pose(w.states[-1].world_T_tob)
    jumped = truth.copy()
    jumped[:3, 3] += [0.05, 0, 0]  # 50 mm
    w.measurement(2_010_000_000, world_T_tob=jumped)
    assert [e.code for e in w.events][-1] == "outlier"
    w.robot_state(2_020_000_000)
    assert np.linalg.norm(from_pose(w.states[-1].world_T_tob)[:3, 3] - before[:3, 3]) < 1e-4
    assert w.states[-1].gated_outliers == 1
    for k in range(2):
        w.measurement(2_040_000_000 + k * FRAME_NS, world_T_tob=jumped)
    assert "filter_reset" in [e.code for e in w.events]
    w.robot_state(2_200_000_000)
    np.testing.assert_allclose(from_pose(w.states[-1].world_T_tob)[:3, 3], jumped[:3, 3], atol=1e-4)


def test_position_only_updates_position_and_keeps_orientation():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    truth = T_m(TARGET_X)
    w = World(core, lambda t: T_m((200, 700, 80, 0, 0, 0)), lambda t: truth)
    w.run(0, 1_000_000_000)
    R_before = from_pose(w.states[-1].world_T_tob)[:3, :3]
    moved = truth.copy()
    moved[:3, 3] += [0.004, -0.003, 0.0]
    src = TargetModel.isosceles(40.0, 30.0).source_positions_mm * 1e-3
    for k in range(30):
        w.measurement(1_010_000_000 + k * FRAME_NS, world_T_tob=moved, status=pb.TOB_STATUS_POSITION_ONLY,
                      points_tob_m=src[[0, 2]])  # sources A and C seen
        w.robot_state(1_020_000_000 + k * FRAME_NS)
    st = w.states[-1]
    assert st.status == pb.TOB_STATUS_POSITION_ONLY
    np.testing.assert_allclose(from_pose(st.world_T_tob)[:3, 3], moved[:3, 3], atol=3e-4)
    np.testing.assert_allclose(from_pose(st.world_T_tob)[:3, :3], R_before, atol=1e-9)


def test_yaw_near_180_does_not_average_through_zero():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    flange = T_m((200, 700, 80, 0, 0, 0))
    w = World(core, lambda t: flange, lambda t: truth)
    for k in range(60):
        truth = T_m((236, 1248, 85, 179.9 if k % 2 else -179.9, 0, 0))
        w.robot_state(k * CYCLE_NS)
        w.measurement(k * CYCLE_NS + 1_000_000, world_T_tob=truth)
    yaw = x_of(from_pose(w.states[-1].world_T_tob))[3]
    assert abs(abs(yaw) - 180.0) < 1.0, yaw  # averaging through 0 would give ~0


def test_lost_after_silence_and_bad_input_never_raises():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0, lost_after_ms=100))
    truth = T_m(TARGET_X)
    w = World(core, lambda t: T_m((200, 700, 80, 0, 0, 0)), lambda t: truth)
    w.run(0, 500_000_000)
    assert w.states[-1].status == pb.TOB_STATUS_FULL
    w.run(500_000_000, 800_000_000, measure=False)
    assert w.states[-1].status == pb.TOB_STATUS_LOST
    bad = pb.TobMeasurement(header=header(800_000_000), status=pb.TOB_STATUS_FULL)
    bad.camera_T_tob.translation.x = float("nan")
    outs = core.step(800_000_001, "perception/tob", bad)
    assert [m.code for _, m in outs] == ["bad_input"]  # every core's input check
    far = pb.TobMeasurement(header=header(50_000_000_000), status=pb.TOB_STATUS_FULL)
    outs = core.step(800_000_002, "perception/tob", far)
    assert [m.code for _, m in outs] == ["no_robot_pose"]
    outs = core.step(800_000_003, "robot_gateway/robot_state", pb.RobotState(
        world_T_flange=pb.Pose(translation=pb.Vector3(x=float("inf")))))
    assert [m.code for _, m in outs] == ["bad_input"]
    outs = core.step(800_000_003, "robot_gateway/robot_state", pb.RobotState(
        header=header(2**63 - 1), world_T_flange=pb.Pose(rotation=pb.Quaternion(w=1.0))))
    assert [m.code for _, m in outs] == ["robot_state_rejected"]


def test_config_is_validated():
    with pytest.raises(ValueError, match="sigma_position_mm must be > 0"):
        PoseFilterConfig(sigma_position_mm=0)


def test_images_before_the_robots_first_state_are_dropped_with_one_info():
    """Start-up: the camera may see the target before the ALTER link is up."""
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    m = pb.TobMeasurement(header=header(1_000_000), status=pb.TOB_STATUS_FULL)
    m.camera_T_tob.CopyFrom(pose(T_m(TARGET_X)))
    first = core.step(1_000_001, "perception/tob", m)
    again = core.step(2_000_001, "perception/tob", m)
    assert [(e.code, e.severity) for _, e in first] == [("waiting_for_robot", pb.SEVERITY_INFO)]
    assert again == [] and not core.kf.initialised


# -- forged and stepping robot stamps (issue 14, item 2) --------------------------------------
def test_a_forged_future_robot_state_does_not_lock_out_the_real_ones():
    """The attack: one robot_state stamped in the future made the buffer refuse every real
    state after it (servo error 0.19 -> 73 mm while the status stayed FULL)."""
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    truth = T_m(TARGET_X)
    w = World(core, lambda t: T_m((200, 700, 80, 0, 0, 0)), lambda t: truth)
    w.run(0, 500_000_000)
    reported = []
    for stamp in (500_000_000 + 10**12, 2**63 - 1):  # 1000 s ahead; the largest int64
        forged = pb.RobotState(header=header(stamp), cycle=99, world_T_flange=pose(np.eye(4)))
        outs = core.step(500_000_001, "robot_gateway/robot_state", forged)
        assert all(t == "pose_filter/events" for t, _ in outs)  # no state from a forged one
        reported += [m.code for _, m in outs]
    assert reported == ["robot_state_rejected"]  # the first reported, the second counted
    assert [m.code for t, m in core.step(500_000_001, "robot_gateway/robot_state", forged)] == []  # rate-limited
    n = len(w.states)
    w.run(500_000_000, 1_000_000_000)
    assert len(w.states) > n + 10  # the real states still come in and are answered
    got = from_pose(w.states[-1].world_T_tob)
    assert np.abs(got[:3, 3] - truth[:3, 3]).max() < 1e-3 and w.states[-1].status == pb.TOB_STATUS_FULL


def test_a_robot_clock_that_steps_back_restarts_the_buffer():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    flange = pose(np.eye(4))
    t = 10_000_000_000
    for k in range(5):
        core.step(t + k * 28_000_000, "robot_gateway/robot_state",
                  pb.RobotState(header=header(t + k * 28_000_000), cycle=k, world_T_flange=flange))
    back = t - 500_000_000  # the robot's clock stepped back half a second (within the skew)
    codes = []
    for k in range(3):
        outs = core.step(t + (5 + k) * 28_000_000, "robot_gateway/robot_state",
                         pb.RobotState(header=header(back + k * 28_000_000), cycle=5 + k, world_T_flange=flange))
        codes += [m.code for tp, m in outs if tp == "pose_filter/events"]
    assert codes == ["robot_state_rejected", "robot_clock_reset"]
    assert core.robot.latest[0] == back + 2 * 28_000_000


def zigzag_flange(t_ns):
    """A robot whose speed changes at every 28 ms cycle (as an ALTER-driven one does):
    piecewise linear between the cycle stamps, 0 and 120 mm/s along x in turn."""
    k, rest = divmod(int(t_ns), CYCLE_NS)
    x = 120.0 * (k // 2) * CYCLE_NS * 1e-9 + (120.0 * rest * 1e-9 if k % 2 else 0.0)  # mean 60 mm/s
    return T_m((200 + x, 700, 80, 0, 0, 0))


class LateStates(World):
    """Robot states reach the filter 11 ms after their stamp (a STATUS frame on a 38 400
    baud line), measurements 5 ms after their image: a measurement usually arrives
    before the state of the cycle after it."""

    def run(self, t0_ns, t1_ns, measure=True):
        events = [(tr + 11_000_000, 0, tr) for tr in range(t0_ns, t1_ns, CYCLE_NS)]
        events += [(ti + 5_000_000, 1, ti) for ti in range(t0_ns + 7_000_000, t1_ns, FRAME_NS)]
        for _, kind, stamp in sorted(events):
            if kind == 0:
                msg = pb.RobotState(header=header(stamp, self.cycle, "world"),
                                    world_T_flange=pose(self.flange(stamp)), cycle=self.cycle)
                self.cycle += 1
                self._take(self.core.step(stamp + 11_000_000, "robot_gateway/robot_state", msg))
            elif measure:
                self.measurement(stamp)


@pytest.mark.parametrize("wait_ms", [60.0, 0.0])
def test_a_measurement_waits_for_the_robot_state_after_it(wait_ms):
    # A still target seen exactly from a robot that changes speed every cycle: with the
    # wait, the robot pose at each image is interpolated between the states around it,
    # which is exact for this robot; without it, it is extrapolated from the two before,
    # off by up to 120 mm/s x 28 ms ~ 3 mm whenever the speed changed in between.
    target = T_m(TARGET_X)
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=wait_ms, still_detect=False))
    w = LateStates(core, zigzag_flange, lambda t: target)
    w.run(0, 1_500_000_000)
    got = np.array([from_pose(s.world_T_tob_at_measurement)[:3, 3] for s in w.states
                    if s.HasField("world_T_tob_at_measurement")])
    assert len(got) > 30
    err_mm = np.abs(got - target[:3, 3]).max() * 1e3
    if wait_ms:
        assert err_mm < 1e-6, err_mm
        assert not [e for e in w.events if e.code == "no_robot_pose"]
    else:
        assert err_mm > 0.5, err_mm  # the check above can fail: the robot does need it


def test_an_orientation_not_measured_is_held_and_its_uncertainty_still_grows():
    """Issue 32 (a source hidden for 2 s): hold_orientation sets the angular velocity's
    estimate to zero in every model, so a prediction keeps the orientation (by hand: with
    w = 0 the constant-velocity transition leaves r unchanged) while the position goes on at
    its velocity, and the orientation's variance still grows with the prediction."""
    import numpy as np

    from humanpt.pose_filter.kalman import PoseIMM, PoseKalman

    for kf in (PoseKalman(1.0, 1.0), PoseIMM(((0.5, 0.5), (5.0, 5.0)), 2.0, 0.5)):
        kf.reset(0, np.eye(4))
        for f in kf._filters():
            f.x[6:9] = [0.01, 0.0, 0.0]  # 10 mm/s along x
            f.x[9:12] = [0.0, 0.0, 0.1]  # 0.1 rad/s about z
        turned = kf.predicted_pose(1_000_000_000)
        assert np.degrees(np.arccos(np.clip((np.trace(turned[:3, :3]) - 1) / 2, -1, 1))) > 5.0  # 0.1 rad/s for 1 s
        var_before = np.diag(kf.P)[3:6].copy() if isinstance(kf, PoseKalman) else None
        kf.hold_orientation()
        held = kf.predicted_pose(1_000_000_000)
        np.testing.assert_allclose(held[:3, :3], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(held[:3, 3], [0.01, 0.0, 0.0], atol=1e-12)  # the position goes on
        if var_before is not None:
            kf.predict_to(1_000_000_000)
            assert (np.diag(kf.P)[3:6] > var_before).all()
