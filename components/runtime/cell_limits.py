"""The cell's default safety limits, one place (SI at the edges: mm, deg, as in the config).

The robot gateway enforces them (its config's defaults), the controller checks a playback
against the same box before anything moves, and the seam tools (`humanpt path retime`,
`path export`) hold a seam to them; a cell's config may change the gateway's, and the
others then read that cell's values (or take these defaults).
"""

from __future__ import annotations

# The paper's step controller: 100 mm/s and 60 deg/s (per cycle: speed x cycle period).
MAX_SPEED_MM_S = 100.0
MAX_ANGULAR_SPEED_DEG_S = 60.0
# The workspace box humanpt drives the robot in (world frame, mm): lower and upper corner.
ENVELOPE_MIN_MM: tuple[float, float, float] = (-1600.0, -1600.0, -1400.0)
ENVELOPE_MAX_MM: tuple[float, float, float] = (1600.0, 1600.0, 1600.0)
