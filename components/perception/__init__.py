"""Perception: a complex image -> the target's 2D centres, left/right pairs, 3D points and
frame (Section 4, steps 1-7 of Pachidis et al.).

Two methods: ``paper`` (the reference: threshold, 9 x 9 cross-template seeds, shape means,
scan-line pairing, eq. (4)) and ``weighted`` (the default: background-subtracted weighted
subpixel centroids, shape checks, scored correspondence). Both check each source's blobs
of a FULL measurement against the measured pose (``checks``: a partly covered or merged
source is flagged "degraded" and rebuilt, excluded or kept). See ``README.md``.
"""

from .blobs import Blobs, Region, find_shapes
from .checks import CheckSettings, SourceCheck, apply_policy, check_sources, rebuild_point
from .config import METHODS, PerceptionConfig
from .core import PerceptionCore, measurement_message
from .correspondence import (
    FULL,
    LOST,
    POSITION_ONLY,
    Match,
    MatchSettings,
    epipolar_residual_px,
    match_scan_line,
    match_scored,
)
from .image import BadImage, Prepared, prepare
from .paper import cross_kernel, detect_paper, pair_by_scan_line, seed_mask
from .pipeline import Perception, Result
from .weighted import background_and_noise, detect_weighted

__all__ = [
    "BadImage",
    "Blobs",
    "CheckSettings",
    "SourceCheck",
    "apply_policy",
    "check_sources",
    "rebuild_point",
    "FULL",
    "LOST",
    "METHODS",
    "Match",
    "MatchSettings",
    "POSITION_ONLY",
    "Perception",
    "PerceptionConfig",
    "PerceptionCore",
    "Prepared",
    "Region",
    "Result",
    "background_and_noise",
    "cross_kernel",
    "detect_paper",
    "detect_weighted",
    "epipolar_residual_px",
    "find_shapes",
    "match_scan_line",
    "match_scored",
    "measurement_message",
    "pair_by_scan_line",
    "prepare",
    "seed_mask",
]
