"""Issue 18.2 and 18.4 on the lock-step twin, judged against ground truth: the path keeps
recording while a source is hidden (position measured, orientation held and flagged, the
filter's covariance on every point, through the CSV and the viewer), and a quick torch
turn at the speed limits keeps G in view."""

from __future__ import annotations

import collections

import numpy as np
import pytest
import rerun as rr
import rerun.chunk as rrc

from humanpt.controller import pathfile
from humanpt.controller.config import ControllerConfig
from humanpt.controller.servo_report import servo_summary
from humanpt.controller.shell import PathWriter
from humanpt.geometry.transforms import x_from_transform
from humanpt.operator import OperatorConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.twin import evaluate
from humanpt.twin.system import build_system, tracking_errors
from humanpt.viz.config import VizConfig
from humanpt.viz.logger import ENTITIES, RerunLogger

pytestmark = [pytest.mark.timeout(120), pytest.mark.twin]
FRAME_NS = 1e9 / 30  # the camera's frame period

@pytest.fixture(scope="module")
def hidden_source():
    """The built-in ``occluded`` seam at 60 mm/s (from 1 s): source B fully covered from 2 s
    to 4 s into the motion (3 s to 5 s here); the path (G and the needle's tip) recorded
    every cycle from the start."""
    op = OperatorConfig(scenario="occluded", speed_mm_s=60.0, start_delay_s=1.0)
    w = build_system(op, seed=3, digest=False,
                     controller=ControllerConfig(record_on_start=True, recording_delay_cycles=1))
    w.run_until(8_000_000_000)
    w.close()
    return w, [pb.PathPoint.FromString(o.data) for o in w.outputs("controller/path")]


def test_the_path_goes_on_with_flagged_orientation_while_a_source_is_hidden(hidden_source):
    w, pts = hidden_source
    stamps = np.array([p.header.stamp_ns for p in pts])
    held = np.array([p.orientation_held for p in pts])
    # The filter saw two sources (position only) for the 2 s; the path has them all, held.
    t_held = stamps[held]
    assert t_held.min() < 3.1e9 and t_held.max() > 4.9e9, (t_held.min(), t_held.max())
    assert not held[stamps < 3.0e9].any() and not held[stamps > 5.2e9].any()
    # No gap longer than two camera frames anywhere (a point per image here).
    assert np.diff(stamps).max() <= 2 * FRAME_NS + 1, np.diff(stamps).max()
    # Positions against ground truth while the target moved, held points included: G's, and
    # the tip's (which the held orientation places, 60 mm from G).
    start = evaluate.scenario_start_ns(w)
    _, xg, xt = evaluate.path_points(w)
    moving = stamps >= start
    for x, field in ((xg, "world_T_tob"), (xt, "world_T_tip")):
        truth = np.array([T[:3, 3] for T in evaluate.truth_at(w, stamps[moving], field=field)])
        err = np.abs(x[moving, :3] - truth).max()
        assert err < 0.5, (field, err)
        if field == "world_T_tip":
            # While the orientation is not measured the filter holds it (pose_filter
            # kalman.hold_orientation): the tip, 60 mm from G, stays within 0.2 mm of the
            # truth over the 2 s (0.06-0.09 mm on seeds 3-5). Before, it turned on at the
            # angular rate it had estimated from noise (0.35 deg/s here): 0.24-0.75 mm.
            held_err = np.abs(x[moving & held, :3] - truth[held[moving]]).max()
            assert held_err < 0.2, held_err
    # Held orientations, interpolated as playback and the VAL export take them, are close to
    # the truth (the seam keeps its orientation).
    filled = pathfile.fill_held_orientation(xg, held, stamps)
    truth = np.array([x_from_transform(T) for T in evaluate.truth_at(w, stamps)])
    assert np.abs(evaluate.wrap_deg(filled[held, 3:] - truth[held, 3:])).max() < 0.2
    # Every point carries the filter's covariance; while held, the orientation's grows, and
    # with it the tip's (the orientation's lever).
    assert all(len(p.position_covariance_m2) == 9 and len(p.rotation_covariance_rad2) == 9
               and len(p.tip_position_covariance_m2) == 9 for p in pts)

    def sd(values, scale):
        return np.array([scale * np.sqrt(np.max(np.diag(np.reshape(v, (3, 3))))) for v in values])

    sd_deg = sd([p.rotation_covariance_rad2 for p in pts], np.degrees(1.0))
    sd_tip = sd([p.tip_position_covariance_m2 for p in pts], 1e3)
    measured = (~held) & (stamps > 1.5e9) & (stamps < 3.0e9)
    assert sd_deg[held].max() > 5 * sd_deg[measured].max(), (sd_deg[held].max(), sd_deg[measured].max())
    assert sd_tip[held].max() > 3 * sd_tip[measured].max(), (sd_tip[held].max(), sd_tip[measured].max())


def test_the_path_file_keeps_the_flags_and_covariance(hidden_source, tmp_path):
    _, pts = hidden_source
    writer = PathWriter(tmp_path)  # the live shell's adapter, as it writes during a run
    writer.start(lambda *_: None)
    for p in pts:
        writer.write("controller/path", p)
    writer.close()
    got = pathfile.read(tmp_path / "path-1.csv")
    assert len(got) == len(pts) and got.x_tip is not None
    np.testing.assert_array_equal(got.orientation_held, [p.orientation_held for p in pts])
    cov_g = np.array([np.reshape(p.position_covariance_m2, (3, 3)) for p in pts]) * 1e6
    cov_r = np.array([np.reshape(p.rotation_covariance_rad2, (3, 3)) for p in pts]) * np.degrees(1.0) ** 2
    np.testing.assert_allclose(got.cov_g_mm2, cov_g, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(got.cov_r_deg2, cov_r, rtol=1e-5, atol=1e-12)
    cov_tip = np.array([np.reshape(p.tip_position_covariance_m2, (3, 3)) for p in pts]) * 1e6
    np.testing.assert_allclose(got.cov_tip_mm2, cov_tip, rtol=1e-5, atol=1e-12)
    # Written back and read again: the same; and so is what a lock-step run writes
    # (RunResult.write_path: pathfile.from_path_points).
    pathfile.write(tmp_path / "again.csv", got)
    pathfile.write(tmp_path / "lockstep.csv", pathfile.from_path_points(pts))
    for name in ("again.csv", "lockstep.csv"):
        again = pathfile.read(tmp_path / name)
        assert (tmp_path / name).read_text().splitlines()[0] == (tmp_path / "path-1.csv").read_text().splitlines()[0]
        np.testing.assert_array_equal(again.orientation_held, got.orientation_held)
        np.testing.assert_allclose(again.cov_r_deg2, got.cov_r_deg2, rtol=1e-5)
        np.testing.assert_allclose(again.cov_tip_mm2, got.cov_tip_mm2, rtol=1e-5)
        np.testing.assert_allclose(again.x_tip, got.x_tip, atol=1e-6)


def test_the_viewer_draws_the_uncertainty_and_the_held_points(hidden_source, tmp_path):
    _, pts = hidden_source
    out = tmp_path / "path.rrd"
    rec = rr.RecordingStream("humanpt_test")
    rec.save(out)
    cfg = VizConfig(path_sigmas=3.0, path_sigma_magnify=10.0)
    lg = RerunLogger(rec, cfg)
    for p in pts:
        lg.log("controller/path", p, p.header.stamp_ns)
    rec.flush()
    rec.disconnect()
    assert not lg.errors
    rows: dict[str, int] = collections.Counter()
    last: dict[str, object] = {}
    for chunk in rrc.RrdReader(out).stream().to_chunks():
        rows[chunk.entity_path] += chunk.num_rows
        rb = chunk.to_record_batch()
        for name in rb.schema.names:
            if name.endswith("Ellipsoids3D:half_sizes") or name.endswith("Points3D:positions"):
                last[chunk.entity_path] = rb.column(rb.schema.names.index(name)).to_pylist()[-1]
    n, held = len(pts), sum(p.orientation_held for p in pts)
    strip = cfg.path_strip_points
    sigma = [e for e in rows if e.startswith(f"/{ENTITIES['path']}/1/sigma/")]
    assert sum(rows[e] for e in sigma) == n  # one ellipsoid strip update per point
    assert len(last[f"/{ENTITIES['path']}/1/sigma/0"]) == min(n, strip)
    # The last ellipsoid's half axes: 3 sd, magnified 10 times (sorted, metres).
    C = np.reshape(pts[-1].tip_position_covariance_m2, (3, 3))  # the tip's: it is what the path records
    k = (n - 1) // strip
    drawn = np.sort(np.asarray(last[f"/{ENTITIES['path']}/1/sigma/{k}"][-1]))
    np.testing.assert_allclose(drawn, 30.0 * np.sqrt(np.linalg.eigvalsh(C)), rtol=1e-5)
    held_rows = sum(rows[e] for e in rows if e.startswith(f"/{ENTITIES['path']}/1/held/"))
    assert held_rows == held > 0
    assert rows[f"/{ENTITIES['path_sd_mm']}"] == n and rows[f"/{ENTITIES['path_held']}"] == n


TURN = """scenario turn
driver 0 0 60
path tip
start 10.907 1226.272 0 0 15 180
speed 60
angular_speed 60
line 70.907 1226.272 0 90 15 180
line 130.907 1226.272 0
line 130.907 1286.272 0 0 15 180
dwell 1
"""


def _turn(saturation: str):
    w = build_system(OperatorConfig(scenario_text=TURN, start_delay_s=1.0), seed=1, digest=False,
                     controller=ControllerConfig(saturation=saturation))
    w.run_for(6.5)
    return w


@pytest.fixture(scope="module")
def turns():
    return {s: _turn(s) for s in ("position_first", "scale")}


def test_a_quick_torch_turn_keeps_g_in_view_and_the_limits(turns):
    """The torch turns 90 deg at 60 deg/s while moving at 60 mm/s: the flange, 700 mm from
    D, would have to swing at up to ~200 mm/s. Scaling the whole step (the old law) let G
    fall 120 mm behind D, 190 px off in the image; position_first keeps G near D (11 mm,
    18 px) and lets the orientation lag (19 deg)."""
    res = {}
    for s, w in turns.items():
        t, e_mm, e_deg = tracking_errors(w)  # the truth: the target against D
        rep = servo_summary(w, after_ns=evaluate.scenario_start_ns(w))
        res[s] = (e_mm.max(), e_deg.max(), rep)
        # Every command, saturated or not, within the robot's limits (per 28 ms cycle).
        cmds = [pb.FlangeCommand.FromString(o.data) for o in w.outputs("controller/command")]
        d_t = np.array([[c.d_translation_m.x, c.d_translation_m.y, c.d_translation_m.z] for c in cmds])
        d_r = np.array([[c.d_rotation_rad.x, c.d_rotation_rad.y, c.d_rotation_rad.z] for c in cmds])
        assert np.linalg.norm(d_t, axis=1).max() <= 0.1 * 0.028 * (1 + 1e-9)
        assert np.linalg.norm(d_r, axis=1).max() <= np.radians(60.0) * 0.028 * (1 + 1e-9)
        # The target stayed tracked (never lost).
        states = [pb.TobState.FromString(o.data) for o in w.outputs("pose_filter/tob_state")]
        assert all(st.status == pb.TOB_STATUS_FULL for st in states[10:])
    e_mm, e_deg, rep = res["position_first"]
    old_mm, _, old = res["scale"]
    assert old_mm > 50.0 and old.min_fov_margin_px < 100.0  # the case under test: the old law fell behind
    assert rep.saturated_cycles > 30 and rep.lagging_cycles > 30  # the limits did bind
    # G stays near D (position_first engages 10 mm off: position_first_beyond_mm); the
    # orientation lags, boundedly.
    assert e_mm < 15.0 and e_deg < 25.0, (e_mm, e_deg)
    assert rep.max_image_error_px < 30.0 < old.max_image_error_px
    assert rep.min_fov_margin_px > 150.0 and rep.min_fov_margin_px > old.min_fov_margin_px + 100.0


@pytest.mark.parametrize("scenario", ["scurve", "abrupt"])
def test_the_hard_scenarios_at_60_mm_s_keep_g_near_the_image_centre(scenario):
    """The built-in hard cases at 60 mm/s (issue 18): the old law let G fall 145 mm
    (scurve) and 45 mm (abrupt) behind D, 240 and 70 px off in the image. Stated bounds:
    G within 15 mm of D (position_first engages at 10), 30 px in the image, the sources at
    least 150 px inside it."""
    from humanpt.twin.run import scenario_duration_s

    op = OperatorConfig(scenario=scenario, speed_mm_s=60.0, start_delay_s=1.0)
    w = build_system(op, seed=0, digest=False)
    w.run_for(op.start_delay_s + scenario_duration_s(op) + 0.5)
    start = evaluate.scenario_start_ns(w)
    t, e_mm, _ = tracking_errors(w)
    rep = servo_summary(w, after_ns=start)
    assert e_mm[t >= start].max() < 15.0, e_mm[t >= start].max()
    assert rep.max_image_error_px < 30.0 and rep.min_fov_margin_px > 150.0, rep.line()
    assert rep.lagging_cycles > 10, rep.line()  # the limits did bind: the orientation lagged


def test_the_reported_field_of_view_margin_is_the_true_one(turns):
    """Each status's margin (the controller's estimate: its predicted flange, the filter's
    target) against the one the truth gives: the robot's true flange in that cycle, the
    operator's target at the status's stamp, the ideal world's camera."""
    from humanpt.controller import law
    from humanpt.geometry.rig import Rig

    w = turns["position_first"]
    rig = Rig()
    sources = np.asarray(rig.target_model().source_positions_mm)
    flange = {round(stamp / 28e6): p["world_T_flange"] for stamp, p in w.truths("sim_robot/truth")}
    statuses = [st for st in (pb.ControllerStatus.FromString(o.data) for o in w.outputs("controller/status"))
                if st.visible and st.cycle in flange]
    targets = evaluate.truth_at(w, [st.header.stamp_ns for st in statuses])
    d = [st.fov_margin_px - law.fov_margin_px(
        rig.params(), np.linalg.inv(flange[st.cycle] @ w.camera.config.flange_T_camera) @ G, sources)
         for st, G in zip(statuses, targets, strict=True)]
    assert len(d) > 300 and np.median(np.abs(d)) < 0.2 and np.abs(d).max() < 5.0, (np.median(np.abs(d)), max(d))


def test_position_first_changes_nothing_within_the_limits():
    """The arc (20 mm/s, 4.7 deg/s) never needs more than the limits: both settings command
    the same steps, bit for bit."""
    cmds = {}
    for s in ("position_first", "scale"):
        w = build_system("arc", seed=2, digest=False, controller=ControllerConfig(saturation=s))
        w.run_for(4.0)
        cmds[s] = [o.data for o in w.outputs("controller/command")]
        statuses = [pb.ControllerStatus.FromString(o.data) for o in w.outputs("controller/status")]
        assert not any(st.saturated for st in statuses[40:])
    assert cmds["position_first"] == cmds["scale"]


def test_a_param_switches_the_saturation_live():
    # A world of its own: the module's ``turns`` are read by other tests, unchanged.
    w = build_system("arc", seed=2, digest=False, controller=ControllerConfig(saturation="position_first"))
    w.run_for(1.0)
    w.lockstep.set_param(w.now_ns, "controller", "saturation", '"scale"')
    w.run_for(0.1)
    ev = [pb.Event.FromString(o.data) for o in w.outputs("controller/events")]
    assert any(e.code == "param_changed" and "saturation" in e.text for e in ev), [e.code for e in ev]
