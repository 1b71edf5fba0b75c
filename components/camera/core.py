"""The real camera's core: captured frames in, ``camera/image`` out.

The grabbing (OpenCV VideoCapture, a thread, the wall clock) lives in the shell's adapter
(:mod:`humanpt.camera.capture`); it hands each frame to the core as a local ``capture``
input (foxglove.RawImage, stamped at capture), so the recording holds every frame and the
run replays. The core checks the frame, turns colour into mono8 (``mono``) and publishes
it as ``camera/image`` - the same message the simulated camera publishes.
"""

from __future__ import annotations

from collections import deque

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
    ``camera_resumed`` (frames again); with ``source_right`` (a stereo pair)
    ``unpaired_frame`` (a frame without its other half within ``pair_tolerance_ms``: dropped)
    and ``camera_stalled`` when no pair comes."""

    name = "camera"
    config_type = CameraConfig
    ports = (Port("capture", RawImage, "_on_capture"),  # frames grabbed by the shell's adapter
             Port("capture_right", RawImage, "_on_capture_right"),  # the pair's right camera (source_right)
             Port("tick", pb.Tick, "_on_tick"),  # the stall watch
             Port("clock_step", pb.Event, "_on_clock_step"))  # the wall clock stepped (runtime/clock.py)

    def __init__(self, config: CameraConfig):
        super().__init__(config)
        self.stereo = bool(config.source_right.strip())
        self.last_stamp_ns: dict[str, int] = {}  # per camera ("left" is the only one of a single camera)
        self.frames = 0
        self.dropped = 0
        self.unpaired = 0
        self.size_px: dict[str, tuple[int, int]] = {}  # (width, height) of each camera's first frame
        self.waiting: dict[str, deque] = {"left": deque(maxlen=16), "right": deque(maxlen=16)}
        self.watch_from_ns: int | None = None  # the last frame (pair) published, or the first tick
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
        what = "pair" if self.stereo else "frame"
        since = f"since the last {what}" if self.frames else f"since the camera started (no {what} yet)"
        return [self.event(t_ns, pb.SEVERITY_ERROR, "camera_stalled",
                           f"no {what} for {gap_ns * 1e-9:.2f} s {since} (camera.stall_s {self.config.stall_s:g}): "
                           f"unplugged, stalled or at the end of its file; the robot holds until frames come again")]

    def _on_capture(self, t_ns: int, msg: RawImage) -> list[Output]:
        return self._take(t_ns, "left", msg)

    def _on_capture_right(self, t_ns: int, msg: RawImage) -> list[Output]:
        if not self.stereo:
            return self._drop(t_ns, "bad_input", "a right camera's frame, but camera.source_right is not set: dropped")
        return self._take(t_ns, "right", msg)

    def _take(self, t_ns: int, side: str, msg: RawImage) -> list[Output]:
        which = f"the {side} camera's " if self.stereo else ""
        try:
            pixels = from_image(msg)
        except MessageError as e:
            return self._drop(t_ns, "bad_frame", f"dropped {which}captured frame: {e}")
        size = (int(msg.width), int(msg.height))
        first = self.size_px.get(side)
        if first is not None and size != first:
            return self._drop(t_ns, "frame_size_changed",
                              f"dropped {which or 'a '}{size[0]} x {size[1]} px frame: the camera gave "
                              f"{first[0]} x {first[1]} px before (the rig is calibrated for one "
                              f"size; restart the camera component after changing the camera's resolution)")
        stamp = image_stamp_ns(msg)
        last = self.last_stamp_ns.get(side)
        if last is not None and stamp <= last:
            return self._drop(t_ns, "stale_frame",
                              f"dropped {which}frame stamped {stamp} ns, not after the previous {last} ns")
        self.last_stamp_ns[side] = stamp
        self.size_px[side] = size
        encoding = msg.encoding
        if self.config.mono and encoding in _TO_GREY:
            pixels, encoding = cv2.cvtColor(np.ascontiguousarray(pixels), _TO_GREY[encoding]), "mono8"
        elif self.config.mono and encoding == "mono16":
            pixels, encoding = (pixels >> 8).astype(np.uint8), "mono8"
        if not self.stereo:
            return self._publish(t_ns, stamp, pixels, encoding)
        return self._pair(t_ns, side, stamp, pixels, encoding)

    def _pair(self, t_ns: int, side: str, stamp: int, pixels: np.ndarray, encoding: str) -> list[Output]:
        """Pair a stereo frame with the other camera's nearest in stamp (within the
        tolerance); frames that can no longer pair (older than this one by more than the
        tolerance, on the other side; older than the pair, on this side) are dropped."""
        other = "right" if side == "left" else "left"
        tol = int(self.config.pair_tolerance_ms * 1e6)
        out: list[Output] = []
        waiting = self.waiting[other]
        while waiting and waiting[0][0] < stamp - tol:  # (later frames of this side are later still)
            out += self._unpaired(t_ns, other, waiting.popleft()[0])
        if not waiting or abs(waiting[0][0] - stamp) > tol:
            if len(self.waiting[side]) == self.waiting[side].maxlen:
                out += self._unpaired(t_ns, side, self.waiting[side][0][0])
            self.waiting[side].append((stamp, pixels, encoding))
            return out
        o_stamp, o_pixels, o_encoding = waiting.popleft()
        while self.waiting[side]:  # this side's older frames lost their chance
            out += self._unpaired(t_ns, side, self.waiting[side].popleft()[0])
        left, right = (pixels, o_pixels) if side == "left" else (o_pixels, pixels)
        if left.shape != right.shape or encoding != o_encoding:
            return out + self._drop(t_ns, "unpaired_frame",
                                    f"a pair of different images: left {left.shape} {encoding if side == 'left' else o_encoding}, "
                                    f"right {right.shape}: the two cameras must give one size and encoding")
        # the pair's stamp: the middle of its two captures
        return out + self._publish(t_ns, (stamp + o_stamp) // 2, np.hstack([left, right]), encoding)

    def _unpaired(self, t_ns: int, side: str, stamp: int) -> list[Output]:
        self.unpaired += 1
        return self._drop(t_ns, "unpaired_frame", f"the {side} camera's frame stamped {stamp} ns has no other half "
                          f"within {self.config.pair_tolerance_ms:g} ms: dropped (unpaired so far: {self.unpaired})")

    def _publish(self, t_ns: int, stamp: int, pixels: np.ndarray, encoding: str) -> list[Output]:
        out: list[Output] = []
        if self.stalled:
            self.stalled = False
            out.append(self.event(t_ns, pb.SEVERITY_INFO, "camera_resumed",
                                  f"frames again after {(t_ns - self.watch_from_ns) * 1e-9:.2f} s without"))
        self.watch_from_ns = t_ns
        self.frames += 1
        return [*out, ("camera/image", image(pixels, stamp, "camera", encoding))]

    def _on_clock_step(self, t_ns: int, msg: pb.Event) -> list[Output]:
        """The wall clock stepped by ``msg.text`` ns: the last stamp moves with it, so that
        frames after a step back are not all stale until the clock catches up."""
        try:
            step = int(msg.text)
        except ValueError:
            return self._drop(t_ns, "bad_input", f"clock_step {msg.text[:40]!r} is not a step in ns: ignored")
        self.last_stamp_ns = {side: last + step for side, last in self.last_stamp_ns.items()}
        for side, queue in self.waiting.items():
            self.waiting[side] = deque(((s + step, p, e) for s, p, e in queue), maxlen=queue.maxlen)
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
