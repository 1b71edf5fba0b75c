"""Getting a complex image ready for either method: decode, check, grey, invert, mask.

Section 4 steps 1-3: the image is captured (a ``foxglove.RawImage``), masked if necessary
and inverted if that property is selected. Here inversion means the sources are *darker*
than the background, so both methods work on ``255 - I`` and always look for bright
shapes (the paper inverts its binary image for the same reason: its template looks for
shapes of one colour). Masked pixels are set to 0, i.e. to "no source".

Nothing here raises on a bad image: :func:`prepare` returns a :class:`BadImage` that says
what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from humanpt.schemas.convert import MessageError, from_image

__all__ = ["BadImage", "Prepared", "prepare", "to_mono8", "mask_array", "apply_mask"]


@dataclass(frozen=True)
class BadImage:
    """An image that cannot be measured. ``code``: ``bad_image`` (undecodable, empty, bad
    encoding), ``wrong_size`` (not the calibrated PSVS size) or ``saturated`` (too many
    pixels at full scale); ``text`` says it for a person."""

    code: str
    text: str


@dataclass(frozen=True)
class Prepared:
    """A measurable image: ``gray`` (H, W) uint8, sources bright, masked pixels 0;
    ``mask`` (H, W) uint8 (255 = usable) or None when nothing is masked."""

    gray: np.ndarray
    mask: np.ndarray | None


def to_mono8(pixels: np.ndarray, encoding: str) -> np.ndarray:
    """Any supported encoding -> (H, W) uint8: colour to grey (ITU-R 601 weights, as
    OpenCV), mono16 scaled by 255/65535."""
    if encoding == "mono8":
        return pixels
    if encoding == "mono16":
        return cv2.convertScaleAbs(pixels, alpha=255.0 / 65535.0)
    if encoding == "rgb8":
        return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_RGB2GRAY)
    if encoding == "bgr8":
        return cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_BGR2GRAY)
    raise ValueError(f"unsupported encoding {encoding!r}")


def mask_array(
    rects: tuple[tuple[int, int, int, int], ...], size_px: tuple[int, int]
) -> np.ndarray | None:
    """Rectangles ``(u, v, width, height)`` (px) -> (H, W) uint8, 0 inside a rectangle and
    255 elsewhere; None for no rectangles. Rectangles may reach outside the image."""
    if not rects:
        return None
    width, height = size_px
    keep = np.full((height, width), 255, np.uint8)
    for u, v, w, h in rects:
        keep[max(v, 0) : max(v + h, 0), max(u, 0) : max(u + w, 0)] = 0
    return keep


def apply_mask(gray: np.ndarray, keep: np.ndarray | None) -> np.ndarray:
    """Masked pixels set to 0 (a copy when anything is masked)."""
    if keep is None:
        return gray
    return cv2.bitwise_and(gray, keep)


def prepare(
    msg,
    size_px: tuple[int, int],
    invert: bool,
    keep: np.ndarray | None,
    max_saturated_fraction: float,
) -> Prepared | BadImage:
    """Decode and check a RawImage; return the grey image both methods measure.

    ``size_px`` (width, height) is the calibrated PSVS image size - another size would
    make every pixel coordinate meaningless, so it is refused. ``keep`` comes from
    :func:`mask_array`. An image with more than ``max_saturated_fraction`` of its pixels at
    full scale (255, after inversion: 0 before it) is refused as saturated.
    """
    try:
        pixels = from_image(msg)
    except MessageError as e:
        return BadImage("bad_image", f"undecodable image: {e}")
    width, height = size_px
    if pixels.shape[1] != width or pixels.shape[0] != height:
        return BadImage(
            "wrong_size",
            f"image is {pixels.shape[1]}x{pixels.shape[0]} px but the rig's camera is calibrated for "
            f"{width}x{height} px",
        )
    gray = to_mono8(pixels, msg.encoding)
    if invert:
        gray = cv2.bitwise_not(gray)
    # (the maximum first: a frame without a full-scale pixel needs no count)
    saturated = 0 if gray.max() < 255 else cv2.countNonZero(cv2.compare(gray, 254, cv2.CMP_GT))
    if saturated > max_saturated_fraction * gray.size:
        return BadImage(
            "saturated",
            f"{100.0 * saturated / gray.size:.0f} % of the pixels are saturated "
            f"(limit {100.0 * max_saturated_fraction:.0f} %): exposure or inversion is wrong",
        )
    return Prepared(apply_mask(gray, keep), keep)
