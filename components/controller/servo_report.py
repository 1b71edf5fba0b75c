"""How the servo did on a run, from the controller's own status messages (no twin needed):
the error it saw, how much of the field of view was left, how often the limits bound.

``servo_summary(src)`` takes anything with ``outputs(topic)`` returning delivered messages
with ``.data`` (a lock-step :class:`~humanpt.twin.world.TwinWorld`, or a recorded run,
:class:`humanpt.twin.evaluate.RunOutputs`), or a list of :class:`ControllerStatus`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humanpt.schemas import humanpt_pb2 as pb

__all__ = ["ServoSummary", "servo_summary"]


@dataclass(frozen=True)
class ServoSummary:
    """Over the cycles with a target (status ``visible`` > 0) from ``after_ns`` on."""

    cycles: int  # cycles with a target
    max_error_mm: float  # the largest |G - D| the controller saw (its own estimate)
    max_error_deg: float  # the largest angle between G's and D's frames
    min_fov_margin_px: float  # the least distance of a source image to the image border
    max_image_error_px: float  # the largest offset of G's image from where G at D appears
    saturated_cycles: int  # cycles whose command hit the speed limits
    lagging_cycles: int  # cycles where position_first let the orientation lag
    min_rotation_scale: float  # the least fraction of the demanded swinging rotation commanded

    def line(self) -> str:
        """One line for a report."""
        return (f"servo: |G-D| max {self.max_error_mm:.2f} mm, {self.max_error_deg:.2f} deg; field of view margin "
                f"min {self.min_fov_margin_px:.0f} px, G's image offset max {self.max_image_error_px:.1f} px; "
                f"saturated {self.saturated_cycles} of {self.cycles} cycles (orientation lagging in "
                f"{self.lagging_cycles}, rotation scale min {self.min_rotation_scale:.2f})")


def servo_summary(src, after_ns: int = 0) -> ServoSummary:
    """The :class:`ServoSummary` of a run's ``controller/status`` messages stamped at or
    after ``after_ns`` (e.g. when the target started moving)."""
    if isinstance(src, list | tuple):
        statuses = list(src)
    else:
        statuses = [pb.ControllerStatus.FromString(o.data) for o in src.outputs("controller/status")]
    st = [s for s in statuses if s.visible and s.header.stamp_ns >= after_ns]
    if not st:
        nan = float("nan")
        return ServoSummary(0, nan, nan, nan, nan, 0, 0, nan)
    a = np.array([(s.error_translation_m * 1e3, np.degrees(s.error_rotation_rad), s.fov_margin_px, s.image_error_px,
                   s.saturated, s.rotation_scale) for s in st])
    return ServoSummary(len(st), float(a[:, 0].max()), float(a[:, 1].max()), float(a[:, 2].min()),
                        float(a[:, 3].max()), int(a[:, 4].sum()), int((a[:, 5] < 1.0).sum()), float(a[:, 5].min()))
