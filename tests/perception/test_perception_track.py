"""Tracking (issue 37, item 2): the next image is measured only in windows around the blobs
the last FULL measurement predicts (one merged window or several, measured in one compiled
call on the image's own pixels); it finds what a search of the whole image finds there (same centres,
order, pairs, points), leaves out what lies outside the windows, and does not depend on the
image's size."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanpt.geometry.rig import Rig
from humanpt.perception import Perception, PerceptionConfig
from humanpt.perception.blobs import windows_around
from humanpt.perception.correspondence import FULL
from humanpt.perception.weighted import detect_weighted
from humanpt.sim_camera import Renderer
from humanpt.testing.perception_eval import clutter_cases, random_cases


def _anchor(result):
    used = result.paired.pairs.ravel()
    return result.blobs.uv_px[used], result.blobs.size_px[used]


def _same(a, b):
    """Two results agree: the paired blobs' centres (to 1e-9 px), the status, points (1e-9 mm)
    and blob checks; when both found the same number of blobs, all of them in the same order
    and the same pair indices (what a message carries)."""
    np.testing.assert_allclose(a.blobs.uv_px[a.match.pairs], b.blobs.uv_px[b.match.pairs], rtol=0, atol=1e-9)
    if len(a.blobs) == len(b.blobs):
        np.testing.assert_allclose(a.blobs.uv_px, b.blobs.uv_px, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(a.match.pairs, b.match.pairs)
    assert a.match.status == b.match.status
    np.testing.assert_allclose(a.match.camera_p_mm, b.match.camera_p_mm, rtol=0, atol=1e-9)
    assert (a.check is None) == (b.check is None)
    if a.check is not None:
        assert a.check.degraded == b.check.degraded
        np.testing.assert_allclose(a.check.brightness, b.check.brightness, rtol=0, atol=1e-9)


def _render(case, width=640, height=480):
    sim = case.sim
    if (width, height) != (640, 480):
        sim = dataclasses.replace(sim, psvs=dataclasses.replace(
            sim.psvs, image_width_px=width, image_height_px=height, u0=width / 2.0, v0=height / 2.0))
    return Renderer(sim).render(case.camera_T_tob, frame_index=case.frame_index), Rig(psvs=sim.psvs)


@pytest.mark.parametrize("size, margin_px", [((640, 480), 40), ((1920, 1200), 40), ((640, 480), 10)])
def test_tracking_finds_what_the_whole_image_search_finds(size, margin_px):
    # at the default 40 px margin the six windows merge into one, measured on the image's own
    # pixels; at 10 px they stay apart: both are checked
    cases = random_cases(12, seed=5) + [c for c in clutter_cases(12, seed=5) if c.name != "lamp"]
    checked = same_count = 0
    windows = []
    for case in cases:
        gray, rig = _render(case, *size)
        p = Perception(PerceptionConfig(roi_margin_px=margin_px), rig)
        whole = p.measure(gray)
        if whole.paired.status != FULL:
            continue
        uv, blob_size = _anchor(whole)
        windows.append(len(windows_around(uv, margin_px + blob_size.max(), *size)))
        tracked = p.track(gray, uv, blob_size)
        _same(tracked, whole)
        same_count += len(tracked.blobs) == len(whole.blobs)
        # the region searched is the windows' bounding box, far smaller than the image
        u0, v0, u1, v1 = tracked.region
        assert (u1 - u0) * (v1 - v0) < 0.5 * 640 * 480
        checked += 1
    assert checked >= 15 and same_count >= 12
    if margin_px == 40:
        assert sum(n == 1 for n in windows) >= 0.8 * len(windows)
    else:
        assert sum(n > 1 for n in windows) >= 0.8 * len(windows)


def test_a_lamp_between_the_blobs_but_outside_every_window_is_not_measured():
    # (with the default 40 px margin the windows of a PSVS image at 450-900 mm merge into
    # about the blobs' bounding box; 10 px keeps them apart)
    case = random_cases(1, seed=7)[0]
    gray, rig = _render(case)
    p = Perception(PerceptionConfig(roi_margin_px=10), rig)
    whole = p.measure(gray)
    assert whole.paired.status == FULL and len(whole.blobs) == 6
    uv, size = _anchor(whole)
    pad = p.config.roi_margin_px + size.max()
    # a point of the blobs' bounding box (what the region of interest was before) 8 px or
    # more outside every window (each blob's, grown by the margin and the largest blob, the
    # overlapping ones merged)
    box = p.roi_around(uv, size)
    grid = np.stack(np.meshgrid(np.arange(box[0] + 8, box[2] - 8), np.arange(box[1] + 8, box[3] - 8)), -1)
    grid = grid.reshape(-1, 2)
    far = np.ones(len(grid), bool)
    for u0, v0, u1, v1 in windows_around(uv, pad, 640, 480):
        far &= ~((grid[:, 0] > u0 - 8) & (grid[:, 0] < u1 + 8) & (grid[:, 1] > v0 - 8) & (grid[:, 1] < v1 + 8))
    assert far.any(), "no point of the bounding box outside the windows"
    u, v = grid[far][0]
    lamp = gray.copy()
    yy, xx = np.mgrid[0 : gray.shape[0], 0 : gray.shape[1]]
    lamp[(xx - u) ** 2 + (yy - v) ** 2 <= 9] = 200
    assert len(p.measure(lamp, box).blobs) == 7  # the bounding box sees it
    tracked = p.track(lamp, uv, size)
    assert len(tracked.blobs) == 6 and tracked.match.status == FULL
    assert np.abs(tracked.blobs.uv_px - [u, v]).max(axis=1).min() > pad
    _same(tracked, whole)


def test_one_merged_window_measures_only_its_own_pixels():
    # at the default margin the six windows merge into one, which the detector measures in
    # place on the image: a lamp 20 px outside it (inside the image) is not measured
    case = random_cases(1, seed=7)[0]
    gray, rig = _render(case)
    p = Perception(PerceptionConfig(), rig)
    whole = p.measure(gray)
    uv, size = _anchor(whole)
    (u0, v0, u1, v1), = windows_around(uv, p.config.roi_margin_px + size.max(), 640, 480)
    u, v = (u1 + 20, (v0 + v1) // 2) if u1 + 25 < 640 else (u0 - 20, (v0 + v1) // 2)
    lamp = gray.copy()
    yy, xx = np.mgrid[0:480, 0:640]
    lamp[(xx - u) ** 2 + (yy - v) ** 2 <= 9] = 200
    assert len(p.measure(lamp).blobs) == len(whole.blobs) + 1  # the whole image sees it
    tracked = p.track(lamp, uv, size)
    assert tracked.region == (u0, v0, u1, v1)
    _same(tracked, whole)
    assert len(tracked.blobs) == len(whole.blobs)


def test_overlapping_windows_merge_into_their_bounding_box():
    # 10 px half size: (20, 20) and (35, 25) overlap, (100, 100) does not; clipped at 0 and
    # at the image's 120 x 110
    w = windows_around(np.array([[20.0, 20.0], [35.0, 25.0], [100.0, 100.0], [5.5, 90.0]]), 10.0, 120, 110)
    assert sorted(w) == sorted([(10, 10, 46, 36), (90, 90, 111, 110), (0, 80, 17, 101)])


def test_several_windows_in_one_call_find_what_each_window_alone_finds():
    # the level is T (the background is far below it), so the one histogram of all the
    # windows changes nothing: every window's blobs, in the whole image's order (descending
    # v, then u, of each shape's first pixel)
    case = random_cases(1, seed=7)[0]
    gray, _ = _render(case)
    whole = detect_weighted(gray, (0, 0, 640, 480), threshold=60)
    assert len(whole) == 6
    windows = windows_around(whole.uv_px, 14.0, 640, 480)
    assert len(windows) >= 4
    together = detect_weighted(gray, windows, threshold=60, gap_px=30)
    alone = [detect_weighted(gray, w, threshold=60) for w in windows]
    assert len(together) == sum(len(b) for b in alone) == 6
    expected = np.concatenate([b.uv_px for b in alone])
    np.testing.assert_allclose(together.uv_px, whole.uv_px, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.sort(together.uv_px, axis=0), np.sort(expected, axis=0), rtol=0, atol=1e-9)
    # windows reaching out of the image are clipped to it
    out = detect_weighted(gray, [(-50, -50, 700, 530)], threshold=60)
    np.testing.assert_allclose(out.uv_px, whole.uv_px, rtol=0, atol=0)


def test_a_blob_cut_by_its_window_is_rejected_as_one_cut_by_the_region():
    case = random_cases(1, seed=7)[0]
    gray, rig = _render(case)
    p = Perception(PerceptionConfig(roi_margin_px=0), rig)
    whole = p.measure(gray)
    uv, size = _anchor(whole)
    # windows of half size 2 px: every blob (~8 px across) touches its window's border
    tiny = p.track(gray, uv, np.full_like(size, 2.0))
    assert len(tiny.blobs) == 0 and tiny.match.status != FULL
