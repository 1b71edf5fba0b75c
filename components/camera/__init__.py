"""The real camera: OpenCV VideoCapture (device or video file) -> ``camera/image``.

The pure core (``core``) checks and converts captured frames; the grabbing lives in the
live shell's adapter (``capture``). See ``README.md`` in this folder.
"""

import importlib

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


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


__all__ = [
    "CameraConfig",
    "CameraCore",
    "CaptureAdapter",
    "capture_adapters",
    "capture_message",
    "read_frames",
]
