"""Shell side of the real camera: OpenCV VideoCapture from a device index or a video file,
a folder of images (:class:`ImageFolder`, replayed at ``camera.fps``), or a source named
``<scheme>:<address>`` opened by the module :data:`SOURCES` registers for its scheme
(``genicam:``: :mod:`humanpt.camera.genicam`, a GenICam camera through harvesters).

:class:`CaptureAdapter` is a live-shell adapter (``humanpt.runtime.live``): a thread grabs
frames, stamps each (the shared time base when the grab returns, or the source's own
capture stamp: ``shared_stamp_ns``) and hands it to the core as a ``capture`` input
(foxglove.RawImage, bgr8 or mono8). :func:`read_frames` is the same grabbing as a plain
generator, for offline use and tests.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

from humanpt.runtime.clock import CLOCK
from humanpt.runtime.registry import import_path
from humanpt.schemas.convert import image

from .config import GENICAM_SCHEME, CameraConfig

__all__ = ["IMAGE_SUFFIXES", "SOURCES", "CaptureAdapter", "ImageFolder", "capture_adapters", "capture_message",
           "open_capture", "read_frames", "request_settings", "setting_note"]

log = logging.getLogger("humanpt.camera")


def capture_message(frame: np.ndarray, stamp_ns: int, frame_id: str = "camera"):
    """An OpenCV frame ((H, W, 3) BGR or (H, W) grey, uint8) -> foxglove.RawImage."""
    encoding = "bgr8" if frame.ndim == 3 else "mono8"
    return image(np.ascontiguousarray(frame), stamp_ns, frame_id, encoding)


# What cv2.imread reads (lower-case suffixes; the match ignores case).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pnm", ".webp")


def _natural_key(path: Path) -> list:
    """img2 before img10: digit runs compare as numbers."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name.lower())]


class ImageFolder:
    """A folder of images read as a video at ``fps`` frames/s, in natural name order
    (``img2`` before ``img10``), with the subset of :class:`cv2.VideoCapture` the adapter uses
    (``read``, ``get(CAP_PROP_FPS)``, ``set(CAP_PROP_POS_FRAMES, 0)``, ``release``). A file
    that does not decode is skipped with an error naming it (``skipped`` lists them): a
    damaged image loses only itself."""

    def __init__(self, folder: str | Path, fps: float):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise OSError(f"image folder {str(folder)!r}: no such folder")
        self.files = sorted((f for f in self.folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES
                             and f.is_file()), key=_natural_key)
        if not self.files:
            raise OSError(f"image folder {str(folder)!r} holds no image ({', '.join(IMAGE_SUFFIXES)})")
        self.fps = float(fps)
        self.position = 0
        self.skipped: list[Path] = []

    def isOpened(self) -> bool:  # noqa: N802 (cv2.VideoCapture's name)
        return True

    def read(self) -> tuple[bool, np.ndarray | None]:
        while self.position < len(self.files):
            path = self.files[self.position]
            self.position += 1
            frame = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if frame is not None and frame.dtype == np.uint8 and frame.ndim in (2, 3):
                if frame.ndim == 3 and frame.shape[2] == 4:
                    frame = cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
                if frame.ndim == 2 or frame.shape[2] == 3:
                    return True, frame
            self.skipped.append(path)
            log.error("image folder: %s is not an 8-bit grey or colour image: skipped", path)
        return False, None

    def get(self, prop: int) -> float:
        return self.fps if prop == cv2.CAP_PROP_FPS else 0.0

    def set(self, prop: int, value: float) -> bool:
        if prop == cv2.CAP_PROP_POS_FRAMES:
            self.position = int(value)
            return True
        return False

    def release(self) -> None:
        pass


# scheme -> "module:class" of the source a ``<scheme>:<address>`` source opens; the class
# takes (config, stop event) and gives VideoCapture's read/get/set/release (and, when it
# knows the capture time better than the grab's return, ``shared_stamp_ns(host_ns)``).
SOURCES: dict[str, str] = {
    GENICAM_SCHEME: "humanpt.camera.genicam:GenICamCapture",
}


def _scheme(config: CameraConfig) -> str | None:
    head, sep, _ = config.source.strip().partition(":")
    return head if sep and head in SOURCES else None


def open_capture(config: CameraConfig, stop: threading.Event | None = None):
    """Open the configured source (a device, a video file, an image folder, or a source of
    :data:`SOURCES`); raises OSError naming it when it does not open. ``stop``: set when the
    caller closes (a source that waits for frames gives up then)."""
    scheme = _scheme(config)
    if scheme is not None:
        return import_path(SOURCES[scheme])(config, stop)
    index = config.device_index
    if index is None and Path(config.source).is_dir():
        if not config.fps:
            raise OSError(f"camera.source {config.source!r} is an image folder: set camera.fps "
                          "(frames/s; a folder has no frame rate of its own)")
        return ImageFolder(config.source, config.fps)
    cap = cv2.VideoCapture(index if index is not None else config.source)
    if not cap.isOpened():
        cap.release()
        what = f"camera device {config.source.strip()}" if config.is_device else f"video file {config.source!r}"
        raise OSError(f"cannot open {what}")
    if config.is_device:
        for note in request_settings(cap, config):
            log.warning("camera %s: %s", config.source.strip(), note)
    return cap


_SETTINGS = (("width_px", "CAP_PROP_FRAME_WIDTH", 0.5), ("height_px", "CAP_PROP_FRAME_HEIGHT", 0.5),
             ("fps", "CAP_PROP_FPS", 0.01), ("exposure", "CAP_PROP_EXPOSURE", 0.01), ("gain", "CAP_PROP_GAIN", 0.01))


def request_settings(cap, config: CameraConfig) -> list[str]:
    """Ask the device for each setting the config gives (not 0) and read it back: one
    note per setting the driver did not take (it refused it, or gives another value), so
    the user knows what the camera really does. (A manual exposure first turns V4L2's
    auto exposure off: CAP_PROP_AUTO_EXPOSURE 1 is V4L2's manual mode.)"""
    notes = []
    for key, prop_name, tolerance in _SETTINGS:
        wanted = getattr(config, key)
        if not wanted:
            continue
        prop = getattr(cv2, prop_name)
        if key == "exposure" and not cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1):
            notes.append("the driver did not turn auto exposure off")
        accepted = cap.set(prop, wanted)
        note = setting_note(key, wanted, accepted, cap.get(prop), tolerance)
        if note:
            notes.append(note)
    return notes


def setting_note(key: str, wanted: float, accepted: bool, got: float, tolerance: float,
                 who: str = "the driver", why: str = "") -> str | None:
    """The note on one setting asked of a camera (None: it took it): refused (``why``, when
    known), or another value read back than asked (beyond ``tolerance``, relative)."""
    if not accepted:
        return f"{key} {wanted:g} refused by {who} ({why + '; ' if why else ''}it gives {got:g})"
    if abs(got - wanted) > tolerance * max(1.0, abs(wanted)):
        return f"{key} {wanted:g} asked, {who} gives {got:g}"
    return None


def _stamp(cap, host_ns: int) -> int:
    """The frame's capture stamp: the source's own (a camera's hardware clock mapped to the
    shared time base) when it has one, else ``host_ns``, the grab's return."""
    own = getattr(cap, "shared_stamp_ns", None)
    return own(host_ns) if own is not None else host_ns


def read_frames(
    config: CameraConfig, clock: Callable[[], int] = time.time_ns, max_frames: int | None = None
) -> Iterator[tuple[int, np.ndarray]]:
    """(stamp ns, frame) for every frame of the source (no pacing, no looping), stamped by
    ``clock`` when each grab returns."""
    cap = open_capture(config)
    try:
        n = 0
        while max_frames is None or n < max_frames:
            ok, frame = cap.read()
            stamp = clock()
            if not ok:
                return
            n += 1
            yield _stamp(cap, stamp), frame
    finally:
        cap.release()


class CaptureAdapter:
    """Grabs frames in a thread and ``put``\\ s them as ``capture`` inputs (see module)."""

    topics_out: tuple[str, ...] = ()

    def __init__(self, config: CameraConfig, clock: Callable[[], int] = CLOCK.now_ns, topic: str = "capture"):
        self.config = config
        self.clock = clock
        self.topic = topic  # "capture", or "capture_right" for a stereo pair's right camera
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames = 0
        self.errors = 0
        self.finished = threading.Event()  # a file played to its end (no loop)
        self.capture = None  # the open source (the capture thread's; None while closed)

    def start(self, put: Callable[[str, object], None]) -> None:
        self._thread = threading.Thread(
            target=self._loop, args=(put,), name="camera-capture", daemon=True
        )
        self._thread.start()

    def write(self, topic: str, msg) -> None:  # the camera has no local outputs
        pass

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def _loop(self, put) -> None:
        cfg = self.config
        is_file = not cfg.is_device
        cap = None
        next_due = 0.0
        while not self._stop.is_set():
            if cap is None:
                try:
                    cap = self.capture = open_capture(cfg, self._stop)
                except OSError as e:
                    self.errors += 1
                    log.error("%s; retrying in %.1f s", e, cfg.reopen_s)
                    self._stop.wait(cfg.reopen_s)
                    continue
                period = (
                    1.0 / cap.get(cv2.CAP_PROP_FPS)
                    if is_file and cap.get(cv2.CAP_PROP_FPS) > 0
                    else 0.0
                )
                next_due = time.monotonic()
            ok, frame = cap.read()
            stamp = self.clock()
            if not ok:
                if self._stop.is_set():  # closing (a source that waits gives up then)
                    break
                if is_file and cfg.loop and self.frames:
                    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
                    continue
                cap.release()
                cap = self.capture = None
                if is_file and not cfg.loop:
                    log.info("video file %s: end after %d frames", cfg.source, self.frames)
                    self.finished.set()
                    return
                self.errors += 1
                log.error("camera %s: grab failed; reopening in %.1f s", cfg.source, cfg.reopen_s)
                self._stop.wait(cfg.reopen_s)
                continue
            self.frames += 1
            put(self.topic, capture_message(frame, _stamp(cap, stamp)))
            if is_file and cfg.pace and period:
                next_due += period
                self._stop.wait(max(0.0, next_due - time.monotonic()))
        if cap is not None:
            self.capture = None
            cap.release()


def capture_adapters(config: CameraConfig) -> list[CaptureAdapter]:
    """The registry's adapter factory for the ``camera`` component. A source that is a path
    must exist; a folder must hold images and come with ``camera.fps``; a GenICam source
    needs its extra installed and its producer file (OSError naming it: the component stops
    at start; a device that does not open, a GenICam camera not found, is retried: a camera
    may be plugged in later)."""
    cameras = [(config, "capture", "source")]
    if config.source_right.strip():  # a stereo pair: the right camera, same settings
        cameras.append((config.right(), "capture_right", "source_right"))
    for cam, _, key in cameras:
        if cam.genicam is not None:  # the library and the producer file must be there; the camera may come later
            from .genicam import require_library

            require_library()
            if not Path(cam.genicam[0]).is_file():
                raise OSError(f"camera.{key} {cam.source!r}: no GenTL producer file {cam.genicam[0]!r} (a .cti: "
                              "the camera vendor's SDK installs one)")
        elif not cam.is_device:
            path = Path(cam.source)
            if path.is_dir():
                open_capture(cam)  # refuses an empty folder or a missing frame rate now
            elif not path.exists():
                raise OSError(f"camera.{key} {cam.source!r}: no such video file, image folder or device")
    return [CaptureAdapter(cam, topic=topic) for cam, topic, _ in cameras]
