"""The limits a seam, a path file and an exported program are held to: one place.

The feed and angular limits and the workspace box are the cell's defaults, which are the
robot gateway's (:mod:`humanpt.runtime.cell_limits`: the paper's step controller,
100 mm/s and 60 deg/s, and the workspace box humanpt drives the robot in), so
``humanpt path retime`` (its ``--max-speed``/``--max-angular`` defaults),
``humanpt path export`` (``--max-speed``, ``--envelope``) and the gateway agree unless a
user changes one.  The rest bound what a file may hold at all (the readers,
:mod:`humanpt.seam.seamfile` and :mod:`humanpt.controller.pathfile`, refuse beyond them,
naming the field): nothing reaches the maths or a robot program as ``inf``, ``nan`` or
a 309-digit number.
"""

from __future__ import annotations

from humanpt.runtime import cell_limits

# Feed along the seam and the torch's turn rate (mm/s, deg/s): the default limits.
MAX_SPEED_MM_S: float = cell_limits.MAX_SPEED_MM_S
MAX_ANGULAR_DEG_S: float = cell_limits.MAX_ANGULAR_SPEED_DEG_S
# No speed limit may be set above this (mm/s), whatever a user asks: a welding feed is
# well under it, a robot's TCP limit about it.
SPEED_CEILING_MM_S = 1000.0
# No acceleration (mm/s^2) above this: URScript's ``a`` and retime's limit (10 m/s^2).
ACCEL_CEILING_MM_S2 = 10_000.0

# The workspace every exported pose must lie in (world frame, mm): the gateway's box.
ENVELOPE_MIN_MM: tuple[float, float, float] = cell_limits.ENVELOPE_MIN_MM
ENVELOPE_MAX_MM: tuple[float, float, float] = cell_limits.ENVELOPE_MAX_MM

# What a seam or path file may hold at all.
MAX_ABS_MM = 10_000.0  # any position or length (10 m: no robot cell is larger)
MAX_ABS_DEG = 720.0  # any Z-Y-X angle (the recorder writes -180..180)
MIN_ARC_RADIUS_MM = 1.0  # an arc tighter than this is a corner, not an arc (and its circle is ill-defined)
MAX_DWELL_S = 3600.0  # a dwell (s): a torch held still longer is a stop, not a weld's dwell
MAX_TIME_S = 86_400.0  # a timed sample's time (s from the start: one day)
MAX_INDEX = 2**31 - 1  # an index into a path's points
MAX_COV = 1e8  # a covariance term (mm^2 or deg^2: a 10 m standard deviation)
MAX_TOOL_MM = 2000.0  # the tool's offset from the flange (mm)
