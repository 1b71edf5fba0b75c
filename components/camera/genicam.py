"""GenICam machine-vision cameras: ``source = "genicam:<producer.cti>[#<device>]"``.

A GenTL producer (the ``.cti`` library a camera's vendor ships: Basler pylon, Allied
Vision Vimba, Teledyne Spinnaker, MATRIX VISION mvGenTL...) driven by `harvesters`
(the ``[genicam]`` extra: ``pip install "humanpt[genicam]"``). :class:`GenICamCapture`
has the subset of :class:`cv2.VideoCapture` the adapter uses (``read``, ``get``, ``set``,
``release``), so the capture loop of :mod:`humanpt.camera.capture` runs it as it runs the
OpenCV sources; it adds :meth:`GenICamCapture.shared_stamp_ns`, the frame's capture stamp.

Stamps: a buffer with the camera's own timestamp (GenTL ``BUFFER_INFO_TIMESTAMP_NS``, or
ticks over the device's tick frequency) is stamped by :class:`DeviceClockMap`: the device
time plus the smallest (shared time base at fetch - device time) over the last
``window_ns`` of device time. The frames' spacing is the camera's own (no host jitter);
the whole lags the exposure by the transfer latency of the quickest frame of the window (a
constant, not jitter), and a stamp is never later than the frame's arrival. A buffer
without one (many USB cameras, the test producer) is stamped with the shared time base when
the fetch returns, as the OpenCV sources are.
"""

from __future__ import annotations

import importlib
import logging
import threading
import time
from collections import deque
from pathlib import Path

import cv2
import numpy as np

from humanpt.runtime.clock import CLOCK

from .config import GENICAM_PIXEL_FORMATS, CameraConfig

__all__ = ["DeviceClockMap", "GenICamCapture", "device_time_ns", "frame_from_buffer", "request_genicam_settings",
           "require_library"]

log = logging.getLogger("humanpt.camera")

EXTRA = 'pip install "humanpt[genicam]" (harvesters and genicam)'

# PFNC name -> the cv2 conversion to an OpenCV frame (BGR, or None: grey as it is)
_TO_BGR = {"Mono8": None, "BGR8": None, "RGB8": cv2.COLOR_RGB2BGR, "RGBa8": cv2.COLOR_RGBA2BGR,
           "BGRa8": cv2.COLOR_BGRA2BGR}
_CHANNELS = {"Mono8": 1, "RGB8": 3, "BGR8": 3, "RGBa8": 4, "BGRa8": 4}
assert set(_TO_BGR) == set(GENICAM_PIXEL_FORMATS)

_FETCH_S = 0.1  # one fetch's wait: how soon a stop (the component closing) is seen


class UnsupportedFormat(OSError):
    """The camera delivers a pixel format the pipeline does not read."""


def require_library() -> None:
    """Raise OSError saying which extra to install when harvesters is missing."""
    try:
        importlib.import_module("harvesters.core")
    except ImportError as e:
        raise OSError(f"a GenICam camera needs the optional extra: {EXTRA} ({e})") from None


def frame_from_buffer(data: np.ndarray, width: int, height: int, data_format: str) -> np.ndarray:
    """One buffer's pixels (flat, uint8) -> an OpenCV frame: (H, W) grey for Mono8, else
    (H, W, 3) BGR (the core turns it into mono8 as it does OpenCV's frames). A copy: the
    buffer goes back to the producer. UnsupportedFormat for another format, naming it."""
    if data_format not in _TO_BGR:
        raise UnsupportedFormat(f"the camera delivers pixel format {data_format!r}; the pipeline reads "
                                f"{', '.join(GENICAM_PIXEL_FORMATS)} (set camera.pixel_format, or the camera's "
                                "PixelFormat with its vendor's tool)")
    channels = _CHANNELS[data_format]
    flat = np.asarray(data, dtype=np.uint8).ravel()
    if flat.size != width * height * channels:
        raise ValueError(f"a {data_format} buffer of {flat.size} bytes for {width} x {height} px "
                         f"(needs {width * height * channels})")
    pixels = flat.reshape((height, width) if channels == 1 else (height, width, channels))
    code = _TO_BGR[data_format]
    return pixels.copy() if code is None else cv2.cvtColor(pixels, code)


class DeviceClockMap:
    """The camera's clock -> the shared time base (pure: the caller gives both times).

    ``offset`` = the smallest (host - device) of the frames whose device time is within
    ``window_ns`` of the newest: the quickest transfer of the window, so the mapped stamp is
    the device's spacing, never later than the host's receipt. The window follows the two
    oscillators' drift (50 ppm: 0.1 ms over 2 s). A device time that goes back (the camera
    reset its clock, a reopen) starts again."""

    def __init__(self, window_ns: int = 2_000_000_000):
        self.window_ns = int(window_ns)
        self._samples: deque[tuple[int, int]] = deque()  # (device ns, host - device ns)

    def to_shared(self, device_ns: int, host_ns: int) -> int:
        if self._samples and device_ns <= self._samples[-1][0]:
            self._samples.clear()
        self._samples.append((device_ns, host_ns - device_ns))
        while self._samples[0][0] < device_ns - self.window_ns:
            self._samples.popleft()
        return device_ns + min(d for _, d in self._samples)


def device_time_ns(buffer) -> int | None:
    """The buffer's hardware timestamp in ns of the device's clock, or None when the
    producer gives none: GenTL's TIMESTAMP_NS, else its TIMESTAMP ticks over the tick
    frequency (the device's, or the node map's GevTimestampTickFrequency: harvesters'
    ``timestamp_frequency``)."""
    try:
        return int(buffer.timestamp_ns)
    except Exception:  # genicam.gentl.NotAvailableException and friends: not given
        pass
    try:
        ticks, frequency = int(buffer.module.timestamp), int(buffer.timestamp_frequency)
    except Exception:
        return None
    if ticks <= 0 or frequency <= 0:
        return None
    return ticks * 1_000_000_000 // frequency


# config key -> (node names, SFNC first; the node that turns its automatic off; the node that
# enables it; unit said in the notes)
_NODES = (("width_px", ("Width",), None, None),
          ("height_px", ("Height",), None, None),
          ("fps", ("AcquisitionFrameRate", "AcquisitionFrameRateAbs"), None, "AcquisitionFrameRateEnable"),
          ("exposure", ("ExposureTime", "ExposureTimeAbs"), "ExposureAuto", None),
          ("gain", ("Gain", "GainRaw"), "GainAuto", None))


def _reason(e: Exception) -> str:
    """genicam's message's first sentence (it goes on with the file and line in C++)."""
    return str(e).split(" : ")[0].strip().splitlines()[0] if str(e).strip() else type(e).__name__


def _snap(node, wanted: float) -> float:
    """``wanted`` within the node's range and on its increment (a camera takes Width in
    steps of 8 or 16, say): what the camera can take nearest to it."""
    lo, hi = float(node.min), float(node.max)
    value = min(max(float(wanted), lo), hi)
    try:  # an IFloat says whether it has an increment; an IInteger always has one
        step = 0.0 if hasattr(node, "has_inc") and not node.has_inc() else float(node.inc)
    except Exception:
        step = 0.0
    if step > 0:  # the nearest step, the top one at most
        value = lo + min(round((value - lo) / step), (hi - lo) // step) * step
    return value


def request_genicam_settings(node_map, config: CameraConfig) -> list[str]:
    """Ask the camera for each setting the config gives (not 0; the pixel format when not
    "") through its node map and read it back: one note per setting it did not take (no such
    node, refused, or another value), in the words the OpenCV source uses. Before streaming:
    a camera locks Width/Height/PixelFormat while it streams."""
    from .capture import setting_note

    notes = []
    if config.pixel_format:
        if not hasattr(node_map, "PixelFormat"):
            notes.append(f"pixel_format {config.pixel_format}: the camera has no PixelFormat node")
        else:
            try:
                node_map.PixelFormat.value = config.pixel_format
            except Exception as e:
                notes.append(f"pixel_format {config.pixel_format} refused by the camera ({_reason(e)}; "
                             f"it gives {node_map.PixelFormat.value})")
    for key, names, auto, enable in _NODES:
        wanted = getattr(config, key)
        if not wanted:
            continue
        name = next((n for n in names if hasattr(node_map, n)), None)
        if name is None:
            notes.append(f"{key} {wanted:g}: the camera has no {names[0]} node (not set)")
            continue
        node = getattr(node_map, name)
        for helper, value in ((auto, "Off"), (enable, True)):
            if helper and hasattr(node_map, helper):
                try:
                    getattr(node_map, helper).value = value
                except Exception as e:
                    notes.append(f"{helper} {value} refused by the camera ({_reason(e)})")
        refusal = ""
        try:
            asked = _snap(node, wanted)
            node.value = int(asked) if key in ("width_px", "height_px") or name == "GainRaw" else asked
        except Exception as e:
            refusal = _reason(e)
        note = setting_note(key, wanted, not refusal, float(node.value), 0.5 if key.endswith("_px") else 0.01,
                            who="the camera", why=refusal)
        if note:
            notes.append(note)
    return notes


class _Producer:
    """One Harvester per GenTL producer file in this process: a producer is loaded once
    (a second Harvester of the same .cti sees no device), shared by the cameras it serves
    (a stereo pair on one producer); its device list is updated only while none is open
    (an update drops the open devices' buffers)."""

    _lock = threading.Lock()
    _loaded: dict[str, _Producer] = {}

    def __init__(self, cti: str):
        from harvesters.core import Harvester

        self.cti = cti
        self.harvester = Harvester()
        self.harvester.add_file(cti, check_existence=True)
        self.users = 0

    @classmethod
    def acquire(cls, cti: str) -> _Producer:
        key = str(Path(cti).resolve())
        with cls._lock:
            producer = cls._loaded.get(key) or cls._loaded.setdefault(key, cls(key))
            if producer.users == 0:
                producer.harvester.update()
            producer.users += 1
            return producer

    def open(self, device: str):
        """(an ImageAcquirer of the device named, its id): one at a time, a stereo pair's
        two capture threads opening together."""
        with self._lock:
            infos = self.harvester.device_info_list
            index = _pick_device(infos, device, self.cti)
            label = f"genicam {infos[index].id_}"
            try:
                return self.harvester.create(index), label
            except Exception as e:
                raise OSError(f"{label}: does not open ({_reason(e)}): in use by another program?") from None

    def release(self) -> None:
        with self._lock:
            self.users -= 1
            if self.users == 0:
                self.harvester.reset()
                type(self)._loaded.pop(self.cti, None)


def _pick_device(infos: list, device: str, cti: str) -> int:
    """The index of the device named by ``device`` (its id, else its serial number, else
    an index), the first when ""; OSError listing what the producer sees."""
    if not infos:
        raise OSError(f"GenTL producer {cti}: no camera found (connected, powered, on this host's network? "
                      "a file that is no GenTL producer finds none either)")

    def attr(info, name):
        try:
            return str(getattr(info, name))
        except Exception:  # an attribute the producer does not give
            return ""

    if not device:
        return 0
    for name in ("id_", "serial_number"):
        for i, info in enumerate(infos):
            if attr(info, name) == device:
                return i
    if device.isdigit() and int(device) < len(infos):
        return int(device)
    seen = ", ".join(f"{attr(info, 'id_')} (serial {attr(info, 'serial_number') or '?'})" for info in infos)
    raise OSError(f"GenTL producer {cti}: no camera {device!r} (id, serial number or index); it sees: {seen}")


class GenICamCapture:
    """A GenICam camera as the adapter reads a capture (see module). Opens at construction:
    the producer, the device, its settings (each one not taken: a warning line), its pixel
    format (refused: UnsupportedFormat), acquisition started. OSError naming what failed."""

    def __init__(self, config: CameraConfig, stop: threading.Event | None = None):
        require_library()
        cti, device = config.genicam
        if not Path(cti).is_file():
            raise OSError(f"camera.source {config.source!r}: no GenTL producer file {cti!r} (a .cti)")
        self.config = config
        self.label = f"genicam {device or '(first)'}"
        self.stop = stop or threading.Event()
        self.clock_map = DeviceClockMap()
        self._epoch = CLOCK.epoch  # the wall clock's steps when the map began
        self._device_ns: int | None = None
        self.acquirer = None
        self.notes: list[str] = []
        self.producer = None
        try:
            self.producer = _Producer.acquire(cti)
            self.acquirer, self.label = self.producer.open(device)
            node_map = self.acquirer.remote_device.node_map
            self.notes = request_genicam_settings(node_map, config)
            for note in self.notes:
                log.warning("camera %s: %s", self.label, note)
            if hasattr(node_map, "PixelFormat") and str(node_map.PixelFormat.value) not in _TO_BGR:
                raise UnsupportedFormat(f"{self.label}: the camera delivers pixel format "
                                        f"{node_map.PixelFormat.value!r}; the pipeline reads "
                                        f"{', '.join(GENICAM_PIXEL_FORMATS)} (set camera.pixel_format)")
            self.acquirer.start()
        except OSError:
            self.release()
            raise
        except Exception as e:  # genicam's own exceptions (a producer that fails to load, a node...)
            self.release()
            raise OSError(f"camera.source {config.source!r}: {self.label}: {_reason(e)}") from None

    def isOpened(self) -> bool:  # noqa: N802 (cv2.VideoCapture's name)
        return self.acquirer is not None

    def read(self) -> tuple[bool, np.ndarray | None]:
        """The next frame; (False, None) when none came for ``reopen_s`` (the camera stalled
        or is gone: the adapter reopens it), when the library fails, or when stopped. A
        frame that does not decode is skipped with an error line."""
        deadline = time.monotonic() + self.config.reopen_s
        while not self.stop.is_set() and time.monotonic() < deadline:
            try:
                buffer = self.acquirer.try_fetch(timeout=_FETCH_S)
            except Exception as e:  # the device went away under the fetch
                log.error("camera %s: fetch failed: %s", self.label, _reason(e))
                return False, None
            if buffer is None:
                continue
            try:
                component = buffer.payload.components[0]
                frame = frame_from_buffer(component.data, int(component.width), int(component.height),
                                          str(component.data_format))
                self._device_ns = device_time_ns(buffer)
            except UnsupportedFormat as e:
                log.error("camera %s: %s", self.label, e)
                return False, None
            except Exception as e:  # a short or broken buffer: this frame only
                log.error("camera %s: frame skipped: %s", self.label, _reason(e))
                continue
            finally:
                try:
                    buffer.queue()
                except Exception as e:  # (the device went away meanwhile: the reopen tells)
                    log.debug("camera %s: %s", self.label, e)
            return True, frame
        return False, None

    def shared_stamp_ns(self, host_ns: int) -> int:
        """The last frame's capture stamp in the shared time base: the camera's timestamp
        mapped by :class:`DeviceClockMap` when the buffer had one, else ``host_ns`` (the
        shared time base when the fetch returned). A step of the wall clock accepted by the
        live shell (runtime/clock.py) starts the map again: its offsets are of the old base."""
        if self._device_ns is None:
            return host_ns
        if CLOCK.epoch != self._epoch:
            self._epoch = CLOCK.epoch
            self.clock_map = DeviceClockMap(self.clock_map.window_ns)
        return self.clock_map.to_shared(self._device_ns, host_ns)

    def get(self, prop: int) -> float:
        return 0.0  # a camera has no frame rate to pace by (it paces itself)

    def set(self, prop: int, value: float) -> bool:
        return False

    def release(self) -> None:
        acquirer, self.acquirer = self.acquirer, None
        if acquirer is not None:
            for step in (acquirer.stop, acquirer.destroy):
                try:
                    step()
                except Exception as e:  # a device gone: nothing more to release
                    log.debug("camera %s: %s", self.label, e)
        producer, self.producer = getattr(self, "producer", None), None
        if producer is not None:
            producer.release()
