"""A picture of a run: rerun's viewer draws an .rrd (``humanpt view --save``'s file) with the
view's blueprint, its time cursor at the end, and saves the window as a PNG
(``rerun FILE.rrd LAYOUT.rbl --screenshot-to PNG --window-size WxH``: the viewer's own
screenshot, the same picture a user sees).

The viewer needs a window and a graphics adapter. Without a display (DISPLAY and
WAYLAND_DISPLAY unset) it runs inside ``xvfb-run`` when that is installed; a software Vulkan
adapter does (Debian: ``apt install xvfb mesa-vulkan-drivers``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from humanpt.viz.blueprint import blueprint
from humanpt.viz.sink import has_display

__all__ = ["ScreenshotError", "parse_size", "screenshot"]


class ScreenshotError(RuntimeError):
    """The picture could not be taken; the message says why and what to install."""


def parse_size(text: str) -> tuple[int, int]:
    """``"1600x900"`` -> (1600, 900); each from 320 to 7680 px."""
    parts = text.lower().split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"size {text!r}: give WIDTHxHEIGHT in px, e.g. 1600x900") from None
    if not (320 <= width <= 7680 and 320 <= height <= 7680):
        raise ValueError(f"size {text!r}: each side from 320 to 7680 px")
    return width, height


def _viewer() -> str:
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    if not Path(exe).exists():
        raise ScreenshotError("the rerun viewer is not installed (pip install rerun-sdk)")
    return exe


def screenshot(rrd: str | Path, png: str | Path, *, application_id: str, size_px: tuple[int, int] = (1600, 900),
               timeout_s: float = 300.0) -> Path:
    """Draw ``rrd`` and save the window as ``png`` (its folder is made); returns the path.
    :class:`ScreenshotError` when there is no display and no ``xvfb-run``, when the viewer
    fails (its last lines, and what to install) or writes nothing."""
    rrd, png = Path(rrd), Path(png)
    if not rrd.is_file():
        raise ScreenshotError(f"{rrd}: no such .rrd file")
    width, height = size_px
    command = [_viewer(), str(rrd), "", "--screenshot-to", str(png.resolve()), "--window-size", f"{width}x{height}"]
    if not has_display():
        xvfb = shutil.which("xvfb-run")
        if xvfb is None:
            raise ScreenshotError("no display here (DISPLAY/WAYLAND_DISPLAY unset) and no xvfb-run: install it and a "
                                  "Vulkan driver (Debian: apt install xvfb mesa-vulkan-drivers), or run where a "
                                  "display is")
        # a screen larger than the window: the pointer (at the screen's centre) stays off the picture
        command = [xvfb, "-a", "-s", f"-screen 0 {2 * width + 64}x{2 * height + 64}x24", *command]
    png.parent.mkdir(parents=True, exist_ok=True)
    png.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory(prefix="humanpt-shot-") as tmp:
        layout = Path(tmp) / "picture.rbl"
        blueprint(picture=True).save(application_id, str(layout))
        command[command.index("")] = str(layout)
        env = {**os.environ, "XDG_RUNTIME_DIR": os.environ.get("XDG_RUNTIME_DIR") or tmp}
        try:
            p = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s, env=env,
                               stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            raise ScreenshotError(f"the viewer did not finish the picture in {timeout_s:g} s") from None
    if p.returncode != 0 or not png.is_file():
        tail = "\n".join((p.stderr or p.stdout).strip().splitlines()[-3:])
        hint = (" (no graphics adapter: install a Vulkan driver, Debian: mesa-vulkan-drivers)"
                if "adapter" in tail.lower() else "")
        raise ScreenshotError(f"the viewer exited with status {p.returncode} and no picture{hint}:\n{tail}")
    return png
