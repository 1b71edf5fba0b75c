"""The lock-step world: the static scenario shows six blobs where the geometry says; runs
are deterministic and replay; the stand-in robot integrates (and limits) commands."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation

from humanpt.geometry import (
    DEFAULT_FLANGE_T_CAMERA_MM,
    invert_transform,
    project,
    transform_from_x,
    x_from_transform,
)
from humanpt.operator import BUILTIN_SCENARIOS, OperatorConfig, builtin_scenario
from humanpt.runtime.core import Core, Port
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, vector3
from humanpt.sim_camera import SimCameraConfig
from humanpt.twin import (
    DEFAULT_START_FLANGE_MM_DEG,
    StandInRobotConfig,
    build_world,
    start_flange_for,
)

# -- the start poses, worked out by hand ----------------------------------------------------
# The default camera sits on the flange with its axes parallel to the flange's and its optical
# centre at (0, 60, 100) mm (geometry.rig); the servo's desired point D is on the optical axis
# 600 mm ahead, its frame parallel to the camera's (paper, Section 5). A robot that starts
# viewing a target therefore has world_R_flange = world_R_tob and
#     p_flange = p_tob - world_R_tob @ (0, 60, 100 + 600).
# For a tip path (trapezium, freehand) the scenario gives the needle tip, 60 mm along the TOB's
# z axis (tob_T_tip = (0, 0, 60), same axes): p_tob = p_tip - world_R_tob @ (0, 0, 60).
CAMERA_AND_D_IN_FLANGE_MM = np.array([0.0, 60.0, 700.0])
NEEDLE_IN_TOB_MM = np.array([0.0, 0.0, 60.0])


def _rotation(ypr_deg) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll): the project's X convention, by scipy."""
    return Rotation.from_euler("ZYX", ypr_deg, degrees=True).as_matrix()


def _hand_start_flange(start_x_mm_deg, tip_path: bool = False) -> np.ndarray:
    p, R = np.array(start_x_mm_deg[:3], dtype=float), _rotation(start_x_mm_deg[3:])
    if tip_path:
        p = p - R @ NEEDLE_IN_TOB_MM
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p - R @ CAMERA_AND_D_IN_FLANGE_MM
    return T


s50, c50 = math.sin(math.radians(50.0)), math.cos(math.radians(50.0))
s15, c15 = math.sin(math.radians(15.0)), math.cos(math.radians(15.0))
HAND_START_FLANGES = {
    # Table 1's target pose.
    "static": _hand_start_flange((236.132, 1248.772, 85.284, -2.598, -0.883, -4.535)),
    # The rotating base at index angle +50 deg: TOB at centre + 246 mm (sin 50, -cos 50, 0),
    # yaw 50, roll 180 (face up): R @ (0, 60, 700) = (60 sin 50, -60 cos 50, -700), so the
    # flange is 246 - 60 = 186 mm from the centre and 700 mm above the TOB.
    "arc": np.block([[_rotation((50.0, 0.0, 180.0)),
                      np.array([[147.5 + 186.0 * s50], [1378.5 - 186.0 * c50], [448.0 + 700.0]])],
                     [np.zeros((1, 3)), np.ones((1, 1))]]),
    # The needle tip at the first corner (x0 - 451 / 2, y0 - 45 / 2, 0), torch pitch 15 deg,
    # roll 180: the TOB is 60 mm and the flange 760 mm back along the tilted axis (sin 15, 0,
    # cos 15), the flange also 60 mm along +y.
    "trapezium": np.block([[_rotation((0.0, 15.0, 180.0)),
                            np.array([[236.132 - 225.5 + 760.0 * s15], [1248.772 - 22.5 + 60.0],
                                      [760.0 * c15]])],
                           [np.zeros((1, 3)), np.ones((1, 1))]]),
    # Seeded: its start tip pose is data; the flange follows by the rule above.
    "freehand": _hand_start_flange(builtin_scenario("freehand").start_x_mm_deg, tip_path=True),
    # issue 18's hard cases: tip paths on the table at the trapezium's torch angle.
    **{name: _hand_start_flange(builtin_scenario(name).start_x_mm_deg, tip_path=True)
       for name in ("scurve", "abrupt", "occluded", "partial")},
}


def test_the_hand_computed_start_poses_follow_the_rule():
    """The closed forms above (arc, trapezium) and the rule agree: a check of the oracle."""
    np.testing.assert_allclose(HAND_START_FLANGES["arc"], _hand_start_flange(
        (147.5 + 246.0 * s50, 1378.5 - 246.0 * c50, 448.0, 50.0, 0.0, 180.0)), atol=1e-9)
    np.testing.assert_allclose(HAND_START_FLANGES["trapezium"], _hand_start_flange(
        (236.132 - 225.5, 1248.772 - 22.5, 0.0, 0.0, 15.0, 180.0), tip_path=True), atol=1e-9)


def _blob_centres(img: np.ndarray, threshold: float = 60.0) -> np.ndarray:
    labels, n = ndimage.label(img > threshold)
    w = img.astype(float) - 14.0  # background of the default sensor
    rc = np.array(ndimage.center_of_mass(w, labels, range(1, n + 1)))
    return rc[:, ::-1]  # (u, v)


def test_static_scenario_shows_six_blobs_where_the_geometry_says():
    world = build_world("static", seed=4).run_for(0.5)
    images = world.images()
    truths = world.truths("sim_camera/truth")
    assert len(images) == 15 and len(truths) == 15  # 30 fps for 0.5 s; none at t = 0 (no truth yet)
    assert [s for s, _ in images] == [t for t, _ in truths]
    stamp, img = images[-1]
    poses = truths[-1][1]
    world_T_camera = poses["world_T_flange"] @ DEFAULT_FLANGE_T_CAMERA_MM
    camera_T_tob = invert_transform(world_T_camera) @ poses["world_T_tob"]
    # The start pose: the TOB 600 mm ahead on the optical axis, frames parallel.
    np.testing.assert_allclose(camera_T_tob[:3, :3], np.eye(3), atol=1e-9)
    np.testing.assert_allclose(camera_T_tob[:3, 3], [0.0, 0.0, 600.0], atol=1e-6)
    sources = (
        world.camera.renderer.model.source_positions_mm @ camera_T_tob[:3, :3].T
        + camera_T_tob[:3, 3]
    )
    uv_right, uv_left = project(SimCameraConfig().params(), sources)
    expected = np.concatenate([uv_right, uv_left])
    found = _blob_centres(img)
    assert len(found) == 6
    dist = np.linalg.norm(found[:, None, :] - expected[None, :, :], axis=2)
    assert sorted(np.argmin(dist, axis=1).tolist()) == list(
        range(6)
    )  # one blob per source and view
    assert np.max(np.min(dist, axis=1)) < 0.1  # px, with noise
    # Pairs share a scan line (to the 0.014 px of the refraction shift l along the axis).
    np.testing.assert_allclose(uv_right[:, 1], uv_left[:, 1], atol=0.02)


def test_every_builtin_scenario_starts_in_view():
    for name in BUILTIN_SCENARIOS:
        world = build_world(name).run_for(0.1)
        _, img = world.images()[-1]
        assert len(_blob_centres(img, threshold=40)) == 6, name
        np.testing.assert_allclose(world.robot.world_T_flange, HAND_START_FLANGES[name], atol=1e-6)
        np.testing.assert_allclose(start_flange_for(OperatorConfig(scenario=name)), HAND_START_FLANGES[name],
                                   atol=1e-6)


def test_the_default_stand_in_start_pose_views_the_static_target():
    np.testing.assert_allclose(transform_from_x(np.array(DEFAULT_START_FLANGE_MM_DEG)), HAND_START_FLANGES["static"],
                               atol=1e-9)
    np.testing.assert_allclose(StandInRobotConfig().start_world_T_flange, HAND_START_FLANGES["static"], atol=1e-9)


def test_same_seed_same_run_and_recordings_replay_exactly(tmp_path):
    def run(seed, run_dir=None):
        world = build_world("freehand", seed=seed, run_dir=run_dir)
        world.run_for(0.7)
        world.close()
        return world

    a, b = run(7, tmp_path), run(7)
    assert a.digest() == b.digest()
    assert len(a.outputs("camera/image")) == 21
    assert run(8).digest() != a.digest()
    for comp in ("operator", "standin_robot", "sim_camera"):
        res = replay(tmp_path / f"{comp}.mcap")
        assert res.match, res.report()
        assert res.recorded_outputs == res.replayed_outputs > 0


class _Commander(Core):
    """A scripted controller: a fixed flange command every ALTER cycle."""

    name = "commander"
    config_type = type(None)
    ports = (Port("tick", pb.Tick, "_on_tick"),)

    def __init__(self, d_t_m, d_r_rad):
        super().__init__(None)
        self.d_t_m, self.d_r_rad = d_t_m, d_r_rad
        self.k = 0  # the robot's cycle: it ticks just before us at equal times

    def tick_period_ns(self):
        return 28_000_000

    def _on_tick(self, t_ns, msg):
        cmd = pb.FlangeCommand(
            header=self.next_header("controller/command", t_ns, "world"),
            cycle=self.k,
            d_translation_m=vector3(self.d_t_m),
            d_rotation_rad=vector3(self.d_r_rad),
        )
        self.k += 1
        return [("controller/command", cmd)]


def _flange_track(world) -> np.ndarray:
    states = [pb.RobotState.FromString(o.data) for o in world.outputs("robot_gateway/robot_state")]
    out = []
    for s in states:
        t = from_pose(s.world_T_flange)
        t[:3, 3] *= 1000
        out.append(t)
    return np.array(out)


def test_stand_in_robot_integrates_commands_in_the_world_frame():
    d_r = np.radians([0.0, 0.0, 0.5])  # 0.5 deg per cycle about world z
    world = build_world("static", extra_cores=[_Commander([0.001, -0.002, 0.0], d_r)])
    world.run_for(0.28)  # ten cycles after the first
    track = _flange_track(world)
    assert len(track) == 11
    # The commander ticks after the robot at equal times, so cycle k applies command k - 1.
    steps = np.diff(track[:, :3, 3], axis=0)
    np.testing.assert_allclose(steps[1:], np.tile([1.0, -2.0, 0.0], (9, 1)), atol=1e-9)
    yaw = np.array([x_from_transform(t)[3] for t in track])
    np.testing.assert_allclose(np.diff(yaw)[1:], 0.5, atol=1e-9)
    truth = world.truths("sim_robot/truth")
    np.testing.assert_allclose(truth[-1][1]["world_T_flange"], track[-1], atol=1e-9)
    states = [pb.RobotState.FromString(o.data) for o in world.outputs("robot_gateway/robot_state")]
    assert [s.cycle for s in states] == list(range(11)) and states[0].missed_cycles == 1
    assert states[-1].missed_cycles == 0 and states[-1].header.frame_id == "world"


def test_stand_in_robot_clips_to_the_step_limits_and_rejects_nan():
    world = build_world("static", extra_cores=[_Commander([0.05, 0.0, 0.0], [0.0, 0.0, 0.0])])
    world.run_for(0.28)
    steps = np.linalg.norm(np.diff(_flange_track(world)[:, :3, 3], axis=0), axis=1)
    np.testing.assert_allclose(steps[1:], 100.0 * 0.028, atol=1e-9)  # 100 mm/s x 28 ms
    events = [pb.Event.FromString(o.data) for o in world.outputs("standin_robot/events")]
    assert [e.code for e in events] == ["step_clipped"]  # once, not every cycle
    nan_world = build_world(
        "static", extra_cores=[_Commander([math.nan, 0.0, 0.0], [0.0, 0.0, 0.0])]
    )
    nan_world.run_for(0.1)
    # NaN never reaches the stand-in's handler: every core's input check drops it.
    assert {
        pb.Event.FromString(o.data).code for o in nan_world.outputs("standin_robot/events")
    } == {"bad_input"}
    track = _flange_track(nan_world)
    np.testing.assert_allclose(track, np.broadcast_to(track[0], track.shape))  # it never moved


def test_param_and_injected_inputs_reach_the_world():
    world = build_world("static", seed=1)
    world.lockstep.set_param(200_000_000, "sim_camera", "occluded_sources", "[0, 1, 2]")
    world.lockstep.set_param(200_000_000, "sim_camera", "occlusion_fraction", "1.0")
    world.run_for(0.4)
    images = world.images()
    before = [img for t, img in images if t < 200_000_000]
    after = [img for t, img in images if t > 200_000_000]
    assert before and after  # images on both sides of the change
    assert before[-1].max() > 100 and after[-1].max() < 25  # every source fully hidden


def test_stand_in_can_start_viewing_any_builtin_scenario_for_live_use():
    for name in BUILTIN_SCENARIOS:
        cfg = StandInRobotConfig(start_view=name)
        np.testing.assert_allclose(cfg.start_world_T_flange, HAND_START_FLANGES[name], atol=1e-6)
    with pytest.raises(ValueError, match="start_view"):
        StandInRobotConfig(start_view="zigzag")


def test_other_robot_cores_can_replace_the_stand_in():
    from humanpt.twin import StandInRobotCore

    class _Fixed(StandInRobotCore):
        name = "fixed_robot"

    world = build_world("static", robot_cores=[_Fixed(StandInRobotConfig())])
    assert world.robot is None
    world.run_for(0.2)
    assert len(world.images()) == 6


def test_stand_in_robot_can_lag_its_commands_by_a_first_order_response():
    """1 mm per cycle along x with tau = one cycle (28 ms): the flange trails its setpoint
    by e_k = (1 - g)(e_(k-1) + 1 mm), g = 1 - 1/e, which settles at 1 / (e - 1) = 0.582 mm
    (by hand); the reported pose is the lagging flange, and so is the truth."""
    start = transform_from_x(np.array(DEFAULT_START_FLANGE_MM_DEG))
    cfg = StandInRobotConfig(start_flange_mm_deg=DEFAULT_START_FLANGE_MM_DEG, lag_time_constant_ms=28.0)
    world = build_world("static", robot=cfg, extra_cores=[_Commander([0.001, 0.0, 0.0], [0.0, 0.0, 0.0])])
    world.run_for(0.56)  # twenty cycles after the first
    x = _flange_track(world)[:, 0, 3] - start[0, 3]
    setpoint = np.arange(len(x), dtype=float)  # 1 mm more every cycle from cycle 1 on
    g, e = 1.0 - math.exp(-1.0), 0.0
    expected = []
    for k in range(len(x)):
        e = 0.0 if k == 0 else (1.0 - g) * (e + 1.0)
        expected.append(setpoint[k] - e)
    np.testing.assert_allclose(x, expected, atol=1e-9)
    assert setpoint[-1] - x[-1] == pytest.approx(1.0 / (math.e - 1.0), abs=1e-3)
    truth = world.truths("sim_robot/truth")
    assert truth[-1][1]["world_T_flange"][0, 3] - start[0, 3] == pytest.approx(x[-1], abs=1e-9)


def test_the_evaluation_interpolates_the_truth_at_the_path_stamps_never_the_nearest():
    """Truth samples 10 ms apart moving 1 mm and 1 deg per sample: at 3 ms after a sample
    the truth is 0.3 mm and 0.3 deg on (by hand), not the nearest sample's pose."""
    from humanpt.twin.evaluate import truth_at

    class _Src:
        def truths(self, topic):
            return [(k * 10_000_000, {"world_T_tob": transform_from_x(np.array([k, 0, 0, k, 0, 0.0]))})
                    for k in range(5)]

    got = truth_at(_Src(), [23_000_000, 40_000_000, 55_000_000])
    np.testing.assert_allclose(x_from_transform(got[0]), [2.3, 0, 0, 2.3, 0, 0], atol=1e-9)
    np.testing.assert_allclose(x_from_transform(got[1]), [4, 0, 0, 4, 0, 0], atol=1e-9)
    np.testing.assert_allclose(x_from_transform(got[2]), [4, 0, 0, 4, 0, 0], atol=1e-9)  # held after the end


class _Accelerating(_Commander):
    """A scripted controller whose steps grow every cycle: the flange accelerates (and turns
    faster and faster)."""

    def _on_tick(self, t_ns, msg):
        k = self.k
        self.d_t_m = [2e-5 * k, -1e-5 * k, 0.0]
        self.d_r_rad = [0.0, 0.0, math.radians(0.02 * k)]
        return super()._on_tick(t_ns, msg)


def test_the_camera_renders_the_accelerating_robot_at_its_true_pose_at_the_image_stamp():
    """Every image's flange (sim_camera/truth) is the robot's truth interpolated at the
    image's stamp between the samples around it (to 1e-9 mm), and the image is published
    only once the robot's truth beyond the exposure exists: never an extrapolation."""
    from humanpt.geometry.transforms import interpolate_transform

    world = build_world("static", extra_cores=[_Accelerating([0, 0, 0], [0, 0, 0])])
    world.run_for(1.0)
    robot = world.truths("sim_robot/truth")
    stamps = np.array([t for t, _ in robot])
    steps = np.linalg.norm(np.diff([p["world_T_flange"][:3, 3] for _, p in robot], axis=0), axis=1)
    assert steps[-1] > steps[5] + 0.5  # it accelerates
    robot_known_at = {o.t_ns for o in world.outputs("sim_robot/truth")}
    images = world.outputs("camera/image")
    assert len(images) >= 29
    for o, (stamp, poses) in zip(images, world.truths("sim_camera/truth"), strict=True):
        i = int(np.searchsorted(stamps, stamp, side="left"))
        (t0, a), (t1, b) = robot[i - 1], robot[i]
        assert t0 < stamp <= t1 or stamp == 0
        want = b["world_T_flange"] if stamp == t1 else interpolate_transform(
            a["world_T_flange"], b["world_T_flange"], (stamp - t0) / (t1 - t0))
        np.testing.assert_allclose(poses["world_T_flange"][:3, 3], want[:3, 3], atol=1e-9)
        np.testing.assert_allclose(poses["world_T_flange"][:3, :3], want[:3, :3], atol=1e-12)
        assert o.t_ns >= t1 + 0 and max(t for t in robot_known_at if t <= o.t_ns) >= stamp + 500_000
