"""``humanpt view RUN --screenshot FILE.png`` (issue 36 item 6: a picture of the rerun view):
the viewer's own screenshot of the golden arc run, and each refusal with its reason."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from humanpt.viz.screenshot import ScreenshotError, parse_size, screenshot
from humanpt.viz.sink import has_display
from tests.conftest import ROOT, run_cli_here

ARC = ROOT / "recordings" / "arc"


@pytest.mark.parametrize("text, why", [("1600", "WIDTHxHEIGHT"), ("axb", "WIDTHxHEIGHT"), ("100x900", "from 320"),
                                       ("1600x9000", "from 320")])
def test_a_bad_size_is_refused(text, why):
    with pytest.raises(ValueError, match=why):
        parse_size(text)
    assert parse_size("1600X900") == (1600, 900)


def test_the_cli_refuses_before_drawing(tmp_path):
    r = run_cli_here("view", str(ARC), "--screenshot", str(tmp_path / "a.jpg"))
    assert r.returncode != 0 and "is a .png file" in r.stderr and not (tmp_path / "a.jpg").exists()
    r = run_cli_here("view", str(ARC), "--screenshot", str(tmp_path / "a.png"), "--size", "10x10")
    assert r.returncode != 0 and "from 320 to 7680" in r.stderr and not (tmp_path / "a.png").exists()
    r = run_cli_here("view", str(ARC), "--screenshot", str(tmp_path / "a.png"), "--save", str(tmp_path / "a.rrd"))
    assert r.returncode == 2 and "not allowed with" in r.stderr


def test_no_display_and_no_xvfb_says_what_to_install(tmp_path, monkeypatch):
    rrd = tmp_path / "x.rrd"
    rrd.write_bytes(b"")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(shutil, "which", lambda name, *a, **k: None)  # nothing on PATH (rerun: beside python)
    with pytest.raises(ScreenshotError, match="apt install xvfb mesa-vulkan-drivers"):
        screenshot(rrd, tmp_path / "x.png", application_id="humanpt")
    with pytest.raises(ScreenshotError, match="no such .rrd file"):
        screenshot(tmp_path / "missing.rrd", tmp_path / "x.png", application_id="humanpt")


@pytest.mark.live  # (the viewer is a process)
@pytest.mark.timeout(600)
@pytest.mark.skipif(not has_display() and shutil.which("xvfb-run") is None,
                    reason="no display and no xvfb-run (Debian: apt install xvfb mesa-vulkan-drivers)")
def test_a_picture_of_the_arc_run(tmp_path):
    png = tmp_path / "pictures" / "arc.png"
    r = run_cli_here("view", str(ARC), "--screenshot", str(png), "--size", "800x450", "--no-progress")
    assert r.returncode == 0, r.stderr
    assert f"the picture {png}" in r.stdout
    img = cv2.imread(str(png))
    # the window's size in logical points, saved at the display's pixel ratio (1 or 2)
    assert img.shape[:2] in ((450, 800), (900, 1600)), img.shape
    # a drawn view, not a blank window: dark panels with bright lines, text and plots
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    assert np.mean(grey < 40) > 0.3 and np.mean(grey > 150) > 0.005
    assert not list(Path(tmp_path).glob("*.rrd"))  # the .rrd was scratch
