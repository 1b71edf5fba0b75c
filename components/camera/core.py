"""The real camera's core: captured frames in, ``camera/image`` out.

The grabbing (OpenCV VideoCapture, a thread, the wall clock) lives in the shell's adapter
(:mod:`humanpt.camera.capture`); it hands each frame to the core as a local ``capture``
input (foxglove.RawImage, stamped at capture), so the recording holds every frame and the
run replays. The core checks the frame, turns colour into mono8 (``mono``) and publishes
it as ``camera/image`` - the same message the simulated camera publishes.
"""

from __future__ import annotations

import cv2
import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import MessageError, from_image, image, image_stamp_ns

from .config import CameraConfig

__all__ = ["CameraCore"]

_TO_GREY = {"bgr8": cv2.COLOR_BGR2GRAY, "rgb8": cv2.COLOR_RGB2GRAY}


class CameraCore(Core):
    """Events: ``bad_frame`` (does not decode as an image), ``stale_frame`` (a stamp not
    after the previous one: dropped), ``frame_size_changed`` (a frame of another size than
    the first: dropped), ``camera_stalled`` (no frame for ``stall_s``: unplugged, stalled, a
    file at its end; the pipeline gets no image, so the controller holds the robot) and
    ``camera_resumed`` (frames again)."""

    name = "camera"
    config_type = CameraConfig
    ports = (Port("capture", RawImage, "_on_capture"),  # frames grabbed by the shell's adapter
             Port("tick", pb.Tick, "_on_tick"),  # the stall watch
             Port("clock_step", pb.Event, "_on_clock_step"))  # the wall clock stepped (runtime/clock.py)

    def __init__(self, config: CameraConfig):
        super().__init__(config)
        self.last_stamp_ns: int | None = None
        self.frames = 0
        self.dropped = 0
        self.size_px: tuple[int, int] | None = None  # (width, height) of the first frame
        self.watch_from_ns: int | None = None  # the last frame taken (or the first tick)
        self.stalled = False

    def tick_period_ns(self) -> int | None:
        return int(self.config.stall_s * 1e9 / 5)

    def _on_tick(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        if self.watch_from_ns is None:
            self.watch_from_ns = t_ns
        gap_ns = t_ns - self.watch_from_ns
        if self.stalled or gap_ns <= self.config.stall_s * 1e9:
            return []
        self.stalled = True
        since = "since the last frame" if self.frames else "since the camera started (no frame yet)"
        return [self.event(t_ns, pb.SEVERITY_ERROR, "camera_stalled",
                           f"no frame for {gap_ns * 1e-9:.2f} s {since} (camera.stall_s {self.config.stall_s:g}): "
                           f"unplugged, stalled or at the end of its file; the robot holds until frames come again")]

    def _on_capture(self, t_ns: int, msg: RawImage) -> list[Output]:
        try:
            pixels = from_image(msg)
        except MessageError as e:
            return self._drop(t_ns, "bad_frame", f"dropped a captured frame: {e}")
        size = (int(msg.width), int(msg.height))
        if self.size_px is not None and size != self.size_px:
            return self._drop(t_ns, "frame_size_changed",
                              f"dropped a {size[0]} x {size[1]} px frame: the camera gave "
                              f"{self.size_px[0]} x {self.size_px[1]} px before (the rig is calibrated for one "
                              f"size; restart the camera component after changing the camera's resolution)")
        stamp = image_stamp_ns(msg)
        if self.last_stamp_ns is not None and stamp <= self.last_stamp_ns:
            return self._drop(
                t_ns,
                "stale_frame",
                f"dropped a frame stamped {stamp} ns, not after the previous {self.last_stamp_ns} ns",
            )
        self.last_stamp_ns = stamp
        self.size_px = size
        out: list[Output] = []
        if self.stalled:
            self.stalled = False
            out.append(self.event(t_ns, pb.SEVERITY_INFO, "camera_resumed",
                                  f"frames again after {(t_ns - self.watch_from_ns) * 1e-9:.2f} s without"))
        self.watch_from_ns = t_ns
        encoding = msg.encoding
        if self.config.mono and encoding in _TO_GREY:
            pixels, encoding = (
                cv2.cvtColor(np.ascontiguousarray(pixels), _TO_GREY[encoding]),
                "mono8",
            )
        elif self.config.mono and encoding == "mono16":
            pixels, encoding = (pixels >> 8).astype(np.uint8), "mono8"
        self.frames += 1
        return [*out, ("camera/image", image(pixels, stamp, "camera", encoding))]

    def _on_clock_step(self, t_ns: int, msg: pb.Event) -> list[Output]:
        """The wall clock stepped by ``msg.text`` ns: the last stamp moves with it, so that
        frames after a step back are not all stale until the clock catches up."""
        try:
            step = int(msg.text)
        except ValueError:
            return self._drop(t_ns, "bad_input", f"clock_step {msg.text[:40]!r} is not a step in ns: ignored")
        if self.last_stamp_ns is not None:
            self.last_stamp_ns += step
        if self.watch_from_ns is not None:  # the watch's times are on the same clock
            self.watch_from_ns += step
        return []

    def _drop(self, t_ns: int, code: str, text: str) -> list[Output]:
        self.dropped += 1
        if self.dropped <= 10 or self.dropped % 1000 == 0:
            return [
                self.event(
                    t_ns, pb.SEVERITY_WARNING, code, f"{text} (dropped so far: {self.dropped})"
                )
            ]
        return []
