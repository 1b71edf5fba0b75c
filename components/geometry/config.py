"""The PSVS geometry as configuration keys: the rig's ``[psvs]`` (what the pipeline
believes) and ``[sim_camera.psvs]`` (the twin's truth): one dataclass, so both always mean
the same thing."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from humanpt.runtime.config_types import Range

from .psvs import PsvsParams, psvs_m_l_mm

__all__ = ["PsvsConfig"]

_M_MM, _L_MM = psvs_m_l_mm(1.0, 45.0, 1.5, 1.0)

# A distortion coefficient (OpenCV's k1, k2, p1, p2, k3): real lenses stay well inside.
Dist = Annotated[float, Range(-100.0, 100.0, "")]
# A virtual camera's principal-point offset from the real camera's (u0, v0).
OffsetPx = Annotated[float, Range(-1000.0, 1000.0, "px")]
# One component of a virtual camera's rotation vector (mirror misalignment).
RotDeg = Annotated[float, Range(-10.0, 10.0, "deg")]


@dataclass(frozen=True)
class PsvsConfig:
    """The PSVS geometry as config keys, see :class:`humanpt.geometry.PsvsParams`.

    Defaults: the issue's sensor - 640 x 480, a_u = a_v = 1000 px, centre (320, 240),
    baseline 90 mm, m, l of a 1 mm beam splitter at 45 deg (eq. (5), (6)), no distortion,
    both virtual cameras parallel to the real one with its principal point.

    Each virtual camera's own optics (all zero by default = the paper's ideal PSVS):
    ``du0_right_px, dv0_right_px, du0_left_px, dv0_left_px`` offset that view's principal
    point from (u0, v0) (px; the lens distortion stays centred on (u0, v0)); a realistic
    residual after calibration is ~0.5 px. ``rotvec_right_deg``, ``rotvec_left_deg`` rotate
    that virtual camera's axes (rotation vector, deg, camera frame): a mirror tilted by
    alpha gives 2 alpha (:func:`humanpt.geometry.virtual_rotation_from_mirror_tilt_deg`);
    about y it pans the view (image shift -a_u tan(angle) along u: 0.05 deg = 0.87 px, a
    z bias of 4.6 mm at 645 mm with b = 90 mm), about x it tilts it (along v: the views leave their common
    scan line). A hand-aligned mirror pair is good to ~0.01-0.05 deg.

    ``splitter_thickness_mm`` (None: use ``m_mm``, ``l_mm``): the beam splitter's
    thickness d, from which m and l follow by eq. (5), (6) at the paper's 45 deg and
    n = 1.5 (m = 0.329 d, l = 0.378 d); give it or m, l, not both. A plate's tolerance is
    ~0.05-0.1 mm."""

    image_width_px: Annotated[int, Range(1, 20000, "px")] = 640
    image_height_px: Annotated[int, Range(1, 20000, "px")] = 480
    a_u: Annotated[float, Range(1, 1e6, "px")] = 1000.0
    a_v: Annotated[float, Range(1, 1e6, "px")] = 1000.0
    skew: Annotated[float, Range(-1e4, 1e4, "px")] = 0.0
    u0: Annotated[float, Range(-1e5, 1e5, "px")] = 320.0
    v0: Annotated[float, Range(-1e5, 1e5, "px")] = 240.0
    baseline_mm: Annotated[float, Range(0.1, 10000, "mm")] = 90.0
    m_mm: Annotated[float, Range(-1e4, 1e4, "mm")] = _M_MM
    l_mm: Annotated[float, Range(-1e4, 1e4, "mm")] = _L_MM
    dist_coeffs: tuple[Dist, Dist, Dist, Dist, Dist] = (0.0, 0.0, 0.0, 0.0, 0.0)
    du0_right_px: OffsetPx = 0.0
    dv0_right_px: OffsetPx = 0.0
    du0_left_px: OffsetPx = 0.0
    dv0_left_px: OffsetPx = 0.0
    rotvec_right_deg: tuple[RotDeg, RotDeg, RotDeg] = (0.0, 0.0, 0.0)
    rotvec_left_deg: tuple[RotDeg, RotDeg, RotDeg] = (0.0, 0.0, 0.0)
    splitter_thickness_mm: Annotated[float, Range(0.0, 20.0, "mm")] | None = None

    def __post_init__(self) -> None:
        self.params()  # PsvsParams validates every field and names it

    def params(self) -> PsvsParams:
        """The geometry library's :class:`PsvsParams`."""
        m_mm, l_mm = self.m_mm, self.l_mm
        if self.splitter_thickness_mm is not None:
            if (m_mm, l_mm) != (_M_MM, _L_MM):
                raise ValueError(
                    "psvs.splitter_thickness_mm sets m_mm and l_mm (eq. (5), (6)): give "
                    "either the thickness or m_mm, l_mm"
                )
            m_mm, l_mm = psvs_m_l_mm(self.splitter_thickness_mm, 45.0, 1.5, 1.0)
        return PsvsParams(
            image_size_px=(self.image_width_px, self.image_height_px),
            a_u=self.a_u,
            a_v=self.a_v,
            skew=self.skew,
            u0=self.u0,
            v0=self.v0,
            baseline_mm=self.baseline_mm,
            m_mm=m_mm,
            l_mm=l_mm,
            dist_coeffs=self.dist_coeffs,
            # no offset: None, the real camera's (u0, v0), as in PsvsParams
            u0_right=_shifted(self.u0, self.du0_right_px),
            v0_right=_shifted(self.v0, self.dv0_right_px),
            u0_left=_shifted(self.u0, self.du0_left_px),
            v0_left=_shifted(self.v0, self.dv0_left_px),
            rotvec_right_deg=self.rotvec_right_deg,
            rotvec_left_deg=self.rotvec_left_deg,
        )


def _shifted(centre_px: float, offset_px: float) -> float | None:
    return None if offset_px == 0 else centre_px + offset_px
