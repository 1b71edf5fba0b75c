"""The simulated PSVS camera as a component core.

Inputs: ``operator/truth`` (world_T_tob) and ``sim_robot/truth`` (world_T_flange), and a
tick at ``fps``. On each tick it renders the complex image at the tick time (the capture
time) from the two truths interpolated - or extrapolated by at most
``max_extrapolation_ms`` - to that time, and publishes it on ``camera/image`` (mono8,
stamp = capture, frame "camera") with the truth it used on ``sim_camera/truth``.
"""

from __future__ import annotations

import numpy as np

from humanpt.geometry.transforms import interpolate_transform, invert_transform
from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import MessageError, from_pose, image, pose_from_mm

from .config import SimCameraConfig
from .render import Renderer

__all__ = ["SimCameraCore", "PoseTrack", "interpolate_pose"]

_WAIT_GRACE_NS = 500_000_000  # no flange truth this long after the first tick: say so


def interpolate_pose(
    t_ns: int, t0_ns: int, a_T_b0: np.ndarray, t1_ns: int, a_T_b1: np.ndarray, max_extra_ns: int
) -> np.ndarray:
    """Pose (4, 4) at ``t_ns`` on the constant-velocity screw through two stamped poses
    (linear in translation, geodesic in rotation). Beyond the two stamps it extrapolates by
    at most ``max_extra_ns``, then holds."""
    span = t1_ns - t0_ns
    if span <= 0:
        return np.array(a_T_b1, dtype=float)
    s = (t_ns - t0_ns) / span
    s = min(max(s, -max_extra_ns / span), 1.0 + max_extra_ns / span)
    return interpolate_transform(a_T_b0, a_T_b1, s, assume_valid=True)


class PoseTrack:
    """The last two stamped poses of one truth stream (mm)."""

    def __init__(self) -> None:
        self.samples: list[tuple[int, np.ndarray]] = []

    def add(self, stamp_ns: int, a_T_b: np.ndarray) -> None:
        if self.samples and stamp_ns <= self.samples[-1][0]:
            if stamp_ns == self.samples[-1][0]:
                self.samples[-1] = (stamp_ns, a_T_b)  # a repeat: the newer value wins
                return
            self.samples.clear()  # time went backwards (a restarted source): start again
        self.samples = [*self.samples[-1:], (stamp_ns, a_T_b)]

    def at(self, t_ns: int, max_extra_ns: int) -> np.ndarray | None:
        if not self.samples:
            return None
        if len(self.samples) == 1:
            return self.samples[0][1]
        (t0, p0), (t1, p1) = self.samples
        return interpolate_pose(t_ns, t0, p0, t1, p1, max_extra_ns)


class SimCameraCore(Core):
    """Renders the PSVS complex image of the twin's truth (see the module docstring)."""

    name = "sim_camera"
    config_type = SimCameraConfig
    ports = (
        Port("tick", pb.Tick, "_on_tick"),
        Port("operator/truth", pb.Truth, "_on_tob_truth"),
        Port("sim_robot/truth", pb.Truth, "_on_flange_truth"),
    )

    def __init__(self, config: SimCameraConfig):
        super().__init__(config)
        self.renderer = Renderer(config)
        self.flange_T_camera = config.flange_T_camera
        self.tob = PoseTrack()
        self.flange = PoseTrack()
        self.frame_index = 0
        self.first_tick_ns: int | None = None
        self.warned_waiting = False
        self.bad_truths = 0

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def on_config_changed(self, old: SimCameraConfig, new: SimCameraConfig) -> None:
        self.renderer = Renderer(new)

    def _on_tick(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        return self._capture(t_ns)

    def _on_tob_truth(self, t_ns: int, msg: pb.Truth) -> list[Output]:
        return self._truth(t_ns, "operator/truth", msg)

    def _on_flange_truth(self, t_ns: int, msg: pb.Truth) -> list[Output]:
        return self._truth(t_ns, "sim_robot/truth", msg)

    def _truth(self, t_ns: int, topic: str, msg: pb.Truth) -> list[Output]:
        field = "world_T_tob" if topic == "operator/truth" else "world_T_flange"
        try:
            if not msg.HasField(field):
                raise MessageError(f"{field} is not set")
            a_T_b = from_pose(getattr(msg, field))
        except MessageError as e:
            self.bad_truths += 1
            if self.bad_truths <= 10 or self.bad_truths % 1000 == 0:
                return [
                    self.event(
                        t_ns,
                        pb.SEVERITY_WARNING,
                        "bad_truth",
                        f"ignored a {topic} message: {e} (so far {self.bad_truths})",
                    )
                ]
            return []
        a_T_b[:3, 3] *= 1000.0  # m -> mm
        (self.tob if topic == "operator/truth" else self.flange).add(msg.header.stamp_ns, a_T_b)
        return []

    def _capture(self, t_ns: int) -> list[Output]:
        if self.first_tick_ns is None:
            self.first_tick_ns = t_ns
        extra_ns = round(self.config.max_extrapolation_ms * 1e6)
        world_T_flange = self.flange.at(t_ns, extra_ns)
        if world_T_flange is None:
            if not self.warned_waiting and t_ns - self.first_tick_ns >= _WAIT_GRACE_NS:
                self.warned_waiting = True
                return [
                    self.event(
                        t_ns,
                        pb.SEVERITY_WARNING,
                        "waiting_for_truth",
                        "no sim_robot/truth yet: the camera does not know where it is",
                    )
                ]
            return []
        world_T_tob = self.tob.at(t_ns, extra_ns)
        world_T_camera = world_T_flange @ self.flange_T_camera
        camera_T_tob = None if world_T_tob is None else invert_transform(world_T_camera) @ world_T_tob
        pixels = self.renderer.render(camera_T_tob, world_T_camera, self.frame_index)
        self.frame_index += 1
        truth = pb.Truth(header=self.next_header("sim_camera/truth", t_ns, "world"))
        truth.world_T_flange.CopyFrom(pose_from_mm(world_T_flange))
        if world_T_tob is not None:
            truth.world_T_tob.CopyFrom(pose_from_mm(world_T_tob))
        return [("camera/image", image(pixels, t_ns, "camera")), ("sim_camera/truth", truth)]
