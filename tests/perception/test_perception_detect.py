"""The two detectors on images drawn with numpy: the paper's cross-template seeds and shape
means, and the default method's weighted centroids and shape checks."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from humanpt.perception import (
    background_and_noise,
    cross_kernel,
    detect_paper,
    detect_weighted,
    find_shapes,
    pair_by_scan_line,
    seed_mask,
)
from tests.perception.drawing import draw

FULL = (0, 0, 640, 480)


def _nearest_errors(found_uv, true_uv):
    """(found - nearest true) for every found centre, and how many true ones were found."""
    found_uv = np.asarray(found_uv).reshape(-1, 2)
    true_uv = np.asarray(true_uv).reshape(-1, 2)
    if len(found_uv) == 0:
        return np.zeros((0, 2)), 0
    d = np.linalg.norm(found_uv[:, None] - true_uv[None], axis=-1)
    j = d.argmin(axis=1)
    return found_uv - true_uv[j], len(set(j.tolist()))


def _separated_centres(rng, n, min_sep=40.0):
    while True:
        c = rng.uniform([40, 40], [600, 440], size=(n, 2))
        d = np.linalg.norm(c[:, None] - c[None], axis=-1) + 1e9 * np.eye(n)
        if d.min() > min_sep:
            return c


# --------------------------------------------------------------------------- paper


def test_the_cross_template_is_figure_6():
    k = cross_kernel(9).astype(int)
    assert k.shape == (9, 9) and int(k.sum()) == 17  # 9 + 9 - 1 pixels of the 81
    assert k[4].all() and k[:, 4].all() and k.sum() - k[4].sum() - k[:, 4].sum() + 1 == 0


def test_seeds_reject_isolated_noise_pixels_and_thin_lines():
    binary = np.zeros((100, 100), np.uint8)
    rng = np.random.default_rng(3)
    ys, xs = rng.integers(0, 100, 300), rng.integers(0, 100, 300)
    binary[ys, xs] = 255  # salt noise: 3 % of the pixels
    binary[10, 5:95] = 255  # a one-pixel line
    binary[20:23, 5:95] = 255  # a three-pixel band: no vertical arm of 9
    cv2.circle(binary, (60, 60), 6, 255, -1)  # a 13-px disc
    seeds = seed_mask(binary, 9)
    ys, xs = np.nonzero(seeds)
    assert len(ys) > 0
    assert np.all(np.hypot(xs - 60, ys - 60) <= 2.5)  # only the disc's centre pixels


def test_paper_detector_finds_discs_not_noise_and_the_centre_is_the_shape_mean():
    centres = np.array([[100.3, 120.6], [400.7, 300.2], [250.1, 50.9]])
    img = draw([(u, v, 6.0, 180) for u, v in centres], noise_dn=0.6, seed=1)
    rng = np.random.default_rng(0)
    img[rng.integers(0, 480, 400), rng.integers(0, 640, 400)] = 255  # hot pixels
    blobs = detect_paper(img, 60, (9,), FULL)
    assert len(blobs) == 3
    assert blobs.rejected >= 200  # hot pixels (some touch each other): shapes without a seed
    err, found = _nearest_errors(blobs.uv_px, centres)
    assert found == 3 and np.abs(err).max() < 0.3
    # the centre is exactly the mean of the thresholded shape's pixel locations
    _, binary = cv2.threshold(img, 60, 255, cv2.THRESH_BINARY)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(binary, connectivity=8)
    big = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] > 20)[1:]
    expected = sorted(map(tuple, np.round(cents[big], 9)))
    assert sorted(map(tuple, np.round(blobs.uv_px, 9))) == expected


def test_small_shapes_need_the_5x5_cross_as_the_appendix_says():
    # 3-px radius discs are ~7 px across: no 9 x 9 cross fits, the 5 x 5 one does
    centres = np.array([[100.5, 100.5], [300.0, 200.0]])
    img = draw([(u, v, 3.0, 180) for u, v in centres], blur_sigma_px=0.0)
    assert len(detect_paper(img, 60, (9,), FULL)) == 0
    assert len(detect_paper(img, 60, (9, 5), FULL)) == 2


def test_find_shapes_measures_exact_pixel_counts_and_means():
    binary = np.zeros((60, 80), np.uint8)
    binary[10:15, 10:20] = 255
    binary[30:40, 50:53] = 255
    binary[31:39, 51] = 0  # a hole: not the shape's pixels
    shapes = find_shapes(binary)
    order = np.argsort(shapes.x)
    assert shapes.area[order].tolist() == [50, 30 - 8]
    assert np.allclose(shapes.centroid[order[0]], (14.5, 12.0))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_find_shapes_agrees_with_opencv_on_random_shapes(seed):
    # random specks, bars and discs (touching ones merge, 8-connected): every shape's pixel
    # count, box and mean as cv2.connectedComponentsWithStats gives them, and the shapes
    # are cv2.findContours' outermost ones (RETR_EXTERNAL), in descending raster order
    rng = np.random.default_rng(seed)
    binary = np.zeros((120, 160), np.uint8)
    binary[rng.integers(0, 120, 150), rng.integers(0, 160, 150)] = 255
    for _ in range(12):
        cv2.circle(binary, (int(rng.integers(0, 160)), int(rng.integers(0, 120))), int(rng.integers(1, 9)), 255, -1)
    cv2.circle(binary, (80, 60), 20, 255, 3)  # a ring ...
    binary[55:65, 75:85] = 0
    binary[58:62, 78:82] = 255  # ... with two specks in its hole: not outermost shapes
    binary[56, 76] = 255
    binary[40, 60] = 255  # inside the ring's box, outside the ring: an outermost shape
    shapes = find_shapes(binary)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    # (a contour starts at its shape's first pixel in raster order)
    assert sorted(shapes.first.tolist()) == sorted(c[0, 0].tolist() for c in contours)
    _, labels, stats, cents = cv2.connectedComponentsWithStats(binary, connectivity=8)
    assert len(shapes) < len(stats) - 1  # the speck in the ring's hole is a component, not a shape
    firsts = shapes.first.tolist()
    assert firsts == sorted(firsts, key=lambda uv: (uv[1], uv[0]), reverse=True)
    for i, (u, v) in enumerate(firsts):
        k = labels[v, u]
        assert (shapes.x[i], shapes.y[i], shapes.w[i], shapes.h[i], shapes.area[i]) == tuple(stats[k, :5])
        np.testing.assert_allclose(shapes.centroid[i], cents[k], rtol=0, atol=1e-12)
        x, y, w, h = stats[k, :4]
        np.testing.assert_array_equal(shapes.masks[i], labels[y : y + h, x : x + w] == k)


@pytest.mark.parametrize("density", [0.4, 0.45, 0.5])
def test_only_the_outermost_shapes_as_opencv_finds_them(density):
    # nested rings, a bar across the whole image above a U (a hole closed by the bar), and
    # dense salt noise (shapes in holes of noise shapes): the outermost shapes are
    # cv2.findContours' RETR_EXTERNAL ones, each starting at its first pixel
    rng = np.random.default_rng(int(density * 100))
    binary = np.where(rng.random((90, 130)) < density, 255, 0).astype(np.uint8)
    for r in (30, 22, 14, 6):
        cv2.circle(binary, (45, 45), r, 255, 2)
        cv2.circle(binary, (45, 45), r - 2, 0, 2)
    binary[60, :] = 255
    binary[60:80, 95] = 255
    binary[60:80, 120] = 255
    binary[80, 95:121] = 255
    binary[62:78, 97:119] = 0
    binary[70, 108] = 255  # in the U's hole
    shapes = find_shapes(binary)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    _, _, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    assert len(contours) < len(stats) - 1 <= 256  # some shapes lie in holes of others
    assert sorted(shapes.first.tolist()) == sorted(c[0, 0].tolist() for c in contours)


def test_the_detector_refuses_an_image_it_cannot_read_safely():
    with pytest.raises(ValueError, match="uint8"):
        detect_weighted(np.zeros((48, 64), np.float32), FULL, threshold=60)
    with pytest.raises(ValueError, match="mask"):
        detect_weighted(np.zeros((48, 64), np.uint8), FULL, threshold=60, keep=np.zeros((48, 63), np.uint8))


def test_scan_line_pairing_pairs_neighbours_in_v_and_orders_by_u():
    uv = np.array([[400.0, 100.2], [260.0, 100.0], [300.0, 250.0], [440.0, 250.4], [10.0, 400.0]])
    pairs = pair_by_scan_line(uv, 3.0)
    assert pairs.tolist() == [[1, 0], [2, 3]]  # right view = smaller u; the loner is unpaired


# --------------------------------------------------------------------------- weighted


def test_background_and_noise_from_the_histogram():
    rng = np.random.default_rng(0)
    img = np.clip(np.rint(rng.normal(20.0, 2.0, (480, 640))), 0, 255).astype(np.uint8)
    img[100:140, 100:140] = 200  # a bright patch does not move the median
    bg, sigma = background_and_noise(img)
    assert abs(bg - 20) <= 1 and 1.0 <= sigma <= 3.0


@pytest.mark.parametrize("radius", [2.5, 3.9, 6.0])
def test_weighted_centroids_are_subpixel_accurate_on_drawn_discs(radius):
    rng = np.random.default_rng(int(radius * 10))
    errs, errs_paper = [], []
    for k in range(20):
        c = _separated_centres(rng, 6)
        img = draw([(u, v, radius, 190) for u, v in c], noise_dn=0.64, seed=k)
        blobs = detect_weighted(img, FULL, threshold=60)
        err, found = _nearest_errors(blobs.uv_px, c)
        assert found == 6 and len(blobs) == 6
        errs.append(err)
        err_p, _ = _nearest_errors(detect_paper(img, 60, (9, 5), FULL).uv_px, c)
        errs_paper.append(err_p)
    rms = float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    rms_paper = float(np.sqrt(np.mean(np.concatenate(errs_paper) ** 2)))
    assert rms < 0.012, rms
    assert rms_paper > 2 * rms  # the shape mean suffers from pixel locking


def test_weighted_shape_checks_reject_noise_and_clutter():
    img = draw([(200.3, 200.6, 4.0, 190)], noise_dn=0.6)
    img[50, 50] = 255  # a hot pixel: below the area limit
    img[300:302, 100:160] = 200  # a scratch: far too elongated
    img[400:404, 500:504] = 32  # a faint square: below the contrast limit (with T = 30)
    cv2.circle(img, (500, 100), 35, 220, -1)  # a lamp: larger than any source can be
    img[240:250, 0:8] = 200  # touching the border: its centre would be biased
    blobs = detect_weighted(img, FULL, threshold=30, max_radius_px=20.0)
    assert len(blobs) == 1
    assert np.allclose(blobs.uv_px[0], (200.3, 200.6), atol=0.03)
    assert blobs.rejected >= 4
    assert 0.8 < blobs.size_px[0] / 8.0 < 1.25 and blobs.elongation[0] < 1.2


def test_weighted_measures_only_the_region_and_reports_whole_image_pixels():
    centres = [(100.25, 100.5), (500.75, 400.25)]
    img = draw([(u, v, 4.0, 190) for u, v in centres], noise_dn=0.5)
    blobs = detect_weighted(img, (400, 300, 640, 480), threshold=60)
    assert len(blobs) == 1 and np.allclose(blobs.uv_px[0], centres[1], atol=0.03)


def test_weighted_ignores_masked_pixels_and_keeps_working_on_a_background_gradient():
    centres = np.array([[150.4, 150.2], [450.6, 330.7]])
    img = draw([(u, v, 4.0, 150) for u, v in centres], noise_dn=0.6).astype(float)
    img += np.linspace(0, 40, 640)[None, :]  # ambient glow across the image
    img = np.clip(img, 0, 255).astype(np.uint8)
    keep = np.full(img.shape, 255, np.uint8)
    keep[300:360, 420:480] = 0
    masked = cv2.bitwise_and(img, keep)
    blobs = detect_weighted(masked, FULL, threshold=60, keep=keep)
    assert len(blobs) == 1
    assert np.allclose(blobs.uv_px[0], centres[0], atol=0.03)
