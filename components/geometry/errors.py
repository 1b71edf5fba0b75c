"""Exceptions raised by the geometry library."""

from __future__ import annotations

__all__ = ["GeometryError"]


class GeometryError(ValueError):
    """Degenerate or inconsistent geometric input.

    Raised, with a message that says what was wrong and by how much, for: points behind a
    (virtual) camera, zero disparity (a point at infinity), collinear or coincident light
    sources, a triangle whose sides do not match the target model, an ambiguous labelling,
    a non-rigid transform, too few or too poorly spread calibration samples, and an
    undistortion that does not converge. It subclasses :class:`ValueError`, so callers that
    already catch bad values keep working.
    """
