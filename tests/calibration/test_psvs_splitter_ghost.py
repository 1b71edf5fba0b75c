"""The beam splitter's ghost and its thickness (issue 32's 0.1 mm sources): what they cost
the TOB's depth at the servo's pose with the nominal rig, that the PSVS stage takes both
up (a ghost is a constant shift of the left view's centroids: a disparity offset, the
left view's pan; a thicker plate moves the left view by m, which the baseline b + m
takes), and the depth 1-sigma the stage states.

Expected values from the geometry alone (eq. (4)-(6) and the ghost's centroid shift
``gain * offset / (1 + gain)``), not from the stage; the stage runs once per world
(module-scoped), noise-free, ~2 s each."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanpt.calibration.psvs import depth_sigma_mm, estimate_psvs
from humanpt.geometry.psvs import project, triangulate
from humanpt.geometry.rig import DEFAULT_DZ_MM, Calibration, Rig
from humanpt.sim_camera.config import SimCameraConfig
from humanpt.twin.cal_psvs import calibrate_psvs_on_twin, servo_pose_error
from humanpt.twin.worlds import World

GHOST_GAIN = 0.04  # the world's source "ghost"
SPLITTER_MM = 1.05  # the world's source "splitter"


@pytest.fixture(scope="module")
def stage():
    """The stage on the nominal rig in the ideal world and in the ideal world with the
    ghost and the thicker splitter: {name: (estimate, truth lines)}."""
    out = {}
    for name in ("ideal", "ideal+ghost+splitter"):
        est, _report, truth = calibrate_psvs_on_twin(World.named(name), Rig(), 0)
        out[name] = (est, truth)
    return out


def _expected_depth_error_mm() -> float:
    """The TOB's depth error at the servo's pose with the nominal rig, by hand: a point on
    the axis at 600 mm projected through the world's optics (the splitter 1.05 mm thick,
    eq. (5), (6)), the left view's u shifted by the ghost's pull on a centroid, then
    triangulated with the nominal rig (eq. (4))."""
    nominal = Rig().params()
    true = dataclasses.replace(Rig().psvs, splitter_thickness_mm=SPLITTER_MM).params()
    offset_u = SimCameraConfig().ghost_offset_px[0]
    pull_px = GHOST_GAIN * offset_u / (1.0 + GHOST_GAIN)  # the centroid of a blob plus its ghost
    uv_r, uv_l = project(true, np.array([0.0, 0.0, DEFAULT_DZ_MM]), distort=False)
    z = triangulate(nominal, uv_r, uv_l + np.array([pull_px, 0.0]), undistort=False)[2]
    return float(z - DEFAULT_DZ_MM)


def _servo_line(truth, which: str) -> np.ndarray:
    line = next(x for x in truth if "servo's pose" in x and f"rig {which}" in x)
    return np.array([float(v) for v in line.split("true: (")[1].split(")")[0].split(",")])


def test_the_hand_computed_cost_is_what_the_nominal_rig_measures(stage):
    expected = _expected_depth_error_mm()
    assert -0.35 < expected < -0.25  # ghost ~ -0.19 mm, splitter ~ -0.12 mm (the error budget's rows)
    _est, truth = stage["ideal+ghost+splitter"]
    before = _servo_line(truth, "before")
    ideal_before = _servo_line(stage["ideal"][1], "before")  # the ideal world's own (perception's model error)
    assert before[2] - ideal_before[2] == pytest.approx(expected, abs=0.03)


def test_the_stage_takes_the_ghost_and_the_splitter_up(stage):
    est, truth = stage["ideal+ghost+splitter"]
    after = _servo_line(truth, "after")
    assert abs(after[2]) < 0.03  # from ~0.3 mm: a tenth left
    check = next(c for c in truth.checks if "depth at the servo's pose" in c.what)
    assert check.met and check.value == pytest.approx(abs(after[2]), abs=5e-4)  # the line rounds to 0.001
    # as the left view's pan (the ghost's constant pull, -pull / a_u rad) and a longer
    # baseline (b + m is what the views see; m held at the nominal plate's): the
    # difference from the ideal world's own fit, within 0.001 deg (0.07 mm at 600 mm) and
    # 0.015 mm (the two trade off against each other: only their sum at each depth is
    # sharp)
    ideal = stage["ideal"][0]
    pull_px = GHOST_GAIN * SimCameraConfig().ghost_offset_px[0] / (1.0 + GHOST_GAIN)
    pan_deg = np.degrees(-pull_px / Rig().params().a_u)
    assert est.rotvec_left_deg[1] - ideal.rotvec_left_deg[1] == pytest.approx(pan_deg, abs=1e-3)
    m_true = dataclasses.replace(Rig().psvs, splitter_thickness_mm=SPLITTER_MM).params().m_mm
    assert est.baseline_mm - ideal.baseline_mm == pytest.approx(m_true - Rig().params().m_mm, abs=0.015)


def test_the_world_without_them_is_not_moved(stage):
    _est, truth = stage["ideal"]
    assert abs(_servo_line(truth, "before")[2]) < 0.03
    assert abs(_servo_line(truth, "after")[2]) < 0.03


def test_the_stated_depth_sigma_carries_the_focal_length_and_the_fit():
    """depth_sigma_mm: the focal part is dz * sigma(a_u) / a_u (by hand); the fit's part
    is the scatter of the triangulated depth over repeated noisy estimates (synthetic views
    through the geometry's own model, 0.03 px), within a factor 1.6."""
    rng = np.random.default_rng(5)
    rig = Rig()
    tob = rig.target_model().source_positions_mm
    from humanpt.twin.cal_psvs import plan_camera_T_tob

    plan = plan_camera_T_tob(30, 2)
    clean = [project(rig.params(), tob @ T[:3, :3].T + T[:3, 3]) for T in plan]
    point = np.array([0.0, 0.0, DEFAULT_DZ_MM])
    true_uv = project(rig.params(), point, distort=False)
    depths, sigmas = [], []
    from humanpt.calibration.psvs import StereoViews, apply_to_rig

    for _ in range(12):
        views = StereoViews(np.array([r + rng.normal(0, 0.03, r.shape) for r, _l in clean]),
                            np.array([l_ + rng.normal(0, 0.03, l_.shape) for _r, l_ in clean]))
        est = estimate_psvs(rig, views)
        after = apply_to_rig(rig, est, "test")
        depths.append(triangulate(after.params(), *true_uv, undistort=False)[2])
        sigmas.append(depth_sigma_mm(after, est)["psvs"])
    scatter = float(np.std(depths, ddof=1))
    stated = float(np.mean(sigmas))
    assert 0 < stated and 1 / 1.6 < stated / scatter < 1.6, (stated, scatter)
    # the focal length's part, from the rig's a_u sigma
    with_sigma = dataclasses.replace(after, psvs_calibration=Calibration("zhang", sigma={"a_u": 0.3}))
    d = depth_sigma_mm(with_sigma, est)
    assert d["a_u"] == pytest.approx(DEFAULT_DZ_MM * 0.3 / 1000.0, rel=1e-9)
    assert d["total"] == pytest.approx(np.hypot(d["a_u"], d["psvs"]), rel=1e-9)
    assert servo_pose_error  # the truth's diagnostic is importable from the stage's module
