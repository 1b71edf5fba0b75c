"""pose_filter: a still target is detected and averaged (zero-velocity updates, calm
process noise), and released at once when it moves again.
The filter is built with ``wait_for_robot_ms=0`` (a measurement is used at once, robot pose
extrapolated if need be) where a test reads its outputs right after a measurement; the
wait itself has its own tests."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.schemas.convert import from_pose
from tests.pose_filter.test_pose_filter import TARGET_X, T_m, World, x_of

# About the twin's per-image noise of a pose (default perception at 600 mm).
NOISE = {"sigma_mm": 0.03, "sigma_deg": 0.06}


def still_flange(t_ns):
    return T_m((200, 700, 80, 0, 0, 0))


def _errors(w, truth_fn, since_ns):
    """(n, 6) errors (mm, deg) of the estimates at measurement of the states after since_ns."""
    out = []
    for s in w.states:
        if s.after_measurement and s.measurement_stamp_ns > since_ns:
            est = x_of(from_pose(s.world_T_tob_at_measurement))
            e = est - np.asarray(x_of(truth_fn(s.measurement_stamp_ns)))
            e[3:] = (e[3:] + 180) % 360 - 180
            out.append(e)
    return np.array(out)


@pytest.mark.parametrize("detect", [True, False])
def test_a_still_target_is_averaged(detect):
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0, still_detect=detect))
    truth = T_m(TARGET_X)
    w = World(core, still_flange, lambda t: truth, np.random.default_rng(7), **NOISE)
    w.run(0, 8_000_000_000)
    codes = [e.code for e in w.events]
    assert ("target_still" in codes) == detect
    assert "target_moving" not in codes and "outlier" not in codes
    sd = _errors(w, lambda t: truth, 4_000_000_000).std(axis=0)
    if detect:
        # A long average: far below the per-image noise (0.03 mm, 0.06 deg per axis).
        assert np.all(sd[:3] < 0.0075) and np.all(sd[3:] < 0.006), sd
        v = w.states[-1].linear_velocity_m_s
        assert abs(v.x) + abs(v.y) + abs(v.z) < 1e-6
    else:
        assert np.all(sd[3:] > 0.01), sd  # the plain filter wanders with its velocity noise


def test_a_still_target_that_moves_is_followed_again_within_a_few_frames():
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    t_move = 4_000_000_000

    def tob(t):  # still, then 30 mm/s along x and 5 deg/s about z from t_move
        s = max(0.0, (t - t_move) * 1e-9)
        return T_m((TARGET_X[0] + 30 * s, *TARGET_X[1:3], TARGET_X[3] + 5 * s, *TARGET_X[4:]))

    w = World(core, still_flange, tob, np.random.default_rng(8), **NOISE)
    w.run(0, 7_000_000_000)
    codes = [e.code for e in w.events]
    assert codes.count("target_still") >= 1 and "target_moving" in codes
    assert "filter_reset" not in codes and "outlier" not in codes
    moving = [e for e in w.events if e.code == "target_moving"]
    assert moving and all(e.header.stamp_ns > t_move for e in moving)
    # A sudden 30 mm/s start is seen on the first frame after it, and the moving model ran
    # on all along: at most ~0.2 mm behind (the plain filter: ~0.16 mm).
    err = _errors(w, tob, t_move)
    assert np.max(np.abs(err[:, 0])) < 0.3, np.abs(err[:, 0]).max()
    late = _errors(w, tob, t_move + 1_500_000_000)
    assert np.all(np.abs(late[:, :3]).mean(axis=0) < 0.05), np.abs(late).mean(axis=0)


def test_still_config_is_validated():
    with pytest.raises(ValueError, match="still_q_scale"):
        PoseFilterConfig(still_q_scale=2.0)
    with pytest.raises(ValueError, match="still_release_mm"):
        PoseFilterConfig(still_release_mm=0.0)


@pytest.mark.parametrize("speed_mm_s", [0.5, 1.0])
def test_a_slow_drift_is_followed_about_as_well_as_by_the_plain_filter(speed_mm_s):
    """Below the still speed a drifting target may be taken as still; the mean offset of the
    latest measurements ends that before the lag grows (no sawtooth of 0.3 mm)."""
    def tob(t):
        return T_m((TARGET_X[0] + speed_mm_s * t * 1e-9, *TARGET_X[1:]))

    def errors(detect):
        w = World(PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0, still_detect=detect)), still_flange, tob,
                  np.random.default_rng(7), **NOISE)
        w.run(0, 10_000_000_000)
        return np.abs(_errors(w, tob, 3_000_000_000)[:, 0])

    with_still, plain = errors(True), errors(False)
    assert with_still.max() < plain.max() + 0.05, (with_still.max(), plain.max())
    assert with_still.mean() < plain.mean() + 0.015, (with_still.mean(), plain.mean())
