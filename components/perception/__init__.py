"""Perception: a complex image -> the target's 2D centres, left/right pairs, 3D points and
frame (Section 4, steps 1-7 of Pachidis et al.).

Two methods: ``paper`` (the reference: threshold, 9 x 9 cross-template seeds, shape means,
scan-line pairing, eq. (4)) and ``weighted`` (the default: background-subtracted weighted
subpixel centroids, shape checks, scored correspondence). Both check each source's blobs
of a FULL measurement against the measured pose (``checks``: a partly covered or merged
source is flagged "degraded" and rebuilt, excluded or kept). See ``README.md``.
"""

from humanpt.runtime.lazy import lazy_exports

# name -> the submodule that defines it, imported on first use (PEP 562): validating a
# config file imports only ``.config``, so the server's install (no OpenCV) reads the
# client's sections too (requirements/server.txt).
_EXPORTS = {
    "Blobs": "blobs",
    "Region": "blobs",
    "find_shapes": "blobs",
    "CheckSettings": "checks",
    "SourceCheck": "checks",
    "apply_policy": "checks",
    "check_sources": "checks",
    "rebuild_point": "checks",
    "METHODS": "config",
    "PerceptionConfig": "config",
    "PerceptionCore": "core",
    "measurement_message": "core",
    "FULL": "correspondence",
    "LOST": "correspondence",
    "POSITION_ONLY": "correspondence",
    "Match": "correspondence",
    "MatchSettings": "correspondence",
    "epipolar_residual_px": "correspondence",
    "match_scan_line": "correspondence",
    "match_scored": "correspondence",
    "BadImage": "image",
    "Prepared": "image",
    "prepare": "image",
    "cross_kernel": "paper",
    "detect_paper": "paper",
    "pair_by_scan_line": "paper",
    "seed_mask": "paper",
    "Perception": "pipeline",
    "Result": "pipeline",
    "background_and_noise": "weighted",
    "detect_weighted": "weighted",
}


__getattr__ = lazy_exports(__name__, _EXPORTS)


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
