"""Issue 37 item 5: a guard against a gross regression of perception's speed, measured as
ratios to baselines timed in the same run, interleaved (``humanpt.bench.measure``), never
as an absolute time: a loaded machine slows the baselines as much as humanpt.

Each figure is the median thread CPU time per image over 150 images per case, 10 rounds
(what `humanpt bench perception` prints as images/s). The limits lie about half below what
this build measures at load average 5-7 (components/perception/README.md, "Speed": core
step 5.3x the naive OpenCV pipeline, the whole-image search 7.8x, tracking 1.05x the
whole-image search at 640x480 - the search is as cheap: both run the same compiled
detector, on the rows that hold a shape - and 2.2x at 1920x1200, the 1920x1200 tracking
rate 0.9-1.0x the 640x480 one), so that only a gross regression fails."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from humanpt.bench.measure import NAIVE, interleaved, perception_cases, tracking_sequence

WHOLE, TRACK, CORE = "search: whole image", "tracking: windows around the blobs", "core step (decode ... message)"


@pytest.fixture
def one_cv2_thread():
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # as the bench: OpenCV's own threads would measure the machine
    yield
    cv2.setNumThreads(threads)


def test_perception_against_its_in_run_baselines(one_cv2_thread):
    small = perception_cases(*tracking_sequence(640, 480, n=8))
    large = perception_cases(*tracking_sequence(1920, 1200, n=8), baselines=False)
    cases = {**{f"640 {k}": small[k] for k in (NAIVE, WHOLE, TRACK, CORE)},
             **{f"1920 {k}": large[k] for k in (WHOLE, TRACK)}}
    times = interleaved(cases, 150, rounds=10)
    cpu = {name: float(np.median(c)) for name, (c, _) in times.items()}
    figures = {
        "core step / naive pipeline (640x480)": cpu[f"640 {NAIVE}"] / cpu[f"640 {CORE}"],
        "whole image / naive pipeline (640x480)": cpu[f"640 {NAIVE}"] / cpu[f"640 {WHOLE}"],
        "tracking / whole image (640x480)": cpu[f"640 {WHOLE}"] / cpu[f"640 {TRACK}"],
        "tracking / whole image (1920x1200)": cpu[f"1920 {WHOLE}"] / cpu[f"1920 {TRACK}"],
        "tracking rate 1920x1200 / 640x480": cpu[f"640 {TRACK}"] / cpu[f"1920 {TRACK}"],
    }
    limits = {
        "core step / naive pipeline (640x480)": 2.0,
        "whole image / naive pipeline (640x480)": 3.0,
        "tracking / whole image (640x480)": 0.6,
        "tracking / whole image (1920x1200)": 1.2,
        "tracking rate 1920x1200 / 640x480": 0.6,
    }
    low = {k: f"{v:.2f} < {limits[k]}" for k, v in figures.items() if not v >= limits[k]}
    assert not low, f"perception regressed against its in-run baselines: {low} (all: {figures})"
