"""The renderer: unbiased blob centres, exact coverage, photometry, noise, determinism,
vanishing sources, clutter."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.geometry import (
    camera_T_desired,
    in_image,
    project,
    project_pinhole,
    projection_jacobian,
    transform_from_x,
)
from humanpt.sim_camera import (
    Blobs,
    Discs,
    PsvsConfig,
    Renderer,
    SimCameraConfig,
    coverage,
    intensity_centroid,
    occlusion_offset,
)
from humanpt.sim_camera import render as render_module

DISTORTED = PsvsConfig(dist_coeffs=(-0.25, 0.12, 0.002, -0.001, 0.0))


def _one(blobs: Blobs, k: int) -> Blobs:
    return Blobs(*(getattr(blobs, f)[[k]] for f in Blobs.__dataclass_fields__))


def _random_camera_T_tob(rng: np.random.Generator) -> np.ndarray:
    x = [
        rng.uniform(-120, 120),
        rng.uniform(-90, 90),
        rng.uniform(450, 950),
        *rng.uniform(-30, 30, 3),
    ]
    return transform_from_x(np.array(x))


@pytest.mark.parametrize("psvs", [PsvsConfig(), DISTORTED], ids=["ideal lens", "distorted lens"])
def test_each_blob_alone_has_its_intensity_centroid_on_the_projected_centre(psvs):
    """The issue's criterion: < 0.02 px for every blob; typically ~0.003 px (rms)."""
    r = Renderer(SimCameraConfig(noise=False, psvs=psvs))
    rng = np.random.default_rng(42)
    errors = []
    for _ in range(40):
        camera_T_tob = _random_camera_T_tob(rng)
        discs = r.discs(camera_T_tob)
        blobs = r.blobs(discs)
        uv_right, uv_left = project(r.params, discs.centre_mm)
        for k in range(len(blobs)):
            expected = (uv_right, uv_left)[blobs.view[k]][blobs.disc[k]]
            if not in_image(r.params, expected, margin_px=10):
                continue  # a blob cut by the border has no full centroid
            img = r.expose(r.signal(_one(blobs, k)), 0)  # 8-bit, noise off
            errors.append(intensity_centroid(img, r.background_dn) - expected)
    errors = np.array(errors)
    assert len(errors) > 150
    assert np.max(np.abs(errors)) < 0.02
    assert np.sqrt(np.mean(errors**2)) < 0.006


def test_noisy_blob_centroid_is_unbiased_over_many_frames():
    r = Renderer(SimCameraConfig())
    camera_T_tob = transform_from_x(np.array([10.0, -20.0, 640.0, 5.0, -8.0, 12.0]))
    blobs = r.blobs(r.discs(camera_T_tob))
    k = 0
    single = r.signal(_one(blobs, k))
    u, v = np.round(blobs.centre_px[k]).astype(int)
    window = np.s_[v - 10 : v + 11, u - 10 : u + 11]
    rows, cols = np.mgrid[window]
    centres = []
    for frame in range(60):
        w = r.expose(single, frame)[window].astype(float) - r.background_dn
        centres.append([(w * cols).sum() / w.sum(), (w * rows).sum() / w.sum()])
    centres = np.array(centres)
    assert np.all(np.std(centres, axis=0) > 0.002)  # the noise is there...
    np.testing.assert_allclose(
        centres.mean(axis=0), blobs.centre_px[k], atol=0.02
    )  # ...and unbiased


@settings(max_examples=60, deadline=None)
@given(
    jac=st.lists(st.floats(-6, 6), min_size=4, max_size=4),
    fraction=st.floats(0.0, 0.95),
    angle=st.floats(0, 2 * math.pi),
    centre=st.tuples(st.floats(20, 21), st.floats(20, 21)),
)
def test_coverage_is_the_exact_area_of_the_visible_part(jac, fraction, angle, centre):
    j = np.array(jac).reshape(2, 2) + np.diag([3.0, 3.0])
    area = abs(np.linalg.det(j))
    if area < 0.5:
        return
    h = occlusion_offset(fraction)
    b = Blobs(
        np.array([centre]),
        j[None],
        np.ones(1),
        np.zeros(1),
        np.array([h]),
        np.array([[math.cos(angle), math.sin(angle)]]),
        np.zeros(1, int),
        np.zeros(1, int),
        np.zeros(1, int),
    )
    cov, _ = coverage(b, 16)
    assert cov.min() >= 0.0 and cov.max() <= 1.0
    assert cov.sum() == pytest.approx(area * math.pi * (1.0 - fraction), rel=1e-9, abs=1e-9)


def test_coverage_agrees_with_dense_supersampling():
    j = np.array([[3.5, 1.2], [-0.7, 2.6]])
    b = Blobs(
        np.array([[30.3, 40.8]]),
        j[None],
        np.ones(1),
        np.zeros(1),
        np.array([0.2]),
        np.array([[0.6, 0.8]]),
        np.zeros(1, int),
        np.zeros(1, int),
        np.zeros(1, int),
    )
    cov, origin = coverage(b, 8)
    s = 64
    sub = (np.arange(s) + 0.5) / s - 0.5
    ys = origin[0, 1] + np.arange(17)[:, None] + sub[None, :]
    xs = origin[0, 0] + np.arange(17)[:, None] + sub[None, :]
    du, dv = np.meshgrid(xs.ravel() - 30.3, ys.ravel() - 40.8)
    st_ = np.linalg.inv(j) @ np.stack([du.ravel(), dv.ravel()])
    inside = (np.sum(st_**2, axis=0) <= 1) & (0.6 * st_[0] + 0.8 * st_[1] <= 0.2)
    dense = inside.reshape(17, s, 17, s).mean(axis=(1, 3))
    assert np.abs(cov - dense).max() < 0.01


def test_each_view_at_its_own_brightness_and_the_signal_is_radiance_times_area():
    cfg = SimCameraConfig(noise=False, view_gain_right=0.5, view_gain_left=0.3, exposure_ms=0.5)
    r = Renderer(cfg)
    blobs = r.blobs(r.discs(camera_T_desired(600.0)))
    assert len(blobs) == 6 and sorted(blobs.view.tolist()) == [0, 0, 0, 1, 1, 1]
    for k in range(len(blobs)):
        gain = (0.5, 0.3)[blobs.view[k]]
        expected = cfg.source_dn_per_ms * 0.5 * gain * math.pi * abs(np.linalg.det(blobs.jac[k]))
        assert r.signal(_one(blobs, k)).sum() == pytest.approx(expected, rel=1e-6)


def test_exposure_saturation_and_quantisation():
    dim = Renderer(SimCameraConfig(exposure_ms=0.2)).render(camera_T_desired(600.0), frame_index=1)
    bright = Renderer(SimCameraConfig(exposure_ms=20.0)).render(
        camera_T_desired(600.0), frame_index=1
    )
    assert dim.dtype == np.uint8 and dim.shape == (480, 640)
    assert 40 < dim.max() < 120
    assert bright.max() == 255 and np.count_nonzero(bright == 255) > 6 * 20  # saturated cores
    # the background of a 20 ms exposure is 4 + 10 * 20 = 204 DN: bright, but not clipped
    assert abs(np.median(bright) - 204) <= 1


def test_background_noise_has_the_configured_statistics():
    cfg = SimCameraConfig(background_dn_per_ms=25.0, read_noise_e=30.0, gain_e_per_dn=10.0)
    r = Renderer(cfg)
    img = r.render(None, frame_index=7).astype(float)  # no target: background only
    mean = cfg.black_level_dn + 25.0
    sigma = math.sqrt(25.0 * 10.0 + 30.0**2) / 10.0  # shot + read, in DN
    assert img.mean() == pytest.approx(mean, abs=0.02)
    assert img.std() == pytest.approx(math.sqrt(sigma**2 + 1 / 12), rel=0.02)  # + quantisation


def test_shot_noise_grows_with_the_signal():
    r = Renderer(SimCameraConfig(blur_sigma_px=0.0))
    blobs = r.blobs(r.discs(camera_T_desired(500.0)))
    signal = r.signal(blobs)
    full = signal >= signal.max() - 1e-6  # fully covered pixels: the same mean everywhere
    values = np.concatenate([r.expose(signal, f)[full] for f in range(20)]).astype(float)
    mean_dn = r.background_dn + signal.max()
    expected_sigma = math.sqrt((mean_dn - 4.0) * 40.0 + 10.0**2) / 40.0
    assert values.mean() == pytest.approx(mean_dn, abs=0.1)
    assert values.std() == pytest.approx(expected_sigma, rel=0.1)


def test_same_seed_same_bytes_and_frames_do_not_depend_on_order():
    camera_T_tob = transform_from_x(np.array([5.0, 3.0, 620.0, 2.0, -3.0, 4.0]))
    a = Renderer(SimCameraConfig(seed=11))
    b = Renderer(SimCameraConfig(seed=11))
    frames_a = [a.render(camera_T_tob, frame_index=i).tobytes() for i in range(4)]
    frames_b = [b.render(camera_T_tob, frame_index=i).tobytes() for i in (3, 2, 1, 0)][::-1]
    assert frames_a == frames_b
    assert len(set(frames_a)) == 4  # each frame its own noise
    other = Renderer(SimCameraConfig(seed=12)).render(camera_T_tob, frame_index=0)
    assert other.tobytes() != frames_a[0]


@pytest.mark.parametrize(
    "x_mm_deg",
    [
        (0.0, 0.0, -600.0, 0.0, 0.0, 0.0),  # behind the camera
        (0.0, 0.0, 5.0, 0.0, 0.0, 0.0),  # nearer than the near plane
        (900.0, 0.0, 600.0, 0.0, 0.0, 0.0),  # far to the side: out of the field of view
        (0.0, 0.0, 600.0, 0.0, 180.0, 0.0),  # lit face turned away
    ],
    ids=["behind", "too near", "out of view", "facing away"],
)
def test_a_source_out_of_view_vanishes(x_mm_deg):
    r = Renderer(SimCameraConfig(seed=5))
    camera_T_tob = transform_from_x(np.array(x_mm_deg))
    assert len(r.blobs(r.discs(camera_T_tob))) == 0
    assert (
        r.render(camera_T_tob, frame_index=3).tobytes() == r.render(None, frame_index=3).tobytes()
    )


def test_a_source_half_out_of_the_image_keeps_only_what_is_inside():
    r = Renderer(SimCameraConfig(noise=False))
    # Slide the target right until the left view's rightmost blob straddles the border.
    for x in np.arange(0.0, 200.0, 0.5):
        blobs = r.blobs(r.discs(camera_T_desired(600.0) @ transform_from_x([x, 0, 0, 0, 0, 0])))
        u = blobs.centre_px[:, 0]
        if np.any(np.abs(u - 639.5) < 1.0):
            break
    sig = r.signal(blobs)
    k = int(np.argmin(np.abs(u - 639.5)))
    inside = r.signal(_one(blobs, k)).sum()
    total = blobs.dn[k] * math.pi * abs(np.linalg.det(blobs.jac[k]))  # were it all inside
    assert 0.3 * total < inside < 0.7 * total
    assert sig.shape == (480, 640)


def test_clutter_reflection_lamp_and_occlusion():
    base = SimCameraConfig(noise=False)
    camera_T_tob = camera_T_desired(600.0)
    plain = Renderer(base)
    n_plain = len(plain.blobs(plain.discs(camera_T_tob)))
    # A shiny wall beside the sources mirrors all three: six more, dimmer, blurred blobs.
    mirrored = Renderer(
        dataclasses.replace(base, reflection_gain=0.3, reflection_plane_tob=(1.0, 0.0, 0.0, 30.0))
    )
    b = mirrored.blobs(mirrored.discs(camera_T_tob))
    assert n_plain == 6 and len(b) == 12
    ghosts = b.label >= 10
    assert ghosts.sum() == 6
    assert np.allclose(b.dn[ghosts] / b.dn[~ghosts], 0.3)
    assert np.all(b.sigma_px[ghosts] > b.sigma_px[~ghosts])
    # A lamp fixed in the camera frame shows up once per view.
    lamp = Renderer(
        dataclasses.replace(base, lamp_position_mm=(-150.0, -100.0, 1500.0), lamp_frame="camera")
    )
    b = lamp.blobs(lamp.discs(camera_T_tob))
    assert np.count_nonzero(b.label == 20) == 2
    # A world-fixed lamp needs to know where the camera is.
    world_lamp = Renderer(dataclasses.replace(base, lamp_position_mm=(0.0, 0.0, 1500.0)))
    assert len(world_lamp.blobs(world_lamp.discs(camera_T_tob))) == 6
    assert len(world_lamp.blobs(world_lamp.discs(camera_T_tob, np.eye(4)))) == 8
    # Hiding the +u half of source A removes half its light and pulls its centroid to -u.
    occluded = Renderer(dataclasses.replace(base, occluded_sources=(0,), occlusion_fraction=0.5))
    b0 = plain.blobs(plain.discs(camera_T_tob))
    b1 = occluded.blobs(occluded.discs(camera_T_tob))
    k = int(np.flatnonzero((b0.label == 0) & (b0.view == 0))[0])
    full, half = plain.signal(_one(b0, k)), occluded.signal(_one(b1, k))
    assert half.sum() == pytest.approx(0.5 * full.sum(), rel=1e-6)
    shift = intensity_centroid(half) - intensity_centroid(full)
    radius_px = abs(b0.jac[k][0, 0])
    assert (
        shift[0] == pytest.approx(-4 * radius_px / (3 * math.pi), rel=0.05) and abs(shift[1]) < 0.01
    )


def test_config_errors_are_clear():
    with pytest.raises(ValueError, match="occluded_sources"):
        SimCameraConfig(occluded_sources=(3,))
    with pytest.raises(ValueError, match="view_gain_left"):
        SimCameraConfig(view_gain_left=1.5)
    with pytest.raises(ValueError, match="a_u"):
        PsvsConfig(a_u=-1.0)
    with pytest.raises(ValueError, match="target"):
        SimCameraConfig(target_leg_mm=10.0, target_base_mm=30.0)
    with pytest.raises(ValueError, match="fps"):
        SimCameraConfig(fps=0.0)


def test_discs_can_be_rendered_without_a_target_model():
    """The renderer is usable on its own: any discs, e.g. one fronto-parallel 10 mm disc."""
    r = Renderer(SimCameraConfig(noise=False))
    d = Discs.make([0.0, 0.0, 800.0], np.diag([1.0, 1.0, -1.0]), 5.0, 400.0)
    b = r.blobs(d)
    assert len(b) == 2
    np.testing.assert_allclose(np.abs(np.linalg.det(b.jac)), (1000 * 5.0 / 845) ** 2, rtol=2e-3)


# --------------------------------------------------------------------------- fast paths


def _table_probabilities(r: Renderer) -> np.ndarray:
    """P(grey = k), k = 0..255, of the background distribution the table holds."""
    return np.bincount(r._table, minlength=256) / r._table.size


@pytest.mark.parametrize(
    "cfg",
    [
        SimCameraConfig(seed=4),
        SimCameraConfig(seed=9, background_dn_per_ms=25.0, read_noise_e=30.0, gain_e_per_dn=10.0),
    ],
    ids=["default", "noisier"],
)
def test_background_grey_levels_have_the_exact_distribution(cfg):
    """Chi-square of the background histogram (three frames, ~920k pixels) against the
    distribution of background_table: the bank draws exactly it."""
    r = Renderer(cfg)
    values = np.concatenate([r.render(None, frame_index=f).ravel() for f in (0, 1, 57)])
    observed = np.bincount(values, minlength=256)
    expected = _table_probabilities(r) * values.size
    assert observed[expected == 0].sum() == 0
    used = expected >= 5
    chi2 = np.sum((observed[used] - expected[used]) ** 2 / expected[used])
    dof = np.count_nonzero(used) - 1
    assert chi2 < dof + 5 * math.sqrt(2 * dof)


def test_background_noise_is_new_in_every_frame_near_the_blobs():
    """The same background pixels around the blobs, frame after frame: uncorrelated, and
    a pixel's values over many frames follow the background distribution."""
    r = Renderer(SimCameraConfig(seed=2))
    camera_T_tob = camera_T_desired(600.0)
    blobs = r.blobs(r.discs(camera_T_tob))
    u, v = np.round(blobs.centre_px).astype(int).T
    mask = np.zeros((480, 640), dtype=bool)
    for uu, vv in zip(u, v, strict=True):
        mask[max(vv - 30, 0) : vv + 31, max(uu - 30, 0) : uu + 31] = True
    mask &= r.signal(blobs) == 0  # background pixels only
    frames = np.array([r.render(camera_T_tob, frame_index=f)[mask] for f in range(40)], float)
    n = mask.sum()
    assert n > 10_000
    corr = np.corrcoef(frames)
    off_diagonal = corr[~np.eye(len(frames), dtype=bool)]
    assert np.max(np.abs(off_diagonal)) < 5.0 / math.sqrt(n)
    # Over the frames, each pixel varies as the background does (mean, variance).
    p = _table_probabilities(r)
    levels = np.arange(256)
    mean = p @ levels
    var = p @ (levels - mean) ** 2
    per_pixel_var = frames.var(axis=0, ddof=1)
    assert frames.mean() == pytest.approx(mean, abs=0.01)
    assert per_pixel_var.mean() == pytest.approx(var, rel=0.03)
    assert np.count_nonzero(frames.std(axis=0) == 0) < 0.01 * n  # no pixel frozen


def test_noise_is_deterministic_per_seed_and_frame_whatever_was_rendered_before():
    camera_T_tob = transform_from_x(np.array([-20.0, 10.0, 700.0, 5.0, 2.0, -3.0]))
    a = Renderer(SimCameraConfig(seed=21)).render(camera_T_tob, frame_index=5)
    render_module._background_bank.cache_clear()  # rebuilt from the seed alone
    b = Renderer(SimCameraConfig(seed=21))
    b.render(None, frame_index=99)
    assert b.render(camera_T_tob, frame_index=5).tobytes() == a.tobytes()
    other = Renderer(SimCameraConfig(seed=22)).render(None, frame_index=5)
    assert np.mean(other != b.render(None, frame_index=5)) > 0.3


@pytest.mark.parametrize("noise", [True, False], ids=["noise", "no noise"])
def test_render_is_expose_of_the_signal_byte_for_byte(noise):
    """render() works on the blobs' pixels only; it is exactly the documented pipeline,
    also with clutter, occlusion, overlapping blobs and a blob cut by the border."""
    cfg = SimCameraConfig(
        noise=noise,
        seed=3,
        reflection_gain=0.4,
        reflection_plane_tob=(1.0, 0.0, 0.0, 8.0),  # close: reflections overlap the sources
        lamp_position_mm=(-150.0, -100.0, 1500.0),
        lamp_frame="camera",
        occluded_sources=(1,),
        occlusion_fraction=0.3,
        occlusion_angle_deg=30.0,
        psvs=DISTORTED,
    )
    r = Renderer(cfg)
    rng = np.random.default_rng(8)
    poses = [camera_T_desired(600.0) @ transform_from_x([165.0, 0, 0, 0, 0, 0])]  # at the border
    poses += [_random_camera_T_tob(rng) for _ in range(10)]
    for i, camera_T_tob in enumerate(poses):
        blobs = r.blobs(r.discs(camera_T_tob))
        signal = r.signal(blobs)
        idx, value = r.signal_pixels(blobs)
        assert np.all(np.diff(idx) > 0) and np.all(value > 0)
        np.testing.assert_array_equal(idx, np.flatnonzero(signal))
        np.testing.assert_array_equal(value, signal.ravel()[idx])
        expected = r.expose(signal, i)
        np.testing.assert_array_equal(r.render(camera_T_tob, frame_index=i), expected)


def test_blobs_follow_the_geometry_library():
    """project_discs writes eq. (2) and its Jacobian out for both views at once: the same
    centres and Jacobians as project_pinhole and projection_jacobian."""
    r = Renderer(SimCameraConfig())
    variants = (
        r.params,
        dataclasses.replace(r.params, skew=0.4),
        dataclasses.replace(r.params, u0_left=300.0, v0_left=250.0, v0_right=235.0, skew=0.3),
        dataclasses.replace(
            r.params, rotvec_right_deg=(0.2, -0.5, 0.1), rotvec_left_deg=(-0.3, 0.4, 1.0)
        ),
    )  # one principal point or one per view; with and without skew; rotated views
    rng = np.random.default_rng(4)
    for i in range(80):
        params = variants[i % 4]
        discs = r.discs(_random_camera_T_tob(rng))
        blobs = render_module.project_discs(params, discs, r.view_gains, 1.0, 0.7)
        for k in range(len(blobs)):
            camera = (params.right_camera, params.left_camera)[blobs.view[k]]
            d = blobs.disc[k]
            p = discs.centre_mm[d]
            np.testing.assert_allclose(blobs.centre_px[k], project_pinhole(camera, p), atol=1e-9)
            plane = discs.axes[d][:, :2] * discs.radius_mm[d]
            np.testing.assert_allclose(
                blobs.jac[k], projection_jacobian(camera, p) @ plane, rtol=1e-12, atol=1e-12
            )
