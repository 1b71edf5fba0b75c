"""The world's optics and sensor beyond the ideal (issue 16): rotated virtual cameras,
ghost, fall-off, fixed-pattern noise, blooming, motion blur. Each is off by default."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from humanpt.geometry import camera_T_desired, make_transform, project, transform_from_x
from humanpt.sim_camera import PsvsConfig, Renderer, SimCameraConfig, intensity_centroid
from humanpt.sim_camera import render as render_module
from humanpt.sim_camera.render import Discs, bloom_columns


def _view_signal(r: Renderer, camera_T_tob, view: int) -> np.ndarray:
    """Noise-free signal of one view's blobs (H, W)."""
    blobs = r.blobs(r.discs(camera_T_tob))
    sel = np.flatnonzero(blobs.view == view)
    return r.signal(render_module.Blobs(*(getattr(blobs, f)[sel] for f in blobs.__dataclass_fields__)))


def _windows(signal: np.ndarray, centres: np.ndarray, half: int = 9):
    for u, v in centres:
        r0, c0 = int(round(v)) - half, int(round(u)) - half
        yield signal[r0 : r0 + 2 * half + 1, c0 : c0 + 2 * half + 1], np.array([c0, r0])


def var_u(window: np.ndarray) -> float:
    """Intensity-weighted variance (px^2) of a window's column coordinate."""
    weight = window.sum(axis=0)
    cols = np.arange(window.shape[1])
    mean = (weight * cols).sum() / weight.sum()
    return float((weight * (cols - mean) ** 2).sum() / weight.sum())


def test_rendered_rotated_views_centre_on_the_rotated_projection():
    """A tilted mirror in the world: each blob's intensity centroid (noise off) sits on the
    geometry library's projection with the rotated cameras and own principal points."""
    psvs = PsvsConfig(
        rotvec_right_deg=(0.05, -0.1, 0.2), rotvec_left_deg=(0.0, 0.3, 0.0), du0_left_px=0.7
    )
    r = Renderer(SimCameraConfig(noise=False, psvs=psvs))
    camera_T_tob = camera_T_desired(645.0)
    p = camera_T_tob[:3, :3] @ r.model.source_positions_mm.T + camera_T_tob[:3, 3:4]
    expected = project(psvs.params(), p.T)
    nominal = project(PsvsConfig().params(), p.T)
    for view in (0, 1):
        signal = _view_signal(r, camera_T_tob, view)
        for (win, origin), uv in zip(_windows(signal, expected[view]), expected[view], strict=True):
            np.testing.assert_allclose(intensity_centroid(win) + origin, uv, atol=0.02)
    # and the rotation is visible: the left view moved by about -a_u tan(0.3 deg) + 0.7 px
    shift = expected[1][:, 0] - nominal[1][:, 0]
    np.testing.assert_allclose(shift, -1000 * math.tan(math.radians(0.3)) + 0.7, atol=0.05)


def test_ghost_is_a_dimmer_shifted_copy_of_the_left_view():
    base = SimCameraConfig(noise=False)
    ghosted = dataclasses.replace(base, ghost_gain=0.04, ghost_offset_px=(1.5, -2.0))
    camera_T_tob = camera_T_desired(645.0)
    r0, r1 = Renderer(base), Renderer(ghosted)
    blobs0, blobs1 = r0.blobs(r0.discs(camera_T_tob)), r1.blobs(r1.discs(camera_T_tob))
    assert len(blobs1) == len(blobs0) + 3 and set(blobs1.label[len(blobs0) :]) == {100, 101, 102}
    ghost = r1.signal(blobs1).astype(float) - r0.signal(blobs0)
    left = _view_signal(r0, camera_T_tob, 1).astype(float)
    assert ghost.sum() == pytest.approx(0.04 * left.sum(), rel=1e-5)
    left_centres = blobs0.centre_px[blobs0.view == 1]
    for (win, origin), uv in zip(_windows(ghost, left_centres + (1.5, -2.0)), left_centres, strict=True):
        np.testing.assert_allclose(intensity_centroid(win) + origin, uv + (1.5, -2.0), atol=0.02)


def test_source_falloff_dims_by_cos_to_the_power_n():
    """A disc on the right camera's axis, its normal turned 30 deg away: cos(30)^2 = 0.75
    of the brightness for n = 2; the left view, seen at another angle, gets its own."""
    params = PsvsConfig().params()
    centre = params.right_camera.centre + (0.0, 0.0, 600.0)
    tilt = transform_from_x(np.array([0, 0, 0, 0, 30.0, 0]))[:3, :3]
    axes = tilt @ np.diag([1.0, 1.0, -1.0])  # e1, e2, lit normal -z turned by 30 deg
    discs = Discs.make(centre, axes, 2.5, 400.0)
    flat = render_module.project_discs(params, discs, (0.5, 0.5), 1.0, 0.7)
    dim = render_module.project_discs(params, discs, (0.5, 0.5), 1.0, 0.7, falloff_exponent=2.0)
    assert dim.dn[0] / flat.dn[0] == pytest.approx(0.75, rel=1e-9)
    to_left = params.left_camera.centre - centre
    cos_left = (to_left @ axes[:, 2]) / np.linalg.norm(to_left)
    assert dim.dn[1] / flat.dn[1] == pytest.approx(cos_left**2, rel=1e-9)


def test_fixed_pattern_is_the_same_in_every_frame_and_has_its_size():
    cfg = SimCameraConfig(noise=False, dsnu_dn=2.0, seed=3)
    r = Renderer(cfg)
    a, b = r.render(None, frame_index=0), r.render(None, frame_index=7)
    np.testing.assert_array_equal(a, b)  # fixed, not per frame
    # background 14 DN + N(0, 2 DN), rounded: SD sqrt(4 + 1/12)
    assert a.astype(float).std() == pytest.approx(math.sqrt(4 + 1 / 12), rel=0.02)
    other = Renderer(dataclasses.replace(cfg, seed=4)).render(None)
    assert np.corrcoef(a.ravel(), other.ravel())[0, 1] < 0.01  # a pattern per seed
    # with temporal noise on, two frames share the pattern: correlation ~ 4 / (4 + 0.6^2)
    noisy = Renderer(dataclasses.replace(cfg, noise=True))
    f0, f1 = (noisy.render(None, frame_index=i).astype(float).ravel() for i in (0, 1))
    assert np.corrcoef(f0, f1)[0, 1] > 0.85
    plain = Renderer(SimCameraConfig(seed=3))
    g0, g1 = (plain.render(None, frame_index=i).astype(float).ravel() for i in (0, 1))
    assert abs(np.corrcoef(g0, g1)[0, 1]) < 0.01


def test_prnu_scales_each_pixels_charge():
    """A large uniform disc, noise off: fully covered pixels read
    black + (signal + sky)(1 + prnu_i); their spread is prnu (signal + sky)."""
    cfg = SimCameraConfig(noise=False, prnu=0.02, blur_sigma_px=0.0, source_dn_per_ms=300.0)
    r = Renderer(cfg)
    discs = Discs.make([0.0, 0.0, 300.0], np.diag([1.0, 1.0, -1.0]), 20.0, 300.0)
    blobs = r.blobs(discs)
    signal = r.signal(blobs)
    img = r.expose(signal, 0).astype(float)
    inner = signal >= signal.max() - 1e-3
    level = signal.max() + r.sky_dn  # fully covered: 300 * 0.5 (or 0.44, the other view) + 10
    assert inner.sum() > 500
    assert img[inner].std() == pytest.approx(0.02 * level, rel=0.1)


def test_bloom_columns_by_hand():
    """Full well 100 e-, background 0: 250 e- spills 75 up and 75 down; 500 e- fills two
    neighbours each way; a pixel at the top edge loses the half that leaves the image."""
    width = 5
    idx = np.array([2 * width + 1, 7 * width + 3])
    charge, other, got = bloom_columns(idx, np.array([250.0, 500.0]), (10, width), 100.0, 1.0, 0.0)
    np.testing.assert_array_equal(charge, [100.0, 100.0])
    received = dict(zip(other.tolist(), got.tolist(), strict=True))
    assert received == {
        1 * width + 1: 75.0,
        3 * width + 1: 75.0,
        5 * width + 3: 100.0,
        6 * width + 3: 100.0,
        8 * width + 3: 100.0,
        9 * width + 3: 100.0,
    }
    charge, other, got = bloom_columns(np.array([0]), np.array([300.0]), (10, width), 100.0, 0.5, 0.0)
    assert charge[0] == 100.0 and other.tolist() == [width] and got.tolist() == [50.0]
    # a signal pixel next to the saturated one takes what fits below its well
    charge, other, got = bloom_columns(
        np.array([width, 2 * width]), np.array([90.0, 130.0]), (10, width), 100.0, 1.0, 0.0
    )
    np.testing.assert_array_equal(charge, [100.0, 100.0])
    # 30 e- over: 15 up (10 fit, 5 go on to row 0) and 15 down
    assert other.tolist() == [0, 3 * width] and got.tolist() == [5.0, 15.0]


def test_blooming_stretches_a_saturated_source_along_its_column():
    cfg = SimCameraConfig(noise=False, exposure_ms=4.0, background_dn_per_ms=0.0)
    camera_T_tob = camera_T_desired(645.0)
    plain = Renderer(cfg).render(camera_T_tob).astype(float)
    bloomed = Renderer(dataclasses.replace(cfg, blooming=1.0)).render(camera_T_tob).astype(float)
    lit = plain > cfg.black_level_dn
    grown = (bloomed > cfg.black_level_dn) & ~lit
    rows, cols = np.nonzero(grown)
    assert rows.size > 20
    # the new pixels lie above or below lit pixels of the same column, not beside them
    assert all(lit[:, c].any() for c in np.unique(cols))
    assert np.all(bloomed >= plain)


def test_motion_blur_spreads_the_blob_by_the_motion_and_centres_it_at_mid_exposure():
    """The target moves 3 mm along x during the exposure at 645 mm: a_u 3 / (645 + b/2)
    = 4.35 px in either view. The blurred blob's centroid is the mid-exposure one and its u variance grows by
    that of N equally spaced samples, L^2 (1 - 1/N^2) / 12 (hand calculation)."""
    cfg = SimCameraConfig(noise=False)
    r = Renderer(cfg)
    start = camera_T_desired(645.0)
    end = make_transform(np.eye(3), start[:3, 3] + (3.0, 0.0, 0.0))
    mid = make_transform(np.eye(3), start[:3, 3] + (1.5, 0.0, 0.0))
    idx, value = r.exposure_signal_pixels((start, end))
    blurred = np.zeros(480 * 640)
    blurred[idx] = value
    blurred = blurred.reshape(480, 640)
    sharp = r.signal(r.blobs(r.discs(mid)))
    b_start, b_end = r.blobs(r.discs(start)), r.blobs(r.discs(end))
    length = np.abs(b_end.centre_px[:, 0] - b_start.centre_px[:, 0])
    n = math.ceil(length.max() / cfg.motion_step_px)
    assert length == pytest.approx(4.35, abs=0.01) and n == 15  # 4.35 px / 0.3 px
    centres = r.blobs(r.discs(mid)).centre_px
    for k, ((wb, origin), (ws, _)) in enumerate(
        zip(_windows(blurred, centres, 12), _windows(sharp, centres, 12), strict=True)
    ):
        np.testing.assert_allclose(intensity_centroid(wb) + origin, centres[k], atol=0.01)
        expected = length[k] ** 2 * (1 - 1 / n**2) / 12
        assert var_u(wb) - var_u(ws) == pytest.approx(expected, rel=0.03)
    assert blurred.sum() == pytest.approx(sharp.sum(), rel=1e-3)


def test_no_motion_costs_one_sample_and_the_old_call_is_unchanged():
    r = Renderer(SimCameraConfig())
    pose = camera_T_desired(645.0)
    world_T_camera = np.eye(4)
    np.testing.assert_array_equal(
        r.render(pose, world_T_camera, 3), r.render(pose, world_T_camera, 3, None, None)
    )
    # a motion below motion_step_px: one sample, at mid-exposure
    end = make_transform(np.eye(3), pose[:3, 3] + (0.05, 0.0, 0.0))
    mid = make_transform(np.eye(3), pose[:3, 3] + (0.025, 0.0, 0.0))
    np.testing.assert_array_equal(r.render(pose, None, 3, end), r.render(mid, None, 3))


def test_every_new_field_is_off_by_default():
    cfg = SimCameraConfig()
    assert (cfg.source_falloff_exponent, cfg.ghost_gain, cfg.dsnu_dn, cfg.prnu, cfg.blooming) == (
        0.0,
    ) * 5
    p = cfg.params()
    assert p.is_parallel and p.left_camera.u0 == p.u0 and p.right_camera.v0 == p.v0


def test_exposure_from_three_samples_renders_the_middle_exactly_or_follows_a_corner():
    r = Renderer(SimCameraConfig())
    start = camera_T_desired(645.0)

    def moved(dx, dy):
        return make_transform(np.eye(3), start[:3, 3] + (dx, dy, 0.0))

    # a sub-step motion: the middle sample itself, byte for byte
    small = [start, moved(0.01, 0.0), moved(0.03, 0.0)]
    np.testing.assert_array_equal(r.render_exposure(small, None, 5), r.render(small[1], None, 5))
    # an L-shaped path, 2 mm along x then 2 mm along y: the blur's centroid is the path's
    # mean, (1.5, 0.5) mm from the start (equal halves with means (1, 0) and (2, 1))
    quiet = Renderer(SimCameraConfig(noise=False))
    idx, value = quiet.exposure_signal_pixels([start, moved(2.0, 0.0), moved(2.0, 2.0)])
    blurred = np.zeros(480 * 640)
    blurred[idx] = value
    centres = quiet.blobs(quiet.discs(moved(1.5, 0.5))).centre_px
    for (win, origin), uv in zip(_windows(blurred.reshape(480, 640), centres, 12), centres, strict=True):
        np.testing.assert_allclose(intensity_centroid(win) + origin, uv, atol=0.02)
