"""Issue 18.4 and 18.2 in the controller's maths, against hand values: the position-first
step at the speed limits, the field-of-view margin, the tip's covariance, and held
orientations filled in for playback."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.controller import law, pathfile
from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore, tip_position_covariance
from humanpt.controller.servo_report import servo_summary
from humanpt.geometry.psvs import PsvsParams
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

DT = 0.028
MAX_M, MAX_RAD = 0.1 * DT, np.radians(60.0) * DT  # the robot's 100 mm/s, 60 deg/s per cycle


def _flange_T_d():
    """D 700 mm ahead of the flange along z, 60 mm off its axis (the nominal rig's)."""
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.06, 0.7]
    return T


def _robot(world_T_flange, d_t, d_r):
    """The robot's step, written with scipy (not law.apply_step)."""
    T = np.array(world_T_flange, dtype=float)
    T[:3, :3] = Rotation.from_rotvec(d_r).as_matrix() @ T[:3, :3]
    T[:3, 3] += d_t
    return T


@pytest.mark.parametrize("w_deg_s", [(0.0, 0.0, 5.0), (40.0, -30.0, 60.0), (0.0, 90.0, 0.0)])
def test_position_first_moves_d_as_asked_within_the_limits(w_deg_s):
    F = np.eye(4)
    F[:3, :3] = Rotation.from_euler("ZYX", [20, 10, 175], degrees=True).as_matrix()
    F[:3, 3] = [0.2, 1.1, 0.8]
    v_d = np.array([0.04, -0.02, 0.01])  # 46 mm/s: leaves room for some rotation
    w = np.radians(w_deg_s)
    d_t, d_r, sat, s = law.position_first(F, _flange_T_d(), v_d, w, DT, MAX_M, MAX_RAD)
    assert np.linalg.norm(d_t) <= MAX_M + 1e-12 and np.linalg.norm(d_r) <= MAX_RAD + 1e-12
    after = _robot(F, d_t, d_r)
    d_before, d_after = (F @ _flange_T_d())[:3, 3], (after @ _flange_T_d())[:3, 3]
    # D moved exactly as asked, whatever happened to the rotation.
    np.testing.assert_allclose(d_after - d_before, v_d * DT, atol=1e-12)
    # The rotation about the flange-D line is never given up (it costs no translation);
    # the rest is scaled by s.
    u = (d_before - F[:3, 3]) / np.linalg.norm(d_before - F[:3, 3])
    w_lim = w * min(1.0, MAX_RAD / DT / max(np.linalg.norm(w), 1e-300))
    np.testing.assert_allclose(d_r @ u, (w_lim @ u) * DT, atol=1e-12)
    assert 0.0 <= s <= 1.0 and sat == (s < 1.0 or np.linalg.norm(w) * DT > MAX_RAD)


def test_position_first_scales_d_when_d_alone_is_too_fast():
    F = np.eye(4)
    v_d = np.array([0.3, 0.0, 0.0])  # 300 mm/s
    d_t, d_r, sat, s = law.position_first(F, _flange_T_d(), v_d, np.radians([30.0, 0.0, 0.0]), DT, MAX_M, MAX_RAD)
    assert sat and s == 0.0
    # Only the rotation about the flange-D line is left, and D goes straight at the limit.
    after = _robot(F, d_t, d_r)
    moved = (after @ _flange_T_d())[:3, 3] - _flange_T_d()[:3, 3]
    np.testing.assert_allclose(moved, [MAX_M, 0.0, 0.0], atol=1e-12)


def test_fov_margin_against_a_hand_projection():
    """A point on the right view's axis projects to (u0, v0): 240 px from the top and bottom
    edges (+0.5: pixel centres at integers), 320 from the sides; the nearest edge of all six
    images is the left view's, computed here by the pinhole formula itself."""
    p = PsvsParams()
    c_r, c_l = p.right_camera.centre_mm, p.left_camera.centre_mm
    z = 600.0
    sources = np.array([[c_r[0], c_r[1], z], [c_r[0], c_r[1] + 100.0, z], [c_r[0] - 50.0, c_r[1], z]])
    margin = law.fov_margin_px(p, np.eye(4), sources)
    # by hand: u = u0 + a_u (X - Ox) / (Z - Oz), v = v0 + a_v (Y - Oy) / (Z - Oz)
    uv = []
    for c in (c_r, c_l):
        for X, Y, Z in sources:
            uv.append((320 + 1000 * (X - c[0]) / (Z - c[2]), 240 + 1000 * (Y - c[1]) / (Z - c[2])))
    uv = np.array(uv)
    expect = np.min(np.minimum(np.minimum(uv[:, 0] + 0.5, 639.5 - uv[:, 0]), np.minimum(uv[:, 1] + 0.5, 479.5 - uv[:, 1])))
    assert margin == pytest.approx(expect, abs=1e-9)
    assert margin < 240.5 - 100.0  # the source 100 mm off the axis is nearer the bottom edge
    behind = sources.copy()
    behind[0, 2] = -100.0  # behind both views' centres (z = -45 and about -44.7 mm)
    assert law.fov_margin_px(p, np.eye(4), behind) == law.FOV_BEHIND_PX
    # G 20 mm off D sideways at 600 mm: 1000 px * 20 / (600 - Oz) in both views.
    off = law.image_offset_px(p, np.array([20.0, 0.0, 600.0]), np.array([0.0, 0.0, 600.0]))
    assert off == pytest.approx(max(1000 * 20 / (600 - c_r[2]), 1000 * 20 / (600 - c_l[2])), rel=1e-9)


def test_tip_covariance_is_the_first_order_propagation():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(6, 6))
    P = A @ A.T * 1e-8
    R = Rotation.from_euler("ZYX", [30, -10, 170], degrees=True).as_matrix()
    t = np.array([0.0, 0.0, 0.06])
    # Monte Carlo (independent of the Jacobian): P = p + exp(dr) R t.
    d = rng.multivariate_normal(np.zeros(6), P, size=200_000)
    tips = d[:, :3] + Rotation.from_rotvec(d[:, 3:]).apply(R @ t)
    np.testing.assert_allclose(tip_position_covariance(P, R @ t), np.cov(tips.T), rtol=0.03, atol=1e-12)


def test_held_orientations_are_interpolated_between_measured_ones():
    x = np.zeros((5, 6))
    x[:, 0] = np.arange(5.0)
    x[:, 3] = [0.0, 77.0, 77.0, 77.0, 40.0]  # psi: the held ones drifted to 77
    held = np.array([False, True, True, True, False])
    stamps = np.array([0, 10, 20, 30, 40]) * 1_000_000
    f = pathfile.fill_held_orientation(x, held, stamps)
    np.testing.assert_allclose(f[:, 3], [0.0, 10.0, 20.0, 30.0, 40.0], atol=1e-9)
    np.testing.assert_array_equal(f[:, :3], x[:, :3])  # positions untouched
    # At the ends: the nearest measured orientation.
    f = pathfile.fill_held_orientation(x, np.array([True, False, True, True, True]), stamps)
    np.testing.assert_allclose(f[:, 3], [77.0] * 5, atol=1e-9)
    # Path6.points fills by default; "keep" gives what was recorded.
    p = pathfile.Path6(np.arange(5), stamps, x, orientation_held=held)
    assert p.points()[2, 3] == pytest.approx(20.0) and p.points(held="keep")[2, 3] == 77.0


def test_the_controller_rejects_a_bad_saturation_and_reports_the_servo():
    core = ControllerCore(ControllerConfig())
    outs = core.step(0, "param", pb.ParamSet(header=header(0), key="saturation", value_json='"clip"'))
    assert outs[0][1].code == "param_rejected" and core.config.saturation == "position_first"
    outs = core.step(0, "param", pb.ParamSet(header=header(0), key="saturation", value_json='"scale"'))
    assert outs[0][1].code == "param_changed" and core.config.saturation == "scale"
    statuses = [pb.ControllerStatus(header=header(i), visible=3, error_translation_m=1e-3 * i, fov_margin_px=200 - i,
                                    image_error_px=i, saturated=i > 2, rotation_scale=1.0 if i < 4 else 0.5)
                for i in range(6)]
    statuses.append(pb.ControllerStatus(header=header(9), visible=0, fov_margin_px=0.0))  # no target: left out
    s = servo_summary(statuses, after_ns=1)
    assert (s.cycles, s.max_error_mm, s.min_fov_margin_px, s.max_image_error_px) == (5, 5.0, 195.0, 5.0)
    assert (s.saturated_cycles, s.lagging_cycles, s.min_rotation_scale) == (3, 2, 0.5)
    assert "field of view margin min 195 px" in s.line()


def test_position_first_engages_beyond_the_band_and_holds_while_the_limits_bind():
    """thetau_step: a saturated step with G within ``position_first_beyond_m`` of D is the
    scaled one (as ``scale``); beyond it, or once engaged, position_first's."""
    F = np.eye(4)
    fd = _flange_T_d()

    def step(g_off_m, **kw):
        G = F @ fd
        G = G.copy()
        G[:3, 3] += [g_off_m, 0.0, 0.0]
        # The target moving at 60 mm/s, turning at 60 deg/s, tilted 30 deg from D's frame:
        # following it would swing the flange (700 mm from D) far beyond 100 mm/s.
        args = dict(v_tob_m_s=np.array([0.06, 0.0, 0.0]), w_tob_rad_s=np.radians([0.0, 0.0, 60.0]),
                    k_t=4.0, k_r=4.0, dt_s=DT, max_step_m=MAX_M, max_step_rad=MAX_RAD)
        G[:3, :3] = Rotation.from_euler("y", 30, degrees=True).as_matrix()
        return law.thetau_step(F, G, fd, **args, **kw)

    scaled = step(0.005, saturation="scale")
    assert scaled.saturated and not scaled.position_first
    within = step(0.005, saturation="position_first", position_first_beyond_m=0.01)
    np.testing.assert_array_equal(within.d_translation_m, scaled.d_translation_m)
    beyond = step(0.015, saturation="position_first", position_first_beyond_m=0.01)
    assert beyond.position_first and beyond.rotation_scale < 1.0
    held = step(0.005, saturation="position_first", position_first_beyond_m=0.01, engaged=True)
    assert held.position_first
