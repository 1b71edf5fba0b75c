"""The rig: where the PSVS sits on the flange, and where the servo wants the target.

``DEFAULT_FLANGE_T_CAMERA_MM`` is the one default hand-eye transform (``F T_C`` of the
paper, Section 4) that every component uses unless configured otherwise: the camera's
axes parallel to the flange's (optical axis along the flange z axis) and its optical
centre 60 mm off the tool axis along flange y and 100 mm out along flange z. The paper
measures its own by hand-eye calibration [42]; this value is an assumption.

Section 5: the desired point D lies on the camera z axis at ``d_z`` (600 mm in the
paper's experiments), with its frame parallel to the camera frame, so at convergence
``camera_T_tob = camera_T_desired(d_z)``.
"""

from __future__ import annotations

import numpy as np

from .transforms import compose, invert_transform, make_transform

__all__ = [
    "DEFAULT_FLANGE_T_CAMERA_MM",
    "DEFAULT_DZ_MM",
    "camera_T_desired",
    "flange_T_desired",
    "viewing_world_T_flange",
]

DEFAULT_FLANGE_T_CAMERA_MM: np.ndarray = make_transform(np.eye(3), np.array([0.0, 60.0, 100.0]))
DEFAULT_FLANGE_T_CAMERA_MM.setflags(write=False)  # a shared constant: never modified in place

DEFAULT_DZ_MM = 600.0
"""The paper's distance d_z of the desired point D from the camera (Section 6)."""


def camera_T_desired(dz_mm: float = DEFAULT_DZ_MM) -> np.ndarray:
    """Section 5: the desired point D frame in the camera frame: on the optical axis at
    ``dz_mm`` (mm, > 0), axes parallel to the camera's. (4, 4), mm."""
    dz_mm = float(dz_mm)
    if not (np.isfinite(dz_mm) and dz_mm > 0):
        raise ValueError(f"dz_mm must be finite and > 0, got {dz_mm}")
    return make_transform(np.eye(3), np.array([0.0, 0.0, dz_mm]))


def flange_T_desired(
    flange_T_camera: np.ndarray = DEFAULT_FLANGE_T_CAMERA_MM, dz_mm: float = DEFAULT_DZ_MM
) -> np.ndarray:
    """Section 5: the desired point D frame in the flange frame, ``flange_T_camera @
    camera_T_desired(dz_mm)``: where the servo drives the target. (4, 4), mm in, mm out."""
    return np.asarray(flange_T_camera, dtype=float) @ camera_T_desired(dz_mm)


def viewing_world_T_flange(
    world_T_tob: np.ndarray,
    dz_mm: float = DEFAULT_DZ_MM,
    flange_T_camera: np.ndarray = DEFAULT_FLANGE_T_CAMERA_MM,
) -> np.ndarray:
    """The flange pose (4, 4), mm, at which the servo has converged on a target at
    ``world_T_tob``: the TOB origin G on the camera's optical axis at ``dz_mm`` and the TOB
    frame parallel to the camera frame, i.e. ``camera_T_tob = camera_T_desired(dz_mm)``.
    ``world_T_flange = world_T_tob @ inv(camera_T_desired) @ inv(flange_T_camera)``.
    A robot started here sees the target from the first image."""
    return compose(
        np.asarray(world_T_tob, dtype=float),
        invert_transform(camera_T_desired(dz_mm)),
        invert_transform(np.asarray(flange_T_camera, dtype=float)),
    )
