"""The operator core: truth at a fixed rate, start delay, live pace, done event."""

from __future__ import annotations

import numpy as np
import pytest

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
        (0, "scenario_started"),
        (2_000_000_000, "scenario_done"),
    ]  # after the start delay


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
