"""Configuration of the simulated PSVS camera (section ``[sim_camera]``).

Brightness is in DN (digital numbers of the 8-bit image). A source's radiance is given as
the DN per millisecond of exposure that a fully covered pixel would collect with no beam
splitter; each view then passes the beam splitter and mirrors with its own gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np

from humanpt.geometry import (
    DEFAULT_FLANGE_T_CAMERA_MM,
    PsvsParams,
    TargetModel,
    psvs_m_l_mm,
    transform_from_x,
    x_from_transform,
)
from humanpt.geometry.config import PsvsConfig
from humanpt.runtime.config import Deg, Mm, Range, live

Px = Annotated[float, Range(-100.0, 100.0, "px")]

_M_MM, _L_MM = psvs_m_l_mm(1.0, 45.0, 1.5, 1.0)
DEFAULT_FLANGE_T_CAMERA_MM_DEG: tuple[float, ...] = tuple(
    float(v) for v in x_from_transform(DEFAULT_FLANGE_T_CAMERA_MM)
)


def _finite(owner: str, name: str, value: float, *, positive: bool = False, nonneg: bool = False):
    if not math.isfinite(value):
        raise ValueError(f"{owner}.{name} must be finite, got {value}")
    if positive and not value > 0:
        raise ValueError(f"{owner}.{name} must be > 0, got {value}")
    if nonneg and not value >= 0:
        raise ValueError(f"{owner}.{name} must be >= 0, got {value}")


@dataclass(frozen=True)
class SimCameraConfig:
    """The simulated PSVS camera: sensor, target, optics, noise, clutter.

    Geometry: ``psvs`` (the PSVS), ``flange_T_camera_mm_deg`` (hand-eye, X = x, y, z mm,
    yaw, pitch, roll deg; default :data:`humanpt.geometry.DEFAULT_FLANGE_T_CAMERA_MM`),
    the target (isosceles, ``target_leg_mm``, ``target_base_mm``, ``source_diameter_mm``).

    Photometry (DN = grey levels): a fully covered pixel of a source collects
    ``source_dn_per_ms * exposure_ms * view_gain_<view>`` DN above the background;
    the background is ``black_level_dn + background_dn_per_ms * exposure_ms``. Optics blur
    is a Gaussian of ``blur_sigma_px``. Noise: shot noise (Poisson on electrons,
    ``gain_e_per_dn`` electrons per DN) and read noise (``read_noise_e``), a full well of
    ``full_well_e``, then 8-bit quantisation and saturation at 255.

    The world's optics and sensor beyond the ideal (each off by default; realistic sizes
    for a 2005-era analogue CCD camera in brackets):

    * ``source_falloff_exponent`` n: a source's radiance falls off as cos(angle)^n with the
      angle between its normal and the direction to each virtual camera (0: Lambertian,
      today; LEDs behind a diffuser ~1-2).
    * ``ghost_gain`` (fraction; ~0.03-0.05): a second, dimmer copy of the ``ghost_view``
      (the left view passes the beam splitter, eq. (3)) from the splitter's second
      surface, shifted by ``ghost_offset_px`` (u, v px; default (1.1, 0): the ~0.76 mm
      lateral shift of a 1 mm plate at 45 deg, seen from ~690 mm, along the baseline).
    * ``dsnu_dn`` (DN; ~0.5-1) and ``prnu`` (fraction; ~0.01): fixed-pattern noise - a
      per-pixel offset (DN, at readout) and gain (multiplies the photo-charge) drawn once
      per ``seed``: the same pattern in every frame.
    * ``blooming`` (fraction; ~0.5-1): the share of the charge above ``full_well_e`` that
      spills into the neighbouring pixels of its column (half up, half down, on to the
      next pixel while a neighbour is full); 0: the excess is lost (clipped), today. It acts
      only on charge above the well: at the defaults the 8-bit output saturates first
      (255 DN = 10 200 e- < 12 000 e-), so pair it with a well near 255 gain_e_per_dn or
      a longer exposure.
    * ``motion_step_px``: with a pose at the start and at the end of the exposure the
      image is integrated over sub-exposures so that it moves at most this far between
      two (one sample, at mid-exposure, when it moves less).

    Clutter (all off by default): a mirror reflection of the sources in a shiny plane
    fixed to the TOB (``reflection_gain`` > 0; plane ``n . p = d`` in the TOB frame, mm,
    ``reflection_plane_tob``), a bright lamp (``lamp_position_mm`` in ``lamp_frame``), and
    partial occlusion of some sources (``occluded_sources``: 0 = A, 1 = B, 2 = C; the part
    beyond a straight edge at ``occlusion_angle_deg`` in the TOB plane, covering
    ``occlusion_fraction`` of the disc, is hidden).

    Timing: one exposure per ``1/fps`` s, centred on the tick (the capture time). It is
    rendered once both truths reach the end of the exposure, from the true trajectories
    (piecewise linear / geodesic through the truth samples) at the capture time, never
    extrapolated; a capture still without truth ``max_truth_wait_ms`` after its exposure
    ended is dropped (event ``truth_late``). Timing errors of the world (all 0 = off): the
    image's stamp is the capture time on the camera's clock, off the robot's clock by
    ``stamp_offset_ms`` (a constant offset; realistic: a few ms with NTP) plus
    ``stamp_jitter_ms`` (SD of a Gaussian error per frame; realistic ~1 ms); a frame is lost
    with ``frame_drop_probability`` (realistic ~0.001-0.01). ``motion_blur``: render the
    motion over the exposure (the renderer's start/end poses of the exposure) instead of
    the poses at the capture instant (off: the ideal world; on in a realistic one).
    Randomness: ``np.random.default_rng([seed, frame_index])`` (image noise) and
    ``np.random.default_rng([seed, frame_index, 1])`` (stamp jitter, frame drops).
    """

    fps: Annotated[float, Range(0.1, 10000, "frames/s")] = 30.0
    seed: Annotated[int, Range(0, 2**63 - 1, "")] = 0
    psvs: PsvsConfig = field(default_factory=PsvsConfig)
    flange_T_camera_mm_deg: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (
        DEFAULT_FLANGE_T_CAMERA_MM_DEG
    )
    target_leg_mm: Annotated[float, Range(1, 1000, "mm")] = 40.0
    target_base_mm: Annotated[float, Range(1, 1000, "mm")] = 30.0
    source_diameter_mm: Annotated[float, Range(0.01, 1000, "mm")] = 5.0
    # photometry
    source_dn_per_ms: Annotated[float, Range(0, 1e6, "DN/ms")] = live(420.0, "radiance of a source (DN/ms, before the view gain)")
    exposure_ms: Annotated[float, Range(1e-3, 10000, "ms")] = live(1.0, "exposure time (ms)")
    view_gain_right: Annotated[float, Range(0, 10, "")] = 0.5
    view_gain_left: Annotated[float, Range(0, 10, "")] = 0.44
    background_dn_per_ms: Annotated[float, Range(0, 1e6, "DN/ms")] = live(10.0, "ambient background (DN/ms)")
    black_level_dn: Annotated[float, Range(0, 255, "DN")] = 4.0
    blur_sigma_px: Annotated[float, Range(0, 100, "px")] = 0.7
    # sensor
    noise: bool = True
    gain_e_per_dn: Annotated[float, Range(1e-3, 1e6, "e-/DN")] = 40.0
    read_noise_e: Annotated[float, Range(0, 1e6, "e-")] = 10.0
    full_well_e: Annotated[float, Range(1, 1e9, "e-")] = 12_000.0
    # the world's optics and sensor beyond the ideal (issue 16): every one off by default
    source_falloff_exponent: Annotated[float, Range(0, 20, "")] = 0.0
    ghost_gain: Annotated[float, Range(0, 1, "fraction")] = 0.0
    ghost_offset_px: tuple[Px, Px] = (1.1, 0.0)
    ghost_view: Literal["left", "right"] = "left"
    dsnu_dn: Annotated[float, Range(0, 50, "DN")] = 0.0
    prnu: Annotated[float, Range(0, 0.5, "fraction")] = 0.0
    blooming: Annotated[float, Range(0, 1, "fraction")] = 0.0
    motion_step_px: Annotated[float, Range(0.01, 10, "px")] = 0.3
    # clutter
    reflection_gain: Annotated[float, Range(0, 10, "")] = live(0.0, "brightness of the mirror images (0: off)")
    reflection_plane_tob: tuple[Annotated[float, Range(-1e4, 1e4, "unit normal, mm")], ...] = (1.0, 0.0, 0.0, 30.0)
    reflection_blur_px: Annotated[float, Range(0, 100, "px")] = 1.5
    lamp_position_mm: tuple[Mm, Mm, Mm] | None = None
    lamp_frame: Literal["world", "camera"] = "world"
    lamp_diameter_mm: Annotated[float, Range(0.01, 10000, "mm")] = 30.0
    lamp_dn_per_ms: Annotated[float, Range(0, 1e6, "DN/ms")] = 300.0
    occluded_sources: tuple[Annotated[int, Range(0, 2, "source")], ...] = live((), "sources partly hidden (0=A, 1=B, 2=C)")
    occlusion_fraction: Annotated[float, Range(0, 1, "")] = live(0.5, "hidden fraction of each occluded source")
    occlusion_angle_deg: Annotated[float, Range(-360, 360, "deg")] = live(0.0, "direction of the hidden side in the TOB plane")
    # timing
    max_truth_wait_ms: Annotated[float, Range(0, 10000, "ms")] = 250.0
    stamp_offset_ms: Annotated[float, Range(-1000, 1000, "ms")] = 0.0
    stamp_jitter_ms: Annotated[float, Range(0, 1000, "ms")] = 0.0
    frame_drop_probability: Annotated[float, Range(0, 1, "")] = 0.0
    motion_blur: bool = False
    near_mm: Annotated[float, Range(1e-3, 10000, "mm")] = 10.0
    # an ordinary stereo pair instead of the PSVS (issue 35): the two virtual cameras
    # rendered apart, each at full brightness (no beam splitter), side by side (left, right)
    stereo: bool = False

    def __post_init__(self) -> None:
        own = "sim_camera"
        _finite(own, "fps", self.fps, positive=True)
        if self.fps > 10_000:
            raise ValueError(f"{own}.fps must be at most 10000, got {self.fps}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"{own}.seed must be an integer >= 0, got {self.seed!r}")
        if not isinstance(self.psvs, PsvsConfig):
            raise ValueError(f"{own}.psvs must be a PsvsConfig, got {type(self.psvs).__name__}")
        x = np.asarray(self.flange_T_camera_mm_deg, dtype=float)
        if x.shape != (6,) or not np.all(np.isfinite(x)):
            raise ValueError(f"{own}.flange_T_camera_mm_deg must be 6 finite numbers, got {x}")
        try:
            self.target_model()
        except ValueError as e:
            raise ValueError(f"{own}: target: {e}") from None
        for name in ("source_dn_per_ms", "exposure_ms", "background_dn_per_ms", "black_level_dn"):
            _finite(own, name, getattr(self, name), nonneg=True)
        for name in ("view_gain_right", "view_gain_left"):
            value = getattr(self, name)
            _finite(own, name, value, nonneg=True)
            if value > 1:
                raise ValueError(f"{own}.{name} is a transmission in [0, 1], got {value}")
        for name in ("source_falloff_exponent", "ghost_gain", "dsnu_dn", "prnu", "blooming"):
            _finite(own, name, getattr(self, name), nonneg=True)
        for name in ("ghost_gain", "prnu", "blooming"):
            if getattr(self, name) > 1:
                raise ValueError(f"{own}.{name} is a fraction in [0, 1], got {getattr(self, name)}")
        ghost = np.asarray(self.ghost_offset_px, dtype=float)
        if ghost.shape != (2,) or not np.all(np.isfinite(ghost)):
            raise ValueError(f"{own}.ghost_offset_px must be two finite numbers (u, v px)")
        if self.ghost_view not in ("left", "right"):
            raise ValueError(f"{own}.ghost_view must be 'left' or 'right', got {self.ghost_view!r}")
        _finite(own, "motion_step_px", self.motion_step_px, positive=True)
        for name in ("blur_sigma_px", "read_noise_e", "reflection_gain", "reflection_blur_px"):
            _finite(own, name, getattr(self, name), nonneg=True)
        for name in ("gain_e_per_dn", "full_well_e", "lamp_diameter_mm", "near_mm"):
            _finite(own, name, getattr(self, name), positive=True)
        _finite(own, "lamp_dn_per_ms", self.lamp_dn_per_ms, nonneg=True)
        _finite(own, "max_truth_wait_ms", self.max_truth_wait_ms, nonneg=True)
        _finite(own, "stamp_offset_ms", self.stamp_offset_ms)
        _finite(own, "stamp_jitter_ms", self.stamp_jitter_ms, nonneg=True)
        _finite(own, "frame_drop_probability", self.frame_drop_probability, nonneg=True)
        if self.frame_drop_probability > 1:
            raise ValueError(
                f"{own}.frame_drop_probability must be in [0, 1], got {self.frame_drop_probability}"
            )
        if self.blur_sigma_px > 20 or self.reflection_blur_px > 20:
            raise ValueError(f"{own}: blur sigmas must be at most 20 px")
        plane = np.asarray(self.reflection_plane_tob, dtype=float)
        if (
            plane.shape != (4,)
            or not np.all(np.isfinite(plane))
            or np.linalg.norm(plane[:3]) < 1e-9
        ):
            raise ValueError(
                f"{own}.reflection_plane_tob must be (nx, ny, nz, d) with a non-zero normal, "
                f"got {self.reflection_plane_tob}"
            )
        if self.lamp_position_mm is not None:
            lamp = np.asarray(self.lamp_position_mm, dtype=float)
            if lamp.shape != (3,) or not np.all(np.isfinite(lamp)):
                raise ValueError(f"{own}.lamp_position_mm must be 3 finite numbers or absent")
        bad = [i for i in self.occluded_sources if i not in (0, 1, 2)]
        if bad or len(set(self.occluded_sources)) != len(self.occluded_sources):
            raise ValueError(
                f"{own}.occluded_sources must be distinct indices 0 (A), 1 (B), 2 (C), "
                f"got {list(self.occluded_sources)}"
            )
        _finite(own, "occlusion_fraction", self.occlusion_fraction, nonneg=True)
        if self.occlusion_fraction > 1:
            raise ValueError(
                f"{own}.occlusion_fraction must be in [0, 1], got {self.occlusion_fraction}"
            )
        _finite(own, "occlusion_angle_deg", self.occlusion_angle_deg)

    # -- derived ---------------------------------------------------------------------------
    def params(self) -> PsvsParams:
        return self.psvs.params()

    def target_model(self) -> TargetModel:
        return TargetModel.isosceles(
            self.target_leg_mm, self.target_base_mm, self.source_diameter_mm, None
        )

    @property
    def flange_T_camera(self) -> np.ndarray:
        """Hand-eye transform (4, 4), mm."""
        return transform_from_x(np.asarray(self.flange_T_camera_mm_deg, dtype=float))

    @property
    def tick_period_ns(self) -> int:
        return round(1e9 / self.fps)
