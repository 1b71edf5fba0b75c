"""The real camera: OpenCV VideoCapture (device or video file) -> ``camera/image``.

The pure core (``core``) checks and converts captured frames; the grabbing lives in the
live shell's adapter (``capture``). See ``README.md`` in this folder.
"""

from .capture import CaptureAdapter, capture_adapters, capture_message, read_frames
from .config import CameraConfig
from .core import CameraCore

__all__ = [
    "CameraConfig",
    "CameraCore",
    "CaptureAdapter",
    "capture_adapters",
    "capture_message",
    "read_frames",
]
