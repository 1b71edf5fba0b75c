"""The rig: what the pipeline believes about the hardware (:class:`Rig`: the PSVS, the
hand-eye transform, the target, the driver tip, each with how it was obtained), and where
the servo wants the target. The file format: :mod:`humanpt.runtime.rigfile`.

``DEFAULT_FLANGE_T_CAMERA_MM`` is the nominal hand-eye transform (``F T_C`` of the
paper, Section 4), the rig's default until hand-eye calibration writes another: the camera's
axes parallel to the flange's (optical axis along the flange z axis) and its optical
centre 60 mm off the tool axis along flange y and 100 mm out along flange z. The paper
measures its own by hand-eye calibration [42]; this value is an assumption.

Section 5: the desired point D lies on the camera z axis at ``d_z`` (600 mm in the
paper's experiments), with its frame parallel to the camera frame, so at convergence
``camera_T_tob = camera_T_desired(d_z)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import numpy as np

from humanpt.runtime.config_types import Deg, Mm, Range

from .config import PsvsConfig
from .psvs import PsvsParams
from .target import TargetModel
from .transforms import (
    compose,
    invert_transform,
    make_transform,
    transform_from_x,
    x_from_transform,
)
from .units import to_m

__all__ = [
    "RIG_VERSION",
    "Calibration",
    "HandEye",
    "TargetGeometry",
    "Tip",
    "Timing",
    "StereoCamera",
    "Stereo",
    "RIG_KINDS",
    "Rig",
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


# --------------------------------------------------------------------------- the rig file

RIG_VERSION = 1
"""The rig file format this version reads and writes (``version = 1``)."""

_SIGMA = Annotated[float, Range(0.0, 1e6, "the field's unit")]


@dataclass(frozen=True)
class Calibration:
    """How one part of the rig was obtained: ``method`` (``"nominal"`` for design values,
    else the tool: ``"zhang"``, ``"ax=yb"``, ``"pivot"``...), ``date`` (ISO 8601, empty for
    design values), ``note`` (free text), and ``sigma``: the 1-sigma uncertainty of each
    field of the part that was estimated, in that field's unit (e.g. ``{"a_u" = 0.4}`` px,
    ``{"flange_T_camera_x" = 0.1}`` mm/deg for each element)."""

    method: str = "nominal"
    date: str = ""
    note: str = ""
    sigma: dict[str, _SIGMA] = field(default_factory=dict)


def _x6(T: np.ndarray) -> tuple[float, ...]:
    return tuple(float(v) for v in x_from_transform(T))


@dataclass(frozen=True)
class HandEye:
    """``[hand_eye]``: the camera frame in the flange frame, ``F T_C`` of the paper (Section
    4), as X = (x, y, z mm, yaw, pitch, roll deg, Z-Y-X)."""

    flange_T_camera_x: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = field(
        default_factory=lambda: _x6(DEFAULT_FLANGE_T_CAMERA_MM))
    calibration: Calibration = field(default_factory=Calibration)

    def flange_T_camera_mm(self) -> np.ndarray:
        """(4, 4), translation in mm."""
        return transform_from_x(np.asarray(self.flange_T_camera_x, dtype=float))

    def flange_T_camera_m(self) -> np.ndarray:
        """(4, 4), translation in metres (what the messages use)."""
        return to_m(self.flange_T_camera_mm())


@dataclass(frozen=True)
class TargetGeometry:
    """``[target]``: the TOB's three sources, an isosceles triangle (Fig. 3c): legs AB = AC =
    ``leg_mm``, base BC = ``base_mm``, each source a disc of ``source_diameter_mm``;
    ``side_tolerance_mm``: how far a measured side may differ and still count as the
    target's."""

    leg_mm: Annotated[float, Range(1, 1000, "mm")] = 40.0
    base_mm: Annotated[float, Range(1, 1000, "mm")] = 30.0
    source_diameter_mm: Annotated[float, Range(0.01, 1000, "mm")] = 5.0
    side_tolerance_mm: Annotated[float, Range(1e-3, 1000, "mm")] = 3.0
    calibration: Calibration = field(default_factory=Calibration)

    def __post_init__(self) -> None:
        self.model()  # the triangle must exist (2 leg > base)

    def model(self) -> TargetModel:
        return TargetModel.isosceles(self.leg_mm, self.base_mm, self.source_diameter_mm, None,
                                     self.side_tolerance_mm)


@dataclass(frozen=True)
class Tip:
    """``[tip]``: the driver's endpoint P in the TOB frame, ``G t_P`` of eq. (9) (mm)."""

    tob_t_tip_mm: tuple[Mm, Mm, Mm] = (0.0, 0.0, 60.0)
    calibration: Calibration = field(default_factory=Calibration)

    def tob_T_tip_mm(self) -> np.ndarray:
        return make_transform(np.eye(3), np.asarray(self.tob_t_tip_mm, dtype=float))


@dataclass(frozen=True)
class Timing:
    """``[timing]``: how the camera's image stamps sit on the robot's clock:
    ``camera_time_offset_ms`` > 0 when an image was taken that long before its stamp (the
    stamps are late), estimated from the robot's motion against the measured target
    (:mod:`humanpt.calibration.timing`).  A rig without it (older files) reads as 0."""

    camera_time_offset_ms: Annotated[float, Range(-1000, 1000, "ms")] = 0.0
    calibration: Calibration = field(default_factory=Calibration)


@dataclass(frozen=True)
class Arm:
    """``[arm]``: the playing arm's kinematic errors against its nominal ``model``
    (``"puma762"``; empty: no calibrated arm, the nominal model is taken as the arm):
    each joint's zero offset (the true DH angle is the encoder's plus the offset) and the
    DH lengths' errors (d2, a2, a3, d4, d6), what :class:`humanpt.geometry.puma.TrueArm`
    takes, estimated by :mod:`humanpt.calibration.arm`.  Older rigs have none."""

    model: str = ""
    joint_offsets_deg: tuple[Annotated[float, Range(-5, 5, "deg")], ...] = (0.0,) * 6
    link_length_errors_mm: tuple[Annotated[float, Range(-50, 50, "mm")], ...] = (0.0,) * 5
    calibration: Calibration = field(default_factory=Calibration)

    def __post_init__(self) -> None:
        for name, n in (("joint_offsets_deg", 6), ("link_length_errors_mm", 5)):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != n or not all(np.isfinite(v)):
                raise ValueError(f"{name} needs {n} finite numbers, got {list(getattr(self, name))}")
            object.__setattr__(self, name, v)
        if self.model:
            from .puma import PumaModel

            if self.model not in {m.value for m in PumaModel}:
                raise ValueError(f"model: {self.model!r} is not a robot model ({', '.join(m.value for m in PumaModel)})")

    @property
    def present(self) -> bool:
        """Whether the rig has a calibrated arm (applied only then)."""
        return bool(self.model)

    def true_arm(self):
        """The calibrated arm (:class:`humanpt.geometry.puma.TrueArm`), None without one."""
        if not self.present:
            return None
        from .puma import GEOMETRY, PumaModel, TrueArm, perturbed_geometry

        return TrueArm(perturbed_geometry(GEOMETRY[PumaModel(self.model)], self.link_length_errors_mm),
                       np.radians(np.asarray(self.joint_offsets_deg, dtype=float)))


@dataclass(frozen=True)
class StereoCamera:
    """One camera of an ordinary stereo pair (``[stereo.left]``, ``[stereo.right]``): its
    focal lengths and principal point (px) and OpenCV's distortion (k1, k2, p1, p2, k3)."""

    a_u: Annotated[float, Range(1, 1e6, "px")] = 1000.0
    a_v: Annotated[float, Range(1, 1e6, "px")] = 1000.0
    u0: Annotated[float, Range(-1e5, 1e5, "px")] = 320.0
    v0: Annotated[float, Range(-1e5, 1e5, "px")] = 240.0
    dist_coeffs: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        dist = tuple(float(v) for v in self.dist_coeffs)
        if len(dist) != 5 or not all(np.isfinite(dist)) or max(map(abs, dist), default=0.0) > 1e3:
            raise ValueError(f"dist_coeffs must be 5 finite numbers (k1, k2, p1, p2, k3) within +-1000, "
                             f"got {list(self.dist_coeffs)}")
        object.__setattr__(self, "dist_coeffs", dist)

    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.a_u, 0.0, self.u0], [0.0, self.a_v, self.v0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Stereo:
    """``[stereo]``: an ordinary stereo pair (the paper: "an ordinary stereovision system
    with two parallel cameras could also replace PSVS"), read when ``kind = "stereo"``: the
    image size both cameras give, each camera, and ``right_T_left_x`` the left camera's pose
    in the right camera's frame (mm, deg: X of Section 4; OpenCV's stereoCalibrate R, T:
    a point X_left is at R X_left + T in the right camera), ``camera_T_right_x`` the right
    camera in the rig's camera frame (the hand-eye's; identity: the camera frame is the
    right camera's, as a calibration of the pair gives). Nominal: two parallel cameras
    100 mm apart, the left one at -100 mm along the right one's x."""

    image_width_px: Annotated[int, Range(16, 20000, "px")] = 640
    image_height_px: Annotated[int, Range(16, 20000, "px")] = 480
    left: StereoCamera = field(default_factory=StereoCamera)
    right: StereoCamera = field(default_factory=StereoCamera)
    right_T_left_x: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (-100.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    camera_T_right_x: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    calibration: Calibration = field(default_factory=Calibration)

    def __post_init__(self) -> None:
        for name in ("right_T_left_x", "camera_T_right_x"):
            x = tuple(float(v) for v in getattr(self, name))
            if len(x) != 6 or not all(np.isfinite(x)):
                raise ValueError(f"{name} must be 6 finite numbers (mm, deg), got {list(getattr(self, name))}")
            object.__setattr__(self, name, x)
        if not self.baseline_mm() > 1.0:
            raise ValueError(f"right_T_left_x: the cameras are {self.baseline_mm():.3g} mm apart; a stereo pair "
                             "needs a baseline (at least 1 mm)")

    def right_T_left_mm(self) -> np.ndarray:
        return transform_from_x(np.asarray(self.right_T_left_x))

    def camera_T_right_mm(self) -> np.ndarray:
        return transform_from_x(np.asarray(self.camera_T_right_x))

    @classmethod
    def of_psvs(cls, psvs: PsvsConfig) -> Stereo:
        """The PSVS's two virtual cameras as an ordinary stereo pair (what the twin renders
        with ``[sim_camera] stereo``): each camera's intrinsics, the lens's distortion (about
        the real camera's principal point: exact when the views' principal points are the
        real one's), the pair's pose from the virtual cameras' centres and rotations, the
        camera frame the PSVS's."""
        p = psvs.params()
        width, height = p.image_size_px
        poses = {}
        cams = {}
        for side, cam in (("right", p.right_camera), ("left", p.left_camera)):
            poses[side] = make_transform(np.asarray(cam.camera_R_virtual, float), np.asarray(cam.centre_mm, float))
            cams[side] = StereoCamera(a_u=cam.a_u, a_v=cam.a_v, u0=cam.u0, v0=cam.v0,
                                      dist_coeffs=tuple(float(v) for v in psvs.dist_coeffs))
        right_T_left = invert_transform(poses["right"]) @ poses["left"]
        return cls(image_width_px=int(width), image_height_px=int(height), left=cams["left"], right=cams["right"],
                   right_T_left_x=tuple(float(v) for v in x_from_transform(right_T_left)),
                   camera_T_right_x=tuple(float(v) for v in x_from_transform(poses["right"])),
                   calibration=Calibration(method="psvs-views", note="the PSVS's virtual cameras as a pair"))

    def baseline_mm(self) -> float:
        return float(np.linalg.norm(self.right_T_left_x[:3]))


RIG_KINDS = ("psvs", "stereo")


@dataclass(frozen=True)
class Rig:
    """Everything the pipeline believes about the hardware (DESIGN.md, "Rig and world"):
    ``psvs`` (camera intrinsics, distortion, each virtual camera, baseline, m, l:
    :class:`humanpt.geometry.config.PsvsConfig`) with ``psvs_calibration``, ``hand_eye``,
    ``target``, ``tip`` and ``timing`` (the camera's stamps on the robot's clock), each
    with how it was obtained and its uncertainty.

    Perception, the pose filter, the controller and viz read it; nothing else in the
    configuration holds these values. The twin's truth (its world) is separate and may
    differ. :mod:`humanpt.runtime.rigfile` reads and writes it as TOML."""

    version: int = RIG_VERSION
    name: str = "nominal"
    kind: str = "psvs"
    psvs: PsvsConfig = field(default_factory=PsvsConfig)
    psvs_calibration: Calibration = field(default_factory=Calibration)
    hand_eye: HandEye = field(default_factory=HandEye)
    target: TargetGeometry = field(default_factory=TargetGeometry)
    tip: Tip = field(default_factory=Tip)
    timing: Timing = field(default_factory=Timing)
    stereo: Stereo = field(default_factory=Stereo)
    arm: Arm = field(default_factory=Arm)

    def __post_init__(self) -> None:
        if self.version != RIG_VERSION:
            raise ValueError(f"version: this humanpt reads rig version {RIG_VERSION}, the file says "
                             f"{self.version!r}")
        if self.kind not in RIG_KINDS:
            raise ValueError(f"kind: {self.kind!r} is not a rig kind ({', '.join(RIG_KINDS)})")

    def params(self) -> PsvsParams:
        """The PSVS as the geometry library's :class:`PsvsParams`."""
        return self.psvs.params()

    def target_model(self) -> TargetModel:
        return self.target.model()

    def methods(self) -> str:
        """One line: how each part was obtained, e.g. ``psvs nominal, hand_eye ax=yb (2026-11-23)``."""
        parts = []
        for name, cal in (("psvs", self.psvs_calibration), ("hand_eye", self.hand_eye.calibration),
                          ("target", self.target.calibration), ("tip", self.tip.calibration)):
            parts.append(f"{name} {cal.method}" + (f" ({cal.date})" if cal.date else ""))
        if self.timing.calibration.method != "nominal":  # (a rig before issue 32 had no timing)
            cal = self.timing.calibration
            parts.append(f"timing {cal.method}" + (f" ({cal.date})" if cal.date else ""))
        if self.arm.present:
            cal = self.arm.calibration
            parts.append(f"arm {cal.method}" + (f" ({cal.date})" if cal.date else ""))
        if self.kind == "stereo" or self.stereo.calibration.method != "nominal":
            cal = self.stereo.calibration
            parts.append(f"stereo {cal.method}" + (f" ({cal.date})" if cal.date else ""))
        return ", ".join(parts)
