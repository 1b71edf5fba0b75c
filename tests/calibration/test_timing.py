"""The camera-to-robot time offset (issue 32.4, humanpt.calibration.timing) on data made by
hand: a still target, a robot moving and turning, images stamped a known time late."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.calibration.timing import TimeOffsetError, estimate_time_offset
from humanpt.geometry.transforms import invert_transform, make_transform

C = make_transform(np.eye(3), np.array([0.0, 60.0, 100.0]))  # flange_T_camera, mm
TARGET = make_transform(np.eye(3), np.array([200.0, 1200.0, 50.0]))  # world_T_tob, still


def flange(t_s: float) -> np.ndarray:
    """A robot looking down at the target from about 600 mm, swaying and turning (mm)."""
    R = Rotation.from_euler("ZYX", [8 * np.sin(1.1 * t_s), 5 * np.sin(0.7 * t_s + 1), 180 + 4 * np.sin(1.9 * t_s)],
                            degrees=True).as_matrix()
    p = np.array([200.0 + 30 * np.sin(0.9 * t_s), 1140.0 + 20 * np.cos(1.3 * t_s), 750.0 + 10 * np.sin(2.1 * t_s)])
    return make_transform(R, p)


def data(offset_ms: float, noise_mm: float = 0.02, seed: int = 0, moving: bool = True):
    rng = np.random.default_rng(seed)
    robot_t = np.arange(0.0, 20.0, 0.028)  # ALTER's states
    img_t = np.arange(0.1, 19.9, 1 / 30)  # the images' true instants
    F = np.array([flange(t if moving else 0.0) for t in robot_t])
    meas = []
    for t in img_t:
        cam_T_tob = invert_transform(flange(t if moving else 0.0) @ C) @ TARGET
        cam_T_tob[:3, 3] += rng.normal(0, noise_mm, 3)
        meas.append(cam_T_tob)
    stamps = ((img_t + offset_ms * 1e-3) * 1e9).astype(np.int64)  # stamped late by the offset
    return stamps, np.array(meas), (robot_t * 1e9).astype(np.int64), F


@pytest.mark.parametrize("offset_ms", [5.0, -3.0, 0.0])
def test_the_offset_the_stamps_were_given_is_found(offset_ms):
    est = estimate_time_offset(*data(offset_ms), C)
    assert est.offset_ms == pytest.approx(offset_ms, abs=0.3)  # 5 ms -> 5.08 +- 0.22 (seed 0)
    assert abs(est.offset_ms - offset_ms) < 3 * est.sigma_ms + 0.05  # the sigma says how well
    assert 0 < est.sigma_ms < 0.5 and est.measurements > 500


def test_a_still_robot_shows_no_offset_and_says_so():
    with pytest.raises(TimeOffsetError, match="did not move"):
        estimate_time_offset(*data(5.0, moving=False), C)


def test_too_few_measurements_are_refused():
    s, m, r, F = data(5.0)
    with pytest.raises(TimeOffsetError, match="at least 20"):
        estimate_time_offset(s[:10], m[:10], r, F, C)
