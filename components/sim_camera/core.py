"""The simulated PSVS camera as a component core.

Inputs: ``operator/truth`` (world_T_tob) and ``sim_robot/truth`` (world_T_flange), and a
tick at ``fps``. The truth is one thing: each stream's true trajectory is the piecewise
linear (translation) / geodesic (rotation) path through its stamped samples (a sample
stamped t is where the body is at t; before its first sample a body holds its first pose).
A tick at t captures an exposure of ``exposure_ms`` centred on t (the capture stamp). The
capture waits in a queue until both truths have samples at or beyond the end of the
exposure, then the image is rendered from the truths interpolated to t - never
extrapolated - and published on ``camera/image`` (mono8, frame "camera", stamp = the
capture time plus the camera clock's error, ``stamp_offset_ms`` + ``stamp_jitter_ms``),
with the sources covered as the operator's truth says at t (its ``cover_fraction``, on
top of the configured static ``occluded_sources``), and with the truth it used on ``sim_camera/truth`` (stamp = the true capture time). A capture
whose truth has not come ``max_truth_wait_ms`` after the exposure ended is dropped with a
``truth_late`` event. A frame is lost with probability ``frame_drop_probability``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.frames import SAMPLE_HOLD_REFUSE, Backwards, FrameGraph, Repeat, TimedPoses
from humanpt.runtime.core import Core, Output, Port, count_decades
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import MessageError, from_pose, image, pose_from_mm

from .config import SimCameraConfig
from .render import Renderer

__all__ = ["SimCameraCore", "truth_poses", "TIMING_STREAM"]

_WAIT_GRACE_NS = 500_000_000  # no flange truth this long after the first tick: say so
TIMING_STREAM = 1  # frame timing draws: default_rng([seed, frame_index, TIMING_STREAM])


def truth_poses(maxlen: int | None = 4096) -> TimedPoses:
    """A truth stream's stamped poses (mm), as the camera keeps them: a repeated stamp
    replaces the pose (the newer value wins), an earlier one starts the stream again (a
    restarted source). Looked up with :data:`humanpt.geometry.frames.SAMPLE_HOLD_REFUSE`, it
    is the true trajectory: linear in translation and geodesic in rotation between
    neighbouring samples; before the first sample the first pose holds (the body stood still
    before its source started); never extrapolated beyond the last sample."""
    return TimedPoses(maxlen, repeat=Repeat.REPLACE, backwards=Backwards.RESTART)


@dataclass(frozen=True)
class _Capture:
    t_ns: int  # true capture time: the middle of the exposure
    frame_index: int
    stamp_ns: int  # the image's stamp (capture time on the camera's clock)
    half_exposure_ns: int
    renderer: Renderer  # the settings at the capture (a live change applies to later ones)


class SimCameraCore(Core):
    """Renders the PSVS complex image of the twin's truth (see the module docstring).
    Events: ``bad_truth``, ``waiting_for_truth`` (no flange truth 0.5 s after the first
    tick), ``truth_late`` (captures dropped: their truth never came; 1st, 10th, 100th...)."""

    name = "sim_camera"
    config_type = SimCameraConfig
    ports = (
        Port("tick", pb.Tick, "_on_tick"),
        Port("operator/truth", pb.Truth, "_on_tob_truth"),
        Port("sim_robot/truth", pb.Truth, "_on_flange_truth"),
    )
    # Snapshots (runtime/snapshot.py): the renderer is made from the config (its noise bank is
    # 1.3 MB); a capture in flight is a _Capture.
    not_frozen = frozenset({"renderer"})
    state_types = (_Capture,)

    def __init__(self, config: SimCameraConfig):
        super().__init__(config)
        self.renderer = Renderer(config)
        self.flange_T_camera = config.flange_T_camera
        # The cell's frames (geometry.frames), mm: world -> flange and world -> tob from the
        # truths, flange -> camera the configured hand-eye.
        self.frames = FrameGraph()
        self.flange = self.frames.add_timed("world", "flange", truth_poses(), SAMPLE_HOLD_REFUSE)
        self.frames.add_static("flange", "camera", self.flange_T_camera)
        self.tob = self.frames.add_timed("world", "tob", truth_poses(), SAMPLE_HOLD_REFUSE)
        # The operator's covers: (stamp ns, fractions A B C, angles rad), in stamp order; a
        # cover holds from its truth's stamp until the next truth's (a step, not blended).
        self.covers: deque[tuple[int, tuple[float, ...], tuple[float, ...]]] = deque(maxlen=4096)
        self.pending: deque[_Capture] = deque()
        self.frame_index = 0  # counts captures (dropped ones too): the noise of frame k is fixed
        self.first_tick_ns: int | None = None
        self.warned_waiting = False
        self.bad_truths = 0
        self.counts: dict[str, int] = {}

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def on_config_changed(self, old: SimCameraConfig, new: SimCameraConfig) -> None:
        self.renderer = Renderer(new)

    # -- inputs -----------------------------------------------------------------------------
    def _on_tick(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        out = self._capture(t_ns)
        return out + self._render_ready(t_ns)

    def _on_tob_truth(self, t_ns: int, msg: pb.Truth) -> list[Output]:
        return self._truth(t_ns, "operator/truth", msg) + self._render_ready(t_ns)

    def _on_flange_truth(self, t_ns: int, msg: pb.Truth) -> list[Output]:
        return self._truth(t_ns, "sim_robot/truth", msg) + self._render_ready(t_ns)

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
        if topic == "operator/truth" and (msg.cover_fraction or msg.cover_angle_rad or self.covers):
            # (A truth without a cover after covers: nothing is covered any more.)
            fraction = tuple(msg.cover_fraction) or (0.0, 0.0, 0.0)
            angle = tuple(msg.cover_angle_rad) or (0.0, 0.0, 0.0)
            if not (len(fraction) == len(angle) == 3 and all(0.0 <= f <= 1.0 for f in fraction)
                    and all(math.isfinite(a) for a in angle)):
                self.bad_truths += 1
                return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_truth",
                                   f"ignored a cover of {topic}: 3 fractions in [0, 1] and 3 finite angles "
                                   f"expected, got {list(fraction)}, {list(angle)} (so far {self.bad_truths})")]
            while self.covers and self.covers[-1][0] >= msg.header.stamp_ns:
                self.covers.pop()  # a repeat or a restarted source: the newer wins
            self.covers.append((msg.header.stamp_ns, fraction, angle))
        a_T_b[:3, 3] *= 1000.0  # m -> mm
        (self.tob if topic == "operator/truth" else self.flange).add(msg.header.stamp_ns, a_T_b)
        return []

    def _cover_at(self, t_ns: int) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
        """The operator's cover at ``t_ns`` (the latest at or before it), or None."""
        while len(self.covers) >= 2 and self.covers[1][0] <= t_ns:
            self.covers.popleft()  # captures come in time order: older covers are done
        if not self.covers or self.covers[0][0] > t_ns:
            return None
        return self.covers[0][1], self.covers[0][2]

    # -- capture and render -----------------------------------------------------------------
    def _half_exposure_ns(self) -> int:
        return round(self.config.exposure_ms * 5e5)

    def _capture(self, t_ns: int) -> list[Output]:
        """A tick: an exposure centred on ``t_ns`` joins the queue (unless the frame is
        lost); captures whose truth is too late leave it."""
        c = self.config
        out: list[Output] = []
        if self.first_tick_ns is None:
            self.first_tick_ns = t_ns
        if not len(self.flange) and not self.warned_waiting and t_ns - self.first_tick_ns >= _WAIT_GRACE_NS:
            self.warned_waiting = True
            out.append(self.event(t_ns, pb.SEVERITY_WARNING, "waiting_for_truth",
                                  "no sim_robot/truth yet: the camera does not know where it is"))
        index = self.frame_index
        self.frame_index += 1
        stamp_ns, lost = t_ns, False
        if c.stamp_offset_ms or c.stamp_jitter_ms or c.frame_drop_probability:
            rng = np.random.default_rng([c.seed, index, TIMING_STREAM])
            error_ms = c.stamp_offset_ms + c.stamp_jitter_ms * rng.standard_normal()
            stamp_ns = max(t_ns + round(error_ms * 1e6), 0)
            lost = bool(rng.random() < c.frame_drop_probability)
        if lost:
            self.counts["frames_dropped"] = self.counts.get("frames_dropped", 0) + 1
        else:
            self.pending.append(_Capture(t_ns, index, stamp_ns, self._half_exposure_ns(), self.renderer))
        # Bounded: a capture whose truth has not come max_truth_wait_ms after its exposure
        # ended is dropped (never rendered from an extrapolation).
        wait_ns = round(c.max_truth_wait_ms * 1e6) + self._half_exposure_ns()
        late = 0
        while self.pending and t_ns - self.pending[0].t_ns > wait_ns:
            self.pending.popleft()
            late += 1
        if late and len(self.flange):  # before any flange truth, waiting_for_truth says it
            worth = [n for _ in range(late) if (n := count_decades(self.counts, "truth_late"))]
            if worth:
                out.append(self.event(
                    t_ns, pb.SEVERITY_WARNING, "truth_late",
                    f"dropped {late} capture(s): no truth at the end of the exposure within "
                    f"{c.max_truth_wait_ms:g} ms (flange truth up to {self.flange.last_ns} ns, "
                    f"target up to {self.tob.last_ns} ns; {self.counts['truth_late']} so far)"))
        return out

    def _ready(self, cap: _Capture) -> bool:
        end_ns = cap.t_ns + cap.half_exposure_ns
        return self.flange.covers(end_ns) and (not len(self.tob) or self.tob.covers(end_ns))

    def _render_ready(self, t_ns: int) -> list[Output]:
        out: list[Output] = []
        while self.pending and self._ready(self.pending[0]):
            out += self._render(self.pending.popleft())
        if self.pending:
            keep_ns = self.pending[0].t_ns - self.pending[0].half_exposure_ns
        else:
            keep_ns = t_ns - self._half_exposure_ns()
        self.flange.forget_before(keep_ns)
        self.tob.forget_before(keep_ns)
        return out

    def _camera_poses(self, t_ns: int) -> tuple[np.ndarray | None, np.ndarray]:
        """(camera_T_tob or None without a target, world_T_camera), mm, at ``t_ns``."""
        return self.frames.lookup("camera", "tob", t_ns), self.frames.lookup("world", "camera", t_ns)

    def _render(self, cap: _Capture) -> list[Output]:
        frames, t = self.frames, cap.t_ns
        world_T_flange, world_T_tob = frames.lookup("world", "flange", t), frames.lookup("world", "tob", t)
        world_T_camera = frames.lookup("world", "camera", t)
        cover = self._cover_at(cap.t_ns)
        # an ordinary stereo pair: each camera's image, side by side (left, right)
        renderers = cap.renderer.stereo_pair() if cap.renderer.config.stereo else (cap.renderer,)
        if cover is not None:
            renderers = tuple(r.covered(*cover) for r in renderers)
        if self.config.motion_blur:
            # The renderer integrates from the poses at the start of the exposure to those at
            # its end (linearly: an exposure is short against the truth's sample interval).
            start, end = (self._camera_poses(cap.t_ns + sign * cap.half_exposure_ns) for sign in (-1, 1))
            images = [r.render(*start, cap.frame_index, *end) for r in renderers]
        else:
            camera_T_tob = frames.lookup("camera", "tob", t)
            images = [r.render(camera_T_tob, world_T_camera, cap.frame_index) for r in renderers]
        pixels = images[0] if len(images) == 1 else np.hstack(images)
        truth = pb.Truth(header=self.next_header("sim_camera/truth", cap.t_ns, "world"))
        truth.world_T_flange.CopyFrom(pose_from_mm(world_T_flange))
        if world_T_tob is not None:
            truth.world_T_tob.CopyFrom(pose_from_mm(world_T_tob))
        if cover is not None:  # the cover this image was rendered with
            truth.cover_fraction.extend(cover[0])
            truth.cover_angle_rad.extend(cover[1])
        return [("camera/image", image(pixels, cap.stamp_ns, "camera")), ("sim_camera/truth", truth)]
