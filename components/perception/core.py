"""The perception core: ``camera/image`` -> ``perception/tob`` (+ ``perception/events``).

Per image (Section 4, steps 1-7):

1. decode and check the image (:func:`humanpt.perception.image.prepare`): a bad image
   (undecodable, empty, unsupported encoding, not the calibrated size, saturated) gives a
   LOST measurement and a warning event - one per run of bad images of the same kind, and
   an ``image_ok`` event when good images return;
2. while tracking (the last measurement was FULL and ``track_roi``), measure only a region
   of interest around the last measurement's centres; if that does not give a FULL
   measurement, measure the whole image in the same step (searching);
3. publish a :class:`TobMeasurement`: every accepted centre, the pairs (ordered A, B, C
   when FULL), the points in the camera frame (metres), ``camera_T_tob`` when FULL,
   ``visible`` (sources paired), ``quality``, ``method``, ``status``;
4. an info event ``tob_status`` whenever the status changes (full, position only, lost);
5. the mirror drift watch: the vertical disparity ``v_L - v_R`` of each FULL measurement's
   pairs in the rig's model (distortion removed, through the rig's rotations; 0 for mirrors
   the rig describes), a running median over ``drift_window`` measurements; above
   ``drift_warn_px`` (well below ``epipolar_tol_px``, where pairs are lost) a
   ``mirror_drift`` warning, once, then again only when it has grown by half the threshold
   more; a ``mirror_drift_ok`` info when it is back under 80 % of the threshold;
6. the blob checks (:mod:`humanpt.perception.checks`, in :class:`Perception`): a FULL
   measurement's sources are checked against the measured pose; the message carries
   ``degraded``, ``degraded_sources``, ``degraded_reason``, ``source_brightness``; a
   ``source_degraded`` warning when a source is first found degraded (again only when
   another one joins), a ``source_ok`` info after ``degraded_clear_frames`` checked
   measurements without one.

The core never raises out of ``step``: an unexpected error while measuring gives a LOST
measurement and an error event. It never reads the clock, so ``processing_s`` is 0 - a
measured time would make replays differ; ``humanpt bench perception`` measures the time.
"""

from __future__ import annotations

import statistics
from collections import deque

import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.geometry.rig import Rig
from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import image_stamp_ns, pose

from .checks import SOURCE_NAMES, SourceCheck
from .config import PerceptionConfig
from .correspondence import (
    FULL,
    LOST,
    POSITION_ONLY,
    Match,
    epipolar_residual_px,
    ideal_pixels,
    lost,
)
from .image import BadImage, prepare
from .pipeline import Perception, Result
from .stereo import StereoPerception

__all__ = ["PerceptionCore", "measurement_message"]

TOPIC = "perception/tob"
_STATUS = {
    FULL: pb.TOB_STATUS_FULL,
    POSITION_ONLY: pb.TOB_STATUS_POSITION_ONLY,
    LOST: pb.TOB_STATUS_LOST,
}
_METHOD = {"paper": pb.PERCEPTION_METHOD_PAPER, "weighted": pb.PERCEPTION_METHOD_WEIGHTED}


def measurement_message(
    header: pb.Header, method: str, uv_px: np.ndarray, match: Match,
    check: SourceCheck | None = None,
) -> pb.TobMeasurement:
    """A :class:`TobMeasurement` from centres (n, 2) px, a :class:`Match` (mm inside,
    metres in the message) and the blob checks (``degraded*``, ``source_brightness``)."""
    m = pb.TobMeasurement(
        header=header,
        visible=match.visible,
        quality=float(match.quality),
        method=_METHOD[method],
        status=_STATUS[match.status],
        processing_s=0.0,
    )
    # (repeated fields filled by add(): no intermediate message objects)
    add = m.centers_px.add
    for u, v in np.asarray(uv_px, dtype=float).reshape(-1, 2).tolist():
        add(u=u, v=v)
    add = m.pairs.add
    for (r, l), res in zip(match.pairs.tolist(), match.residual_px.tolist(), strict=True):
        add(right=int(r), left=int(l), residual_px=res)
    add = m.points_camera_m.add
    for x, y, z in np.asarray(match.camera_p_mm, dtype=float).reshape(-1, 3).tolist():
        add(x=x / 1000.0, y=y / 1000.0, z=z / 1000.0)
    if check is not None:
        m.degraded = bool(check.degraded)
        m.degraded_sources.extend(check.degraded)
        m.degraded_reason = check.reason
        m.source_brightness.extend(np.asarray(check.brightness, dtype=float).tolist())
    if match.camera_T_tob is not None:
        t = np.array(match.camera_T_tob, dtype=float)
        t[:3, 3] /= 1000.0
        m.camera_T_tob.CopyFrom(pose(t))
    return m


class PerceptionCore(Core):
    """Complex image -> tob measurement (module docstring)."""

    name = "perception"
    config_type = PerceptionConfig
    # Latest wins: a stale image is worth nothing once a newer one waits.
    ports = (Port("camera/image", RawImage, "_on_image", queue=1),)

    uses_rig = True

    def __init__(self, config: PerceptionConfig, rig: Rig | None = None):
        super().__init__(config, Rig() if rig is None else rig)
        self.perception = Perception(config, self.rig)
        # a rig of kind "stereo": camera/image is the pair side by side (perception/stereo.py)
        self.stereo = StereoPerception(config, self.rig) if self.rig.kind == "stereo" else None
        self._anchor: tuple[np.ndarray, np.ndarray] | None = None  # last FULL centres, sizes
        self._bad_code: str | None = None
        self._bad_count = 0
        self._status: str | None = None
        self._drift: deque[float] = deque(maxlen=config.drift_window)
        self._drift_warned_px: float | None = None  # |median| at the last mirror_drift warning
        self._degraded: tuple[int, ...] = ()  # sources reported degraded (source_degraded)
        self._clean = 0  # checked measurements without a degraded source since then
        self._saturated = False  # a blob_saturated warning stands (no blob_saturated_ok since)
        self.counters = {
            "images": 0,
            "bad_images": 0,
            "roi_hits": 0,
            "full_searches": 0,
            "errors": 0,
            "saturated_blobs": 0,  # paired blobs with more than saturated_blob_px pixels at 255
        }

    def on_config_changed(self, old: PerceptionConfig, new: PerceptionConfig) -> None:
        self.perception = Perception(new, self.rig)
        if self.stereo is not None:
            self.stereo = StereoPerception(new, self.rig)
        if new.drift_window != old.drift_window:
            self._drift = deque(self._drift, maxlen=new.drift_window)
        self._anchor = None  # search the whole image with the new settings

    # -- input -------------------------------------------------------------------------
    def warm_up(self) -> None:
        """A synthetic image of the target measured once (:meth:`Perception.warm_up`): the
        detector's compiled kernels are loaded (or, on a fresh install, compiled) before the
        live process says it is up. The core's state is not touched."""
        self.perception.warm_up()

    def _on_image(self, t_ns: int, msg: RawImage) -> list[Output]:
        self.counters["images"] += 1
        outputs: list[Output] = []
        c = self.perception.config
        stamp = t_ns
        try:
            # A stamp of 0 is a real capture time (a lock-step run starts at 0; the image of
            # that capture now arrives later): only a missing stamp falls back to arrival.
            stamp = image_stamp_ns(msg) if msg.HasField("timestamp") else t_ns
            size, keep = ((self.stereo.side_by_side_px, None) if self.stereo is not None
                          else (self.perception.size_px, self.perception.keep))
            prepared = prepare(msg, size, c.invert, keep, c.max_saturated_fraction)
        except Exception as e:  # noqa: BLE001 - the core never raises on input
            prepared = BadImage("bad_image", f"image could not be read: {type(e).__name__}: {e}")
        if isinstance(prepared, BadImage):
            self.counters["bad_images"] += 1
            self._anchor = None
            if prepared.code != self._bad_code:
                outputs.append(
                    self.event(
                        t_ns,
                        pb.SEVERITY_WARNING,
                        prepared.code,
                        f"perception: {prepared.text} (target reported lost)",
                    )
                )
                self._bad_code = prepared.code
            self._bad_count += 1
            return outputs + self._publish(t_ns, stamp, np.zeros((0, 2)), lost())
        if self._bad_code is not None:
            outputs.append(
                self.event(
                    t_ns,
                    pb.SEVERITY_INFO,
                    "image_ok",
                    f"perception: images good again after {self._bad_count} bad ones",
                )
            )
            self._bad_code, self._bad_count = None, 0
        if self.stereo is not None:
            try:
                uv, match = self.stereo.measure_side_by_side(prepared.gray)
            except Exception as e:  # noqa: BLE001 - the core never raises on input
                self.counters["errors"] += 1
                outputs.append(self.event(t_ns, pb.SEVERITY_ERROR, "perception_error",
                                          f"perception: measuring the stereo pair failed: {type(e).__name__}: {e}"))
                return outputs + self._publish(t_ns, stamp, np.zeros((0, 2)), lost())
            return outputs + self._publish(t_ns, stamp, uv, match)
        try:
            result = self._measure(prepared.gray)
        except Exception as e:  # noqa: BLE001 - the core never raises on input
            self.counters["errors"] += 1
            self._anchor = None
            outputs.append(
                self.event(
                    t_ns,
                    pb.SEVERITY_ERROR,
                    "perception_error",
                    f"perception: measuring failed: {type(e).__name__}: {e}",
                )
            )
            return outputs + self._publish(t_ns, stamp, np.zeros((0, 2)), lost())
        outputs += self._watch_drift(t_ns, result)
        outputs += self._watch_degraded(t_ns, result)
        outputs += self._watch_saturated(t_ns, result)
        return outputs + self._publish(t_ns, stamp, result.blobs.uv_px, result.match, result.check)

    def _watch_degraded(self, t_ns: int, result: Result) -> list[Output]:
        """``source_degraded`` (warning) when a source is first found degraded or the set of
        degraded sources grows; ``source_ok`` (info) after ``degraded_clear_frames``
        checked measurements without one. Measurements that are not checked (not FULL)
        change nothing."""
        check = result.check
        if check is None:
            return []
        c = self.perception.config
        if check.degraded:
            self._clean = 0
            grown = set(check.degraded) - set(self._degraded)
            if not grown:
                return []
            self._degraded = tuple(sorted(set(self._degraded) | grown))
            action = {"rebuild": "rebuilt from the other two and the target model",
                      "exclude": "left out (position only)",
                      "keep": "kept as measured"}[c.degraded_policy]
            if c.degraded_policy == "rebuild" and len(check.degraded) > 1:
                action = "left out (position only: more than one degraded)"
            names = ", ".join(SOURCE_NAMES[k] for k in self._degraded)
            return [self.event(t_ns, pb.SEVERITY_WARNING, "source_degraded",
                               f"perception: source(s) {names} not seen whole: {check.reason}; "
                               f"{action}")]
        if not self._degraded:
            return []
        self._clean += 1
        if self._clean < c.degraded_clear_frames:
            return []
        names = ", ".join(SOURCE_NAMES[k] for k in self._degraded)
        self._degraded, self._clean = (), 0
        return [self.event(t_ns, pb.SEVERITY_INFO, "source_ok",
                           f"perception: source(s) {names} seen whole again "
                           f"({c.degraded_clear_frames} checked measurements)")]

    def _watch_saturated(self, t_ns: int, result: Result) -> list[Output]:
        """Paired blobs with more than ``saturated_blob_px`` aperture pixels at full scale
        (their centres are biased: the peak is clipped) are counted
        (``counters["saturated_blobs"]``); a ``blob_saturated`` warning on the first
        measurement with one, a ``blob_saturated_ok`` info on the first one with paired
        blobs and none after it. Measurements without pairs, or from a detector that does
        not count (the paper method), change nothing."""
        full_scale = result.blobs.saturated_px
        pairs = result.paired.pairs
        if full_scale is None or not len(pairs):
            return []
        c = self.perception.config
        paired = full_scale[pairs.ravel()]
        count = int(np.count_nonzero(paired > c.saturated_blob_px))
        self.counters["saturated_blobs"] += count
        if count and not self._saturated:
            self._saturated = True
            return [self.event(t_ns, pb.SEVERITY_WARNING, "blob_saturated",
                               f"perception: {count} of {len(paired)} paired blobs have more than "
                               f"{c.saturated_blob_px} pixels at full scale (most: {int(paired.max())}): "
                               "their centres are biased; lower the exposure, the gain or the sources' current")]
        if not count and self._saturated:
            self._saturated = False
            return [self.event(t_ns, pb.SEVERITY_INFO, "blob_saturated_ok",
                               "perception: no paired blob saturated any more")]
        return []

    def _watch_drift(self, t_ns: int, result: Result) -> list[Output]:
        """The mirror drift watch (module docstring, step 5)."""
        match = result.paired
        if match.status != FULL or not len(match.pairs):
            return []
        residual = match.eq4_residual_px  # (when the correspondence computed them)
        if residual is None:
            params = self.perception.params
            uv = ideal_pixels(params, result.blobs.uv_px)
            right, left = match.pairs[:, 0], match.pairs[:, 1]
            residual = epipolar_residual_px(params, uv[right], uv[left])
        # epipolar_residual_px is v_R - v_L (scaled): the vertical disparity is its negative
        self._drift.append(-sum(residual.tolist()) / len(residual))
        c = self.perception.config
        if len(self._drift) < min(c.drift_window, 10):
            return []
        # (the residuals of FULL measurements passed the gates: finite. statistics.median
        # is np.median's (a + b) / 2 on floats without its ~15 us of overhead)
        level = statistics.median(self._drift)
        size = abs(level)
        warned = self._drift_warned_px
        if size > c.drift_warn_px and (warned is None or size >= warned + 0.5 * c.drift_warn_px):
            self._drift_warned_px = size
            return [self.event(t_ns, pb.SEVERITY_WARNING, "mirror_drift",
                               f"perception: the mirrors drift: vertical disparity v_L - v_R {level:+.2f} px "
                               f"(limit {c.drift_warn_px:g} px; pairs are lost at {c.epipolar_tol_px:g} px): "
                               "check them (humanpt calibrate mirrors)")]
        if warned is not None and size < 0.8 * c.drift_warn_px:
            self._drift_warned_px = None
            return [self.event(t_ns, pb.SEVERITY_INFO, "mirror_drift_ok",
                               f"perception: vertical disparity back in range ({level:+.2f} px)")]
        return []

    def _measure(self, gray: np.ndarray) -> Result:
        p = self.perception
        if p.config.track_roi and self._anchor is not None:
            result = p.track(gray, *self._anchor)
            if result.paired.status == FULL:
                self.counters["roi_hits"] += 1
                self._remember(result)
                return result
        self.counters["full_searches"] += 1
        result = p.measure(gray)
        self._remember(result)
        return result

    def _remember(self, result: Result) -> None:
        # (the sources found, also one the blob checks left out: the region keeps it)
        if result.paired.status == FULL:
            used = result.paired.pairs.ravel()
            self._anchor = (result.blobs.uv_px[used], result.blobs.size_px[used])
        else:
            self._anchor = None

    def _publish(self, t_ns: int, stamp_ns: int, uv_px: np.ndarray, match: Match,
                 check: SourceCheck | None = None) -> list[Output]:
        outputs: list[Output] = []
        if match.status != self._status:
            before = self._status or "none"
            outputs.append(
                self.event(
                    t_ns,
                    pb.SEVERITY_INFO,
                    "tob_status",
                    f"perception: target {before} -> {match.status} "
                    f"({match.visible} source(s) paired)",
                )
            )
            self._status = match.status
        header = self.next_header(TOPIC, stamp_ns, "camera")
        outputs.insert(
            0, (TOPIC, measurement_message(header, self.perception.config.method, uv_px, match, check))
        )
        return outputs
