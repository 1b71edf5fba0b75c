"""The blob checks (issue 18, item 3): a partly covered or merged source is flagged and
rebuilt, excluded or kept; no flag in normal tracking, ideal or realistic optics; the
closed loop on the lock-step twin with a cover that starts during the motion.

Images come from the twin's renderer (its exact partial occlusion of a disc by a straight
edge); expected values from its ground truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanpt.geometry import TargetModel, invert_transform, transform_from_x, transform_points
from humanpt.operator import OperatorConfig
from humanpt.perception import PerceptionConfig, PerceptionCore
from humanpt.perception.checks import rebuild_point
from humanpt.perception.correspondence import FULL, POSITION_ONLY
from humanpt.perception.pipeline import Perception
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, image
from humanpt.sim_camera import Discs, SimCameraConfig
from humanpt.sim_camera.render import Renderer
from humanpt.testing.perception_eval import realistic_sim_config, standard_cases
from humanpt.twin.run import SystemConfig, run
from humanpt.twin.system import build_system, tracking_errors
from humanpt.twin.worlds import World

MODEL = TargetModel.isosceles()
# Poses near those of the built-in scenarios (G ~600 mm ahead, tilted a little; X: mm, then
# yaw, pitch, roll in deg)
POSES = [transform_from_x(np.array(x, dtype=float)) for x in (
    [4, -3, 600, 10, 3, -6], [-20, 12, 640, -25, -12, 8], [15, 20, 560, 60, 8, 14],
    [-8, -15, 620, 150, -5, -10],
)]


def _render(sim: SimCameraConfig, camera_T_tob: np.ndarray, frame: int = 0, extra=None) -> np.ndarray:
    r = Renderer(sim)
    discs = r.discs(camera_T_tob)
    if extra is not None:
        discs = Discs.concat([discs, extra])
    return r.expose(r.signal(r.blobs(discs)), frame)


def _covered(fraction: float, source: int, angle_deg: float) -> SimCameraConfig:
    return dataclasses.replace(SimCameraConfig(seed=5), occluded_sources=(source,),
                               occlusion_fraction=fraction, occlusion_angle_deg=angle_deg)


# --------------------------------------------------------------------------- images


@pytest.mark.parametrize("fraction", [0.1, 0.2, 0.3])
def test_a_covered_source_is_flagged_and_rebuilt_without_bias(fraction):
    rebuild = Perception(PerceptionConfig())
    keep = Perception(PerceptionConfig(degraded_policy="keep"))
    err_rebuilt, err_kept, err_uncovered = [], [], []
    for n, (camera_T_tob, source, angle) in enumerate(
        (T, s, a) for T in POSES for s in range(3) for a in (0.0, 100.0, 215.0)
    ):
        img = _render(_covered(fraction, source, angle), camera_T_tob, n)
        result = rebuild.measure(img)
        assert result.check is not None and result.check.degraded == (source,), result.check
        assert result.match.status == FULL
        assert f"{'ABC'[source]}:" in result.check.reason
        # the covered source is as dim as its uncovered part (the renderer's exact area)
        assert abs(result.check.brightness[source] - (1 - fraction)) < 0.02
        err_rebuilt.append(result.match.camera_T_tob[:3, 3] - camera_T_tob[:3, 3])
        kept = keep.measure(img)
        assert kept.check.degraded == (source,) and kept.match.status == FULL
        err_kept.append(kept.match.camera_T_tob[:3, 3] - camera_T_tob[:3, 3])
        uncovered = rebuild.measure(_render(SimCameraConfig(seed=5), camera_T_tob, n))
        assert not uncovered.check.degraded
        err_uncovered.append(uncovered.match.camera_T_tob[:3, 3] - camera_T_tob[:3, 3])
    # G: the bias the cover leaves (mean error against the uncovered images') is gone, and
    # each image's error stays at the centre noise's (~0.02 mm RMS); the measured pose
    # carries the cover's bias (~0.7 mm x the covered fraction: one source of three moved)
    bias = np.mean(err_rebuilt, axis=0) - np.mean(err_uncovered, axis=0)
    assert np.linalg.norm(bias) < 0.05, bias  # the acceptance; measured <= 0.015 (noise)
    rebuilt = np.linalg.norm(err_rebuilt, axis=1)
    assert rebuilt.max() < 0.1 and np.sqrt(np.mean(rebuilt**2)) < 0.04, rebuilt
    kept = np.linalg.norm(err_kept, axis=1)
    assert np.median(kept) > 0.5 * fraction, np.median(kept)


def test_a_merged_source_is_flagged():
    # a small reflection 2 mm beside source B in the TOB plane: one blob with B in both views
    camera_T_tob = POSES[0]
    sim = SimCameraConfig(seed=5)
    beside = transform_points(camera_T_tob, MODEL.source_positions_mm[1] + [2.0, 0.0, 0.0])
    axes = camera_T_tob[:3, :3] @ np.diag([1.0, 1.0, -1.0])
    spot = Discs.make(beside, axes, 1.0, 0.5 * sim.source_dn_per_ms, label=20)
    result = Perception(PerceptionConfig()).measure(_render(sim, camera_T_tob, extra=spot))
    assert result.check.degraded == (1,), result.check
    assert result.check.brightness[1] > 1.05
    assert "merged" in result.check.reason


def test_the_policies_exclude_and_keep():
    img = _render(_covered(0.3, 2, 40.0), POSES[1], 3)
    out = Perception(PerceptionConfig(degraded_policy="exclude")).measure(img)
    assert out.match.status == POSITION_ONLY and out.match.camera_T_tob is None
    assert out.paired.status == FULL  # what was found, before the policy
    # the remaining points are A and B (their pairs as found)
    np.testing.assert_array_equal(out.match.pairs, out.paired.pairs[:2])
    truth = transform_points(POSES[1], MODEL.source_positions_mm)
    assert np.abs(out.match.camera_p_mm - truth[:2]).max() < 0.3
    kept = Perception(PerceptionConfig(degraded_policy="keep")).measure(img)
    assert kept.match is kept.paired and kept.check.degraded == (2,)
    off = Perception(PerceptionConfig(check_blobs=False)).measure(img)
    assert off.check is None
    np.testing.assert_array_equal(off.match.camera_T_tob, kept.match.camera_T_tob)


def test_rebuild_point_takes_only_the_angle_about_the_other_two():
    # hand check: the true triangle; C moved within the TOB plane (a straight cover) comes
    # back exactly; moved out of it, the rebuilt C stays at the model's distances
    T = POSES[2]
    true = transform_points(T, MODEL.source_positions_mm)
    in_plane = T[:3, :3] @ np.array([0.6, -0.4, 0.0])
    measured = true.copy()
    measured[2] += in_plane
    np.testing.assert_allclose(rebuild_point(measured, 2, MODEL), true[2], atol=1e-9)
    measured[2] += T[:3, :3] @ np.array([0.0, 0.0, 0.5])
    c = rebuild_point(measured, 2, MODEL)
    ab, bc, ca = MODEL.sides_mm
    assert abs(np.linalg.norm(c - true[1]) - bc) < 1e-9 and abs(np.linalg.norm(c - true[0]) - ca) < 1e-9


def test_no_flag_on_the_scenarios_poses_ideal_or_realistic_optics_either_method():
    # the poses of the built-in scenarios as a tracking camera sees them (15 each):
    # the ideal world and the realistic one's optics and sensor (fall-off, blooming, ghost,
    # 2005-era noise, fixed pattern, distortion, focal, splitter, mirror tilt)
    cases = standard_cases(15, seed=2)
    for sim in (SimCameraConfig(seed=2), realistic_sim_config(2)):
        r = Renderer(sim)
        perceptions = [Perception(PerceptionConfig(method=m)) for m in ("weighted", "paper")]
        checked = 0
        for case in cases:
            img = r.expose(r.signal(r.blobs(r.discs(case.camera_T_tob, case.world_T_camera))),
                           case.frame_index)
            for p in perceptions:
                result = p.measure(img)
                if result.check is not None:
                    checked += 1
                    assert not result.check.degraded, (case.name, p.config.method, result.check.reason)
        assert checked >= 0.95 * 2 * len(cases)


def test_the_paper_method_flags_a_30_percent_cover():
    paper = Perception(PerceptionConfig(method="paper"))
    for n, T in enumerate(POSES):
        result = paper.measure(_render(_covered(0.3, n % 3, 70.0 * n), T, n))
        assert result.check.degraded == (n % 3,), result.check


# --------------------------------------------------------------------------- core


def test_the_core_reports_degraded_and_one_event_per_episode():
    core = PerceptionCore(PerceptionConfig(degraded_clear_frames=3))
    clean = _render(SimCameraConfig(seed=5), POSES[0], 0)
    covered = _render(_covered(0.3, 0, 0.0), POSES[0], 0)
    frames = [clean, covered, covered, covered, clean, covered, clean, clean, clean, clean]
    tobs, events = [], []
    for k, img in enumerate(frames):
        for topic, msg in core.step(k, "camera/image", image(img, k)):
            (tobs if topic == "perception/tob" else events).append(msg)
    assert [m.degraded for m in tobs] == [f is covered for f in frames]
    m = tobs[1]
    assert list(m.degraded_sources) == [0] and m.degraded_reason.startswith("A:")
    assert m.status == pb.TOB_STATUS_FULL and len(m.source_brightness) == 3
    assert abs(m.source_brightness[0] - 0.7) < 0.02
    assert len(tobs[0].source_brightness) == 3 and not tobs[0].degraded_sources
    codes = [(e.code, e.header.stamp_ns) for e in events if e.code.startswith("source_")]
    # the clean frame at 4 is not enough (3 needed): one episode from 1 to the third clean
    # frame after 5
    assert codes == [("source_degraded", 1), ("source_ok", 8)], codes
    (warning,) = [e for e in events if e.code == "source_degraded"]
    assert warning.severity == pb.SEVERITY_WARNING and "rebuilt" in warning.text


def test_bad_check_parameters_are_rejected():
    core = PerceptionCore(PerceptionConfig())
    for key, value in (("degraded_policy", '"ignore"'), ("degraded_flux_tol", "1.5"),
                       ("degraded_noise_k", "-1"), ("degraded_paper_factor", "0.5")):
        outs = core.step(1, "param", pb.ParamSet(component="perception", key=key, value_json=value))
        assert [m.code for _, m in outs] == ["param_rejected"], (key, outs)
    outs = core.step(2, "param", pb.ParamSet(component="perception", key="degraded_policy",
                                              value_json='"exclude"'))
    assert [m.code for _, m in outs] == ["param_changed"]
    assert core.perception.config.degraded_policy == "exclude"
    with pytest.raises(ValueError):
        PerceptionConfig(degraded_clear_frames=0)


# --------------------------------------------------------------------------- closed loop


def _full_measurements(w):
    """Each perception/tob measurement of a lock-step run (each must be FULL) with the
    error (3,) mm of its G against the truth of its image (camera frame)."""
    truths = dict(w.truths("sim_camera/truth"))
    flange_T_camera = w.camera.config.flange_T_camera
    for out in w.outputs("perception/tob"):
        m = pb.TobMeasurement.FromString(out.data)
        p = truths[m.header.stamp_ns]
        camera_T_tob = invert_transform(p["world_T_flange"] @ flange_T_camera) @ p["world_T_tob"]
        assert m.status == pb.TOB_STATUS_FULL
        yield m, from_pose(m.camera_T_tob)[:3, 3] * 1000.0 - camera_T_tob[:3, 3]


def _arc_run(cover_from_s: float | None, fraction: float = 0.3):
    """The arc scenario (moving from 2 s on), closed loop, 6 s; source A ``fraction``
    covered from ``cover_from_s``. Per image: (stamp s, degraded, |G error| mm, G error)."""
    w = build_system("arc", seed=3)
    if cover_from_s is not None:
        t = round(cover_from_s * 1e9)
        w.lockstep.set_param(t, "sim_camera", "occlusion_fraction", str(fraction))
        w.lockstep.set_param(t, "sim_camera", "occlusion_angle_deg", "30")
        w.lockstep.set_param(t, "sim_camera", "occluded_sources", "[0]")
    w.run_for(6.0)
    rows = [(m.header.stamp_ns / 1e9, m.degraded, *err) for m, err in _full_measurements(w)]
    events = [pb.Event.FromString(o.data) for o in w.outputs("perception/events")]
    return np.array(rows), events, tracking_errors(w)


@pytest.mark.timeout(120)
def test_closed_loop_a_30_percent_cover_during_the_motion_is_flagged_at_once_without_bias():
    cover_s = 3.0
    base, base_events, _ = _arc_run(None)
    rows, events, (t_ns, servo_mm, _) = _arc_run(cover_s)
    assert not base[:, 1].any() and not any(e.code == "source_degraded" for e in base_events)
    before, after = rows[rows[:, 0] < cover_s], rows[rows[:, 0] >= cover_s]
    assert not before[:, 1].any()
    # flagged within 3 frames of the cover starting, and on every frame after that
    first = int(np.argmax(after[:, 1]))
    assert after[:, 1].any() and first < 3 and after[first:, 1].all(), first
    assert [e.code for e in events].count("source_degraded") == 1
    # the bias it leaves: mean G error (vs the truth) while covered, against the uncovered
    # run's over the same time; every single image within the uncovered run's worst
    bias = after[:, 2:].mean(axis=0) - base[base[:, 0] >= cover_s, 2:].mean(axis=0)
    assert np.linalg.norm(bias) < 0.05, bias
    worst_base = np.linalg.norm(base[:, 2:], axis=1).max()
    assert np.linalg.norm(after[:, 2:], axis=1).max() < max(1.2 * worst_base, 0.1)
    # and the servo keeps the target as tightly as without the cover (issue 7: < 0.2 mm)
    assert servo_mm[t_ns >= cover_s * 1e9].max() < 0.2


@pytest.mark.timeout(120)
@pytest.mark.parametrize("speed_mm_s", [20.0, 60.0])
def test_closed_loop_the_partial_scenario_is_flagged_within_3_frames_and_left_unbiased(speed_mm_s):
    # issue 18's acceptance: source A 30 % covered from 1 s into the motion (the operator's
    # truth says which images: sim_camera renders its cover_fraction)
    w = build_system(OperatorConfig(scenario="partial", speed_mm_s=speed_mm_s), seed=1)
    w.run_for(7.5)  # the motion from 2 s, the cover from 3 s: 90 images before it, 135 under it
    covered = {}
    for out in w.outputs("sim_camera/truth"):
        truth = pb.Truth.FromString(out.data)
        covered[truth.header.stamp_ns] = bool(truth.cover_fraction) and truth.cover_fraction[0] > 0
    rows = [(covered[m.header.stamp_ns], m.degraded, list(m.degraded_sources) == [0], *err)
            for m, err in _full_measurements(w)]
    rows = np.array(rows, dtype=float)
    cov = rows[:, 0] > 0
    assert cov.sum() > 100 and (~cov).sum() > 30  # covered for the last 4.5 s
    assert not rows[~cov, 1].any()  # no flag before the cover
    first_covered = int(np.argmax(cov))
    flags = rows[first_covered:, 1]
    assert flags[:3].any() and flags[int(np.argmax(flags)):].all()  # within 3 frames, then every frame
    assert rows[cov & (rows[:, 1] > 0), 2].all()  # A, and only A
    err = rows[:, 3:]
    bias = err[cov].mean(axis=0) - err[~cov].mean(axis=0)
    assert np.linalg.norm(bias) < 0.05, bias  # measured: < 0.01
    assert np.linalg.norm(err[cov], axis=1).max() < 0.1
    events = [pb.Event.FromString(o.data) for o in w.outputs("perception/events")]
    assert [e.code for e in events].count("source_degraded") == 1


@pytest.mark.timeout(120)
def test_closed_loop_realistic_world_no_flag_on_quick_torch_turns():
    # the realistic world (every error source, motion blur over a 4 ms exposure included) on
    # issue 18's abrupt scenario: instant starts, stops, speed changes and quick torch turns
    config = SystemConfig.for_scenario("abrupt", seed=4, world=World.realistic())
    result = run(config, duration_s=10.0)
    tobs = [pb.TobMeasurement.FromString(o.data) for o in result.world.outputs("perception/tob")]
    checked = [m for m in tobs if len(m.source_brightness) == 3]
    assert len(checked) > 250  # FULL at 30 fps
    assert not any(m.degraded for m in tobs), [m.degraded_reason for m in tobs if m.degraded][:3]
    events = [pb.Event.FromString(o.data) for o in result.world.outputs("perception/events")]
    assert not any(e.code == "source_degraded" for e in events)


@pytest.mark.timeout(120)
def test_closed_loop_timed_10_and_20_percent_covers_start_and_end_events():
    # the scenario keyword `cover`: C 10 % covered from 1 s to 2.5 s into the motion, B 20 %
    # from 3 s to 4 s; each flagged within 3 frames of its start, cleared after its end
    text = """scenario covers
driver 0 0 60
path tip
start 186.132 1248.772 0 0 15 180
line 286.132 1248.772 0
dwell 1
cover C 0.1 from 1 to 2.5 angle 200
cover B 0.2 from 3 to 4 angle 45
"""
    w = build_system(OperatorConfig(scenario_text=text), seed=2)
    w.run_for(7.5)  # the motion from 2 s: the covers from 3 to 4.5 s and 5 to 6 s
    cover = {}
    for out in w.outputs("sim_camera/truth"):
        truth = pb.Truth.FromString(out.data)
        cover[truth.header.stamp_ns] = tuple(truth.cover_fraction) or (0.0, 0.0, 0.0)
    tobs = [pb.TobMeasurement.FromString(o.data) for o in w.outputs("perception/tob")]
    covered = [next((k for k in range(3) if cover[m.header.stamp_ns][k] > 0), None) for m in tobs]
    flagged = [tuple(m.degraded_sources) for m in tobs]
    assert all(m.status == pb.TOB_STATUS_FULL for m in tobs)
    for source in (2, 1):
        frames = [i for i, c in enumerate(covered) if c == source]
        assert len(frames) > 25
        first = next(i for i in frames if flagged[i])
        assert first - frames[0] < 3 and all(flagged[i] == (source,) for i in frames[first - frames[0]:])
    # nothing else flagged: not before, between or after the covers
    assert all(not flagged[i] for i, c in enumerate(covered) if c is None)
    events = [pb.Event.FromString(o.data) for o in w.outputs("perception/events")]
    codes = [e.code for e in events if e.code.startswith("source_")]
    assert codes == ["source_degraded", "source_ok", "source_degraded", "source_ok"], codes
    texts = [e.text for e in events if e.code == "source_degraded"]
    assert "source(s) C " in texts[0] and "source(s) B " in texts[1]
