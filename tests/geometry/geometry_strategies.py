"""Hypothesis strategies shared by the geometry tests (imported as a sibling module)."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from humanpt.geometry import PsvsParams, TargetModel, transform_from_x


def finite(lo: float, hi: float):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def psvs_params(draw, distortion: bool = True) -> PsvsParams:
    """A plausible PSVS: focal lengths, skew, image centres, baseline and mirror vary."""
    a_u = draw(finite(500.0, 3000.0))
    dist = (0.0,) * 5
    if distortion and draw(st.booleans()):
        dist = (
            draw(finite(-0.15, 0.15)),
            draw(finite(-0.03, 0.03)),
            draw(finite(-1e-3, 1e-3)),
            draw(finite(-1e-3, 1e-3)),
            0.0,
        )
    return PsvsParams.from_mirror(
        thickness_mm=draw(finite(0.0, 3.0)),
        omega1_deg=draw(finite(30.0, 60.0)),
        n_glass=draw(finite(1.4, 1.9)),
        a_u=a_u,
        a_v=a_u * draw(finite(0.95, 1.05)),
        skew=draw(finite(-3.0, 3.0)),
        u0=draw(finite(280.0, 360.0)),
        v0=draw(finite(200.0, 280.0)),
        u0_left=draw(st.one_of(st.none(), finite(280.0, 360.0))),
        v0_left=draw(st.one_of(st.none(), finite(200.0, 280.0))),
        baseline_mm=draw(finite(30.0, 150.0)),
        dist_coeffs=dist,
    )


@st.composite
def scene_points(draw) -> np.ndarray:
    """A point in front of the PSVS, inside a ~40 deg cone, 300..2000 mm away."""
    z = draw(finite(300.0, 2000.0))
    return np.array([draw(finite(-0.35, 0.35)) * z, draw(finite(-0.35, 0.35)) * z, z])


@st.composite
def tob_poses(draw, max_tilt_deg: float = 60.0) -> np.ndarray:
    """camera_T_tob of a TOB 400..1200 mm in front of the camera, its lit face towards the
    camera (w, the underside normal, within max_tilt_deg of the optical axis)."""
    z = draw(finite(400.0, 1200.0))
    x = [
        draw(finite(-0.2, 0.2)) * z,
        draw(finite(-0.2, 0.2)) * z,
        z,
        draw(finite(-180.0, 180.0)),
        draw(finite(-max_tilt_deg / 1.5, max_tilt_deg / 1.5)),
        draw(finite(-max_tilt_deg / 1.5, max_tilt_deg / 1.5)),
    ]
    return transform_from_x(np.array(x))


@st.composite
def target_models(draw) -> TargetModel:
    leg = draw(finite(25.0, 80.0))
    ratio = draw(st.one_of(finite(0.3, 0.8), finite(1.25, 1.8)))
    return TargetModel.isosceles(leg_mm=leg, base_mm=leg * ratio, side_tolerance_mm=1.0)


@st.composite
def rigid_transforms(draw, max_translation_mm: float = 2000.0) -> np.ndarray:
    t = [draw(finite(-max_translation_mm, max_translation_mm)) for _ in range(3)]
    ypr = [draw(finite(-179.0, 179.0)), draw(finite(-89.0, 89.0)), draw(finite(-179.0, 179.0))]
    return transform_from_x(np.array(t + ypr))
