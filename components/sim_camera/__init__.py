"""The simulated PSVS camera: renders the complex image of the twin's truth.

``render`` is the pure renderer (usable without the runtime); ``core`` is the component
(``humanpt sim_camera``). See ``README.md`` in this folder.
"""

from .config import PsvsConfig, SimCameraConfig
from .core import SimCameraCore, truth_poses
from .render import Blobs, Discs, Renderer, coverage, intensity_centroid, occlusion_offset

__all__ = [
    "Blobs",
    "Discs",
    "PsvsConfig",
    "Renderer",
    "SimCameraConfig",
    "SimCameraCore",
    "coverage",
    "intensity_centroid",
    "occlusion_offset",
    "truth_poses",
]
