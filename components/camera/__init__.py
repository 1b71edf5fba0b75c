"""The real camera: OpenCV VideoCapture (device or video file), an image folder or a GenICam
camera (harvesters, ``genicam.py``) -> ``camera/image``.

The pure core (``core``) checks and converts captured frames; the grabbing lives in the
live shell's adapter (``capture``). See ``README.md`` in this folder.
"""

from humanpt.runtime.lazy import lazy_exports

# name -> the submodule that defines it, imported on first use (PEP 562): validating a
# config file imports only ``.config``, so the server's install (no OpenCV) reads the
# client's sections too (requirements/server.txt).
_EXPORTS = {
    "CaptureAdapter": "capture",
    "capture_adapters": "capture",
    "capture_message": "capture",
    "read_frames": "capture",
    "CameraConfig": "config",
    "CameraCore": "core",
}


__getattr__ = lazy_exports(__name__, _EXPORTS)


__all__ = [
    "CameraConfig",
    "CameraCore",
    "CaptureAdapter",
    "capture_adapters",
    "capture_message",
    "read_frames",
]
