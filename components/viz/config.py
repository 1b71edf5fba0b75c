"""Configuration of the viz component (section ``[viz]``).

Where the rerun data goes (``mode``), how much of the camera stream is shown, and the
desired point D's distance.  The rest of the geometry the views need (the hand-eye
transform: where the camera frustum sits on the flange; the PSVS: to project expected
source positions into the complex image; the target's shape) is the rig's.  ``humanpt
view`` takes d_z and the rig from the run's recordings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

from humanpt.geometry import DEFAULT_DZ_MM
from humanpt.runtime.config import Range, live

__all__ = ["VizConfig", "MODES"]

MODES = ("spawn", "serve", "connect", "save")



@dataclass(frozen=True)
class VizConfig:
    """``[viz]``: the live rerun view (README.md has the table).

    ``mode``: ``spawn`` a local viewer (on a machine without a display: serve instead),
    ``serve`` a gRPC server that viewers on other machines connect to
    (``rerun --connect rerun+http://HOST:PORT/proxy``), ``connect`` to a viewer already
    running at ``connect_url``, or ``save`` to an .rrd file headless. ``rrd_path``: the
    file of ``save`` (empty: ``<run dir>/viz.rrd``); in the other modes a non-empty path
    is written as well.
    """

    mode: Literal["spawn", "serve", "connect", "save"] = "spawn"
    rrd_path: str = ""
    grpc_port: Annotated[int, Range(0, 65535, "TCP port")] = 9876
    bind_ip: str = "0.0.0.0"
    connect_url: str = "rerun+http://127.0.0.1:9876/proxy"
    server_memory_limit: str = "1GiB"
    application_id: str = "humanpt"
    # What the core forwards to the viewer (pure, replayable decimation).
    # Every 2nd image by default: ~15 Hz of a 30 Hz camera is plenty to watch, and each shown
    # image is recorded twice in viz.mcap (as input and as the forwarded copy).
    image_every: Annotated[int, Range(1, 10000, "images")] = live(2, "show every Nth camera image (1: all)")
    # Display transfer of 8-bit images: shown = 255 * (raw / 255) ** display_gamma. The complex
    # image is small bright sources on a nearly black background; below 1 the background and
    # the sources' halos show at panel size (1: the raw image). Display only: what perception
    # sees and what is recorded are untouched.
    display_gamma: Annotated[float, Range(0.1, 1.0, "")] = 0.5
    # Geometry the views need beyond the rig (the messages carry poses; the hand-eye, the
    # PSVS and the target come from the rig).  D's distance at start; the view follows the
    # controller's dz_mm changes (its events).
    dz_mm: Annotated[float, Range(10, 5000, "mm")] = DEFAULT_DZ_MM
    # (The cycle, to draw per-cycle steps as speeds, is the robot link's, from the robot
    # states: RobotState.cycle_period_ns, humanpt.runtime.cycle.)
    # The recorded path is drawn as line strips of at most this many points each (a new
    # strip starts when one is full, so a long path is not re-sent whole at every point).
    path_strip_points: Annotated[int, Range(2, 10000000, "points")] = 200
    # Each path point's position uncertainty is drawn as an ellipsoid of this many standard
    # deviations, magnified (1: true size; the filter's ~1 mm sd is small beside a 0.5 m
    # seam, a held orientation's tip tens of mm): half axes = path_sigmas * magnify * sd.
    path_sigmas: Annotated[float, Range(0.1, 10, "sd")] = 3.0
    path_sigma_magnify: Annotated[float, Range(0.01, 10000, "")] = 1.0

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"viz.mode must be one of {MODES}, got {self.mode!r}")
        if (
            isinstance(self.grpc_port, bool)
            or not isinstance(self.grpc_port, int)
            or not 0 < self.grpc_port < 65536
        ):
            raise ValueError(f"viz.grpc_port must be a TCP port (1..65535), got {self.grpc_port!r}")
        if not self.connect_url.startswith(("rerun://", "rerun+http://", "rerun+https://")):
            raise ValueError(
                f"viz.connect_url must be a rerun gRPC URL (rerun+http://HOST:PORT/proxy), "
                f"got {self.connect_url!r}"
            )
        if (
            isinstance(self.image_every, bool)
            or not isinstance(self.image_every, int)
            or self.image_every < 1
        ):
            raise ValueError(f"viz.image_every must be an integer >= 1, got {self.image_every!r}")
        for name in ("dz_mm",):
            v = getattr(self, name)
            if (
                isinstance(v, bool)
                or not isinstance(v, int | float)
                or not math.isfinite(v)
                or v <= 0
            ):
                raise ValueError(f"viz.{name} must be a finite number > 0, got {v!r}")
        for name in ("path_sigmas", "path_sigma_magnify"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"viz.{name} must be a finite number > 0, got {v!r}")
        if (
            isinstance(self.path_strip_points, bool)
            or not isinstance(self.path_strip_points, int)
            or self.path_strip_points < 2
        ):
            raise ValueError(
                f"viz.path_strip_points must be an integer >= 2, got {self.path_strip_points!r}"
            )
