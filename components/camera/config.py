"""Configuration of the real camera (section ``[camera]``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

from humanpt.runtime.config import Range

# A source named ``<scheme>:<address>`` is opened by the source registered for its scheme
# (capture.SOURCES); anything else is OpenCV's (a device, a video file) or an image folder.
GENICAM_SCHEME = "genicam"
# The pixel formats a GenICam camera may deliver (PFNC names): grey, or colour turned to
# mono8 as the core does; anything else (Bayer, 10/12-bit packed) is refused, naming it.
GENICAM_PIXEL_FORMATS = ("Mono8", "RGB8", "BGR8", "RGBa8", "BGRa8")


@dataclass(frozen=True)
class CameraConfig:
    """A real camera through OpenCV's VideoCapture.

    ``source``: a device index (``"0"``) or path (``/dev/video0``), a video file path or a
    folder of images. ``width_px``/``height_px``/``fps``, ``exposure`` and ``gain`` (in the
    driver's units: V4L2's exposure_time_absolute is in 100 us) are requested from a device
    (0: its default; what the driver does not take is said at start). A file
    is played at its own frame rate when ``pace`` (else as fast as it decodes) and from the
    start again when ``loop``; a folder's images (natural name order) at ``fps``, which a
    folder needs. No frame for ``stall_s`` (a camera unplugged, stalled, a file at its end)
    gives a ``camera_stalled`` event; the next frame ``camera_resumed``.

    ``source_right``: a second camera (an ordinary stereo pair: ``source`` is its left
    camera, this its right, same settings): the two cameras' frames are paired by stamp
    (within ``pair_tolerance_ms``) and published side by side (left then right), what a
    rig of kind "stereo" reads; a frame without its other half is dropped and counted.
    ``source = "genicam:<producer.cti>[#<device>]"``: a GenICam machine-vision camera through
    harvesters and the camera vendor's GenTL producer (the ``[genicam]`` extra); ``<device>``
    its id, serial number or index in the producer's list (default: the first). Its
    ``width_px``/``height_px``/``fps``/``exposure`` (us)/``gain`` (dB) and ``pixel_format``
    (one of :data:`GENICAM_PIXEL_FORMATS`; "" keeps the camera's) are asked through its node
    map. A source that fails is reopened every ``reopen_s``. ``mono``: colour frames are turned
    to mono8 (the PSVS processing works on grey levels). Frames are stamped when the grab
    returns (the capture time, minus the driver's latency).
    """

    source: str = "0"
    width_px: Annotated[int, Range(0, 20000, "px")] = 0
    height_px: Annotated[int, Range(0, 20000, "px")] = 0
    fps: Annotated[float, Range(0, 10000, "frames/s")] = 0.0
    pace: bool = True
    loop: bool = False
    mono: bool = True
    reopen_s: Annotated[float, Range(0.01, 3600, "s")] = 2.0
    exposure: Annotated[float, Range(0, 1e6, "driver units")] = 0.0
    gain: Annotated[float, Range(0, 1e6, "driver units")] = 0.0
    stall_s: Annotated[float, Range(0.05, 60, "s")] = 0.5
    source_right: str = ""
    pair_tolerance_ms: Annotated[float, Range(0.01, 1000, "ms")] = 5.0
    pixel_format: str = ""

    def __post_init__(self) -> None:
        if not self.source.strip():
            raise ValueError("camera.source must be a device index, a video file path or an image folder")
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 20000:
                raise ValueError(f"camera.{name} must be an integer in [0, 20000], got {value!r}")
        for name, lo, hi in (("fps", 0.0, 10_000.0), ("reopen_s", 0.01, 3600.0), ("stall_s", 0.05, 60.0),
                             ("exposure", 0.0, 1e6), ("gain", 0.0, 1e6), ("pair_tolerance_ms", 0.01, 1000.0)):
            value = getattr(self, name)
            if not (math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"camera.{name} must be within {lo} and {hi}, got {value}")
        for key in ("source", "source_right"):
            text = getattr(self, key).strip()
            if text.startswith(f"{GENICAM_SCHEME}:") and not text[len(GENICAM_SCHEME) + 1:].split("#")[0].strip():
                raise ValueError(f"camera.{key} {text!r} names no GenTL producer: "
                                 f"{GENICAM_SCHEME}:/path/to/producer.cti[#device id, serial or index]")
        if self.pixel_format:
            if self.pixel_format not in GENICAM_PIXEL_FORMATS:
                raise ValueError(f"camera.pixel_format {self.pixel_format!r} is not one of "
                                 f"{', '.join(GENICAM_PIXEL_FORMATS)} (or \"\": the camera's own)")
            if self.genicam is None:
                raise ValueError("camera.pixel_format is asked of a GenICam camera only "
                                 f"(source = \"{GENICAM_SCHEME}:...\"), not of {self.source!r}")

    def right(self) -> CameraConfig:
        """The second camera's config: this one with ``source_right`` as its source."""
        import dataclasses

        return dataclasses.replace(self, source=self.source_right, source_right="")

    @property
    def is_device(self) -> bool:
        """A camera (an index, a /dev/ path or a GenICam camera), not a file or a folder."""
        return (self.device_index is not None or self.source.strip().startswith("/dev/")
                or self.genicam is not None)

    @property
    def genicam(self) -> tuple[str, str] | None:
        """(producer .cti path, device: id, serial, index or "" for the first) when
        ``source`` is ``genicam:<cti>[#<device>]``, else None."""
        text = self.source.strip()
        if not text.startswith(f"{GENICAM_SCHEME}:"):
            return None
        cti, _, device = text[len(GENICAM_SCHEME) + 1:].partition("#")
        return cti.strip(), device.strip()

    @property
    def device_index(self) -> int | None:
        """The device index when ``source`` is one, else None (a file)."""
        text = self.source.strip()
        return int(text) if text.isdigit() else None
