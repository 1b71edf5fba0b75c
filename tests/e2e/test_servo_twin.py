"""The closed loop on the lock-step twin (operator, stand-in robot, sim_camera, perception,
pose_filter, controller), judged against ground truth: issue 7's acceptance."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry.transforms import transform_from_x
from humanpt.operator import OperatorConfig
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, pose
from humanpt.twin.cal_tip import pivot_scenario
from humanpt.twin.system import build_system, path_points, tracking_errors

pytestmark = [pytest.mark.timeout(300), pytest.mark.twin]
OFFSET = (12.0, -9.0, 7.0, 2.0, -1.5, 2.5)  # the robot starts off the target: mm, deg


def _events(world, code=None):
    evs = [pb.Event.FromString(o.data) for o in world.outputs() if o.topic.endswith("/events")]
    return [e for e in evs if code is None or e.code == code]


def test_static_target_converges_and_holds():
    w = build_system("static", seed=2, start_offset_mm_deg=OFFSET)
    w.run_for(7.0)  # converges within 4 s, then holds for 3 s
    t, e_mm, e_deg = tracking_errors(w)
    assert e_mm[0] > 10.0  # it did start off target
    settled = t > t[0] + 4e9
    assert t[-1] - t[0] > 6.5e9  # ... and held
    assert e_mm[settled].max() < 0.5 and e_deg[settled].max() < 0.5, (e_mm[settled].max(), e_deg[settled].max())
    # The same against hand values rather than the controller's own flange_T_desired (which
    # the error above uses): D is on the camera's axis 600 mm ahead of the camera, which sits
    # at (0, 60, 100) mm on the flange with the flange's axes: (0, 60, 700) mm in the flange.
    # G is Table 1's pose.
    flange_T_d = transform_from_x(np.array([0.0, 60.0, 700.0, 0.0, 0.0, 0.0]))
    G = transform_from_x(np.array([236.132, 1248.772, 85.284, -2.598, -0.883, -4.535]))
    last = w.truths("sim_robot/truth")[-1][1]
    D = last["world_T_flange"] @ flange_T_d
    assert np.linalg.norm(G[:3, 3] - D[:3, 3]) < 0.5
    assert np.degrees(Rotation.from_matrix(G[:3, :3] @ D[:3, :3].T).magnitude()) < 0.5


def test_arc_is_tracked_and_the_recorded_radius_is_246_mm(tmp_path):
    w = build_system("arc", seed=3, controller=ControllerConfig(record_on_start=True), run_dir=tmp_path)
    w.run_for(10.0)  # 8 s of the arc (160 mm, 37 deg of it)
    w.close()
    t, e_mm, e_deg = tracking_errors(w)
    # The arc starts at 2 s with a step of the target's speed to 20 mm/s: while the servo
    # catches up G runs ahead of D, by the speed times the loop's latency - an image leaves
    # the camera once the robot's truth beyond it exists (up to one 28 ms cycle after its
    # capture: issue 16), so up to ~1.5 mm; from 3 s on the tracking is ten times tighter.
    assert e_mm.max() < 1.6 and e_deg.max() < 1.0, (e_mm.max(), e_deg.max())
    assert e_mm[t > 3_000_000_000].max() < 0.2, e_mm[t > 3_000_000_000].max()
    _, xg, _ = path_points(w)
    assert len(xg) > 30  # a point per 4 mm (200 ms at 20 mm/s) or 280 ms: 8 s give ~40
    radius = np.linalg.norm(xg[:, :2] - [147.5, 1378.5], axis=1)
    assert abs(radius.mean() - 246.0) < 1.0 and np.ptp(radius) < 1.0, (radius.mean(), np.ptp(radius))
    # The whole closed loop replays exactly, component by component.
    # At least a measurement (and a state) per image, 30 fps for 10 s; a command per 28 ms cycle.
    for comp, at_least in (("perception", 300), ("pose_filter", 300), ("controller", 357)):
        res = replay(tmp_path / f"{comp}.mcap")
        assert res.match and res.compared >= at_least, res.report()


def test_target_lost_holds_within_one_cycle():
    w = build_system("arc", seed=4)
    w.run_for(4.0)
    # Blind the camera: nothing passes the threshold any more.
    w.lockstep.set_param(w.now_ns, "perception", "threshold", "254")
    w.run_for(1.5)
    states = [pb.TobState.FromString(o.data) for o in w.outputs("pose_filter/tob_state")]
    cmds = [pb.FlangeCommand.FromString(o.data) for o in w.outputs("controller/command")]
    # One command per filter state (a cycle may be re-commanded after a new image).
    assert len(cmds) == len(states)
    first_lost = next(i for i, s in enumerate(states) if s.status == pb.TOB_STATUS_LOST and s.cycle > 100)
    assert cmds[first_lost - 1].mode == pb.CONTROL_MODE_TRACK
    assert len(cmds) - first_lost > 20
    for c in cmds[first_lost:]:
        assert c.mode == pb.CONTROL_MODE_LOST
        assert (c.d_translation_m.x, c.d_translation_m.y, c.d_translation_m.z) == (0, 0, 0)
    # The robot holds from the next cycle on (robot truths are one per cycle, from cycle 0).
    flanges = [r["world_T_flange"] for s, r in w.truths("sim_robot/truth")]
    still = flanges[states[first_lost].cycle + 1:]
    assert len(still) > 20
    assert max(np.abs(f - still[0]).max() for f in still) < 1e-9  # the robot holds


def test_an_outlier_measurement_is_gated():
    w = build_system("static", seed=5)
    w.run_for(4.0)
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.1, 0.5]  # far from where the target is
    t_bogus = w.now_ns + 1_000_000  # between two images
    bogus = pb.TobMeasurement(header=header(t_bogus, 0, "camera"), status=pb.TOB_STATUS_FULL,
                              camera_T_tob=pose(T), visible=3)
    w.lockstep.inject(t_bogus, "pose_filter", "perception/tob", bogus)
    w.run_for(2.0)
    assert len(_events(w, "outlier")) == 1
    t, e_mm, e_deg = tracking_errors(w)
    after = t > t[0] + 3.5e9
    assert e_mm[after].max() < 0.5 and e_deg[after].max() < 0.5


def test_playback_follows_the_recorded_path():
    ctl = ControllerConfig(record_on_start=True, recording_delay_cycles=3)
    w = build_system("arc", seed=6, controller=ctl)
    w.run_for(9.0)
    core = next(c for c in w.extra if isinstance(c, ControllerCore))
    cmd = pb.Command(header=header(w.now_ns), component="controller", verb="playback",
                     args_json=json.dumps({"speed_mm_s": 20.0}))
    w.lockstep.inject(w.now_ns, "controller", "console/command", cmd)
    n_robot = len(w.truths("sim_robot/truth"))
    assert w.run_until_event("playback_done", 25.0)  # ~140 mm at 20 mm/s after the approach
    _, xg, _ = path_points(w)
    path = np.array([transform_from_x(x)[:3, 3] for x in xg])
    tool = core.flange_T_tool.copy()
    tool[:3, 3] *= 1e3
    mode_of_cycle = {}
    for o in w.outputs("controller/status"):
        st = pb.ControllerStatus.FromString(o.data)
        mode_of_cycle[st.cycle] = st.mode
    tips = [r["world_T_flange"] @ tool for _, r in w.truths("sim_robot/truth")]
    # Only while following (after the approach to the first point).
    follow = [p[:3, 3] for k, p in enumerate(tips) if k >= n_robot and mode_of_cycle.get(k) == pb.CONTROL_MODE_PLAYBACK]
    # The robot first approaches the path's first point; judge it from there on.
    start = next(i for i, p in enumerate(follow) if np.linalg.norm(p - path[0]) < 0.3)
    follow = follow[start:]
    a, b = path[:-1], path[1:]
    ab = b - a
    d = []
    for p in follow:
        s = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        d.append(np.min(np.linalg.norm(a + s[:, None] * ab - p, axis=1)))
    assert len(d) > 100 and max(d) < 0.5, max(d)


PIVOT = pivot_scenario((3.0, -2.0, 62.0), angular_speed_deg_s=10.0)  # the twin's own pivot, faster


def test_driver_calibration_recovers_the_twins_tip():
    op = OperatorConfig(scenario_text=PIVOT, start_delay_s=1.0)
    w = build_system(op, seed=7, controller=ControllerConfig(has_driver=False,
                                                             calibration_samples=80))
    w.run_for(2.0)
    cmd = pb.Command(header=header(w.now_ns), component="controller", verb="calibrate",
                     args_json=json.dumps({"pivot_mm": [236.0, 1249.0, 0.0]}))
    w.lockstep.inject(w.now_ns, "controller", "console/command", cmd)
    # the operator pivots slowly (10 deg/s) through +-20 deg until 80 samples are taken
    assert w.run_until_event("calibration_done", 40.0), [e.code for e in _events(w)]
    done = _events(w, "calibration_done")
    assert done, [e.code for e in _events(w)]
    res = json.loads(done[0].text)
    err = np.linalg.norm(np.array(res["tob_t_tip_mm"]) - [3.0, -2.0, 62.0])
    # 0.11-0.13 mm over seeds 7-9: the controller fits the filter's pose at each image's
    # instant (a predicted pose lagged the pivoting target: 0.23-0.24 mm).
    assert err < 0.2, res
    assert np.linalg.norm(np.array(res["world_p_pivot_mm"]) - [236.0, 1249.0, 0.0]) < 0.3, res  # 0.25
    # The paper's method (eq. 10-13, P' given) too.
    assert np.linalg.norm(np.array(res["paper_tob_t_tip_mm"]) - [3.0, -2.0, 62.0]) < 0.1, res  # 0.015-0.021
    core = next(c for c in w.extra if isinstance(c, ControllerCore))
    assert core.config.has_driver and np.allclose(core.rig.tip.tob_t_tip_mm, res["tob_t_tip_mm"], atol=1e-3)
    assert core.rig.tip.calibration.method == "pivot"


def test_playback_ends_when_the_robot_lags_behind_the_carrot():
    # A sluggish arm (first-order lag of 150 ms) falls more than playback_max_lag_mm behind
    # the carrot on the way; the carrot then waits. With the path's feed-forward still on,
    # the arm settled v / K = 5 mm past the waiting carrot for ever (found by the
    # calibrate-then-teach demo in the realistic world); now the playback ends.
    ctl = ControllerConfig(record_on_start=True, recording_delay_cycles=3, playback_speed_mm_s=40.0)
    w = build_system("arc", seed=6, controller=ctl, robot_overrides={"standin_robot": {"lag_time_constant_ms": 150.0}})
    w.run_for(9.0)
    cmd = pb.Command(header=header(w.now_ns), component="controller", verb="playback",
                     args_json=json.dumps({"speed_mm_s": 40.0}))
    w.lockstep.inject(w.now_ns, "controller", "console/command", cmd)
    assert w.run_until_event("playback_done", 30.0)
    lag = [pb.ControllerStatus.FromString(o.data).error_translation_m for o in w.outputs("controller/status")]
    assert max(lag) > ctl.playback_max_lag_mm * 1e-3  # it did fall behind (the case under test)
    assert "playback_done" in [e.code for e in _events(w)]
