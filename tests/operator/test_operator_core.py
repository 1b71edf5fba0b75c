"""The operator core: truth at a fixed rate, start delay, live pace, done event."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry import x_from_transform
from humanpt.operator import TABLE1_X_MM_DEG, OperatorConfig, OperatorCore, Trajectory
from humanpt.runtime.lockstep import Lockstep
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose


def _truths(ls: Lockstep) -> list[pb.Truth]:
    return [pb.Truth.FromString(o.data) for o in ls.outputs if o.topic == "operator/truth"]


def _mm(p: pb.Pose) -> np.ndarray:
    t = from_pose(p)
    t[:3, 3] *= 1000.0
    return t


def test_static_truth_at_the_configured_rate():
    ls = Lockstep([OperatorCore(OperatorConfig(rate_hz=50.0))])
    ls.run_until(2_500_000_000)
    truths = _truths(ls)
    assert len(truths) == 126
    assert {t.header.frame_id for t in truths} == {"world"}
    stamps = [t.header.stamp_ns for t in truths]
    assert set(np.diff(stamps)) == {20_000_000}
    assert [t.header.seq for t in truths] == list(range(126))
    np.testing.assert_allclose(
        x_from_transform(_mm(truths[-1].world_T_tob)), TABLE1_X_MM_DEG, atol=1e-6
    )
    assert not truths[-1].has_tip
    events = [
        (o.t_ns, pb.Event.FromString(o.data).code)
        for o in ls.outputs
        if o.topic == "operator/events"
    ]
    assert events == [
        (2_000_000_000, "scenario_started"),  # when the target starts to move: after the delay
        (2_000_000_000, "scenario_done"),  # (a still scenario is done at once)
    ]


def test_moves_after_the_start_delay_at_the_live_pace_and_says_when_done():
    cfg = OperatorConfig(scenario="trapezium", start_delay_s=0.5, speed_mm_s=100.0)
    ls = Lockstep([OperatorCore(cfg)])
    ls.set_param(1_500_000_000, "operator", "speed_scale", "2.0")
    ls.run_until(12_000_000_000)
    truths = _truths(ls)
    assert len(truths) == 1201 and all(t.has_tip for t in truths)  # 100 Hz for 12 s
    tips = np.array([_mm(t.world_T_tip)[:3, 3] for t in truths])
    stamps = np.array([t.header.stamp_ns for t in truths]) / 1e9
    assert np.sum(stamps <= 0.5) == 51  # 0 ... 0.5 s
    assert np.allclose(tips[stamps <= 0.5], tips[0])  # holding still during the delay
    started = [o.t_ns for o in ls.outputs if o.topic == "operator/events"
               and pb.Event.FromString(o.data).code == "scenario_started"]
    assert started == [500_000_000]  # said when the motion starts, not at the first tick
    speed = np.linalg.norm(np.diff(tips, axis=0), axis=1) / np.diff(stamps)
    mid = (stamps[1:] > 0.6) & (stamps[1:] < 1.4)
    fast = (stamps[1:] > 1.6) & (stamps[1:] < 2.5)
    assert np.median(speed[mid]) == pytest.approx(100.0, rel=0.01)
    assert np.median(speed[fast]) == pytest.approx(200.0, rel=0.01)
    duration = Trajectory(cfg.build_scenario()).duration_s  # at pace 1
    done = [
        o
        for o in ls.outputs
        if o.topic == "operator/events" and pb.Event.FromString(o.data).code == "scenario_done"
    ]
    assert len(done) == 1
    expected_done_s = 0.5 + 1.0 + (duration - 1.0) / 2.0  # 1 s at pace 1, the rest at pace 2
    assert done[0].t_ns / 1e9 == pytest.approx(expected_done_s, abs=0.011)
    assert np.sum(stamps > expected_done_s + 0.02) > 50
    assert np.allclose(tips[stamps > expected_done_s + 0.02], tips[-1])  # holds at the end


def _tremor_offsets(cfg: OperatorConfig, seconds: float = 20.0):
    """(translation mm (N, 3), rotation deg (N, 3)) of the truth against the intended path
    (the scenario's own, without the operator's tremor)."""
    ls = Lockstep([OperatorCore(cfg)])
    ls.run_until(round(seconds * 1e9))
    intended = Trajectory(cfg.build_scenario())
    d_t, d_r = [], []
    for t in _truths(ls):
        elapsed_s = t.header.stamp_ns / 1e9
        scen_t = max(elapsed_s - cfg.start_delay_s, 0.0)
        want, _ = intended.pose(scen_t, tremor_t_s=elapsed_s)
        got = _mm(t.world_T_tob)
        d_t.append(got[:3, 3] - want[:3, 3])
        d_r.append(np.degrees(Rotation.from_matrix(got[:3, :3] @ want[:3, :3].T).as_rotvec()))
    return np.array(d_t), np.array(d_r)


def test_hand_tremor_on_any_scenario_has_the_configured_rms_and_is_seeded():
    """0.2 mm and 0.25 deg RMS per axis on the static target (which has no tremor of its
    own): the truth's offsets from the intended pose have those RMS values (within 15 %:
    20 s of a sum of sines, the slow drift's periods reach 5 s), and most of the power is
    at 8-12 Hz (physiological tremor) besides the drift; off by default."""
    off_t, off_r = _tremor_offsets(OperatorConfig(rate_hz=400.0))
    assert np.abs(off_t).max() < 1e-9 and np.abs(off_r).max() < 1e-9
    cfg = OperatorConfig(rate_hz=400.0, tremor_mm=0.2, tremor_deg=0.25, seed=4)
    d_t, d_r = _tremor_offsets(cfg)
    np.testing.assert_allclose(np.sqrt(np.mean(d_t**2, axis=0)), 0.2, rtol=0.15)
    np.testing.assert_allclose(np.sqrt(np.mean(d_r**2, axis=0)), 0.25, rtol=0.15)
    spectrum = np.abs(np.fft.rfft(d_t[:, 0] - d_t[:, 0].mean())) ** 2
    freqs = np.fft.rfftfreq(len(d_t), 1 / 400.0)
    tremor_band = spectrum[(freqs >= 8) & (freqs <= 12)].sum()
    drift_band = spectrum[freqs <= 1.5].sum()
    assert (tremor_band + drift_band) / spectrum.sum() > 0.95 and tremor_band > 0.1 * spectrum.sum()
    again, _ = _tremor_offsets(cfg)
    np.testing.assert_array_equal(again, d_t)  # seeded
    other, _ = _tremor_offsets(OperatorConfig(rate_hz=400.0, tremor_mm=0.2, tremor_deg=0.25, seed=5))
    assert np.abs(other - d_t).max() > 0.05


def test_hand_tremor_adds_to_a_scenario_tremor_without_repeating_it():
    """freehand has its own 0.2 mm tremor from the same seed: the operator's is another
    waveform (its own stream), so the two add in power: RMS ~ sqrt(0.2^2 + 0.2^2)."""
    base = OperatorConfig(scenario="freehand", rate_hz=400.0, seed=2)
    with_hand = OperatorConfig(scenario="freehand", rate_hz=400.0, seed=2, tremor_mm=0.2)
    d_t, _ = _tremor_offsets(with_hand)  # the operator's tremor alone (intended = freehand's own)
    assert np.sqrt(np.mean(d_t**2)) == pytest.approx(0.2, rel=0.15)
    own = Trajectory(base.build_scenario()).tremor
    hand = with_hand.hand_tremor()
    ts = np.arange(0.0, 20.0, 1e-3)
    a = np.array([own.offset(t)[0] for t in ts])
    b = np.array([hand.offset(t)[0] for t in ts])
    assert abs(np.corrcoef(a[:, 0], b[:, 0])[0, 1]) < 0.2  # independent waveforms


def test_a_built_in_speed_with_a_scenario_file_is_refused_not_ignored(tmp_path, cli_main):
    """A scenario file sets its own speeds: ``--speed 60`` beside one was announced and then
    ignored (a "60 mm/s" job ran the file's 20 mm/s and gave the 20 mm/s figures to the
    digit). Refused before any work, with what to do; a built-in still takes it."""
    scn = tmp_path / "line.scn"
    scn.write_text("scenario line\nstart 100 1200 0 0 0 180\nspeed 20\nline 140 1200 0\n")
    with pytest.raises(ValueError, match=r"speed_mm_s .*60 mm/s sets a built-in scenario's speed; the scenario "
                                         r".*line\.scn sets its own .*operator\.speed_scale"):
        OperatorConfig(scenario_file=str(scn), speed_mm_s=60.0)
    assert OperatorConfig(scenario_file=str(scn), speed_scale=3.0).build_scenario() is not None
    slow, fast = (OperatorConfig(scenario="trapezium", speed_mm_s=v).build_scenario() for v in (20.0, 60.0))
    assert slow.segments[1].speed_mm_s == 20.0 and fast.segments[1].speed_mm_s == 60.0
    run_dir = tmp_path / "run"
    with pytest.raises(SystemExit, match="humanpt: .*sets its own"):  # main prints it, exits 1
        cli_main(["demo", "--lockstep", "--scenario", str(scn), "--speed", "60", "--run-dir", str(run_dir)])
    assert not run_dir.exists()
