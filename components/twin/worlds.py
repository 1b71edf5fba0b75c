"""The twin's world: what is true, which the pipeline does not know (DESIGN.md, "Rig and
world").

A world is a set of overrides of the twin's own configs (``[operator]``, ``[sim_camera]``,
``[sim_robot]``, ``[standin_robot]``) on top of their defaults, which are the ideal world:
every error off, the optics exactly the nominal rig's.  The pipeline keeps believing its
rig (:class:`humanpt.geometry.rig.Rig`), so any difference shows in the recorded path.

``ideal``: today's twin.  ``realistic``: every error source of :data:`ERROR_SOURCES` on at
the size a real cell of the paper's era would have (each one a few config keys, so that
``humanpt experiment budget`` can switch them on one at a time).  A world file (TOML)
either lists the sources it switches on (``sources = ["focal", "tremor"]``, or
``sources = "all"``) and/or gives its own overrides as sections, e.g.::

    name = "my cell"
    sources = ["stamp_offset"]
    [sim_camera.psvs]
    a_u = 1002.0
    [sim_robot]
    lag_time_constant_ms = 15.0
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from humanpt.geometry.psvs import virtual_rotation_from_mirror_tilt_deg
from humanpt.geometry.rig import Rig
from humanpt.runtime.config import ConfigError, read_toml

__all__ = ["WORLD_SECTIONS", "ErrorSource", "ERROR_SOURCES", "World", "load_world", "merge_overrides"]

# The twin's configs a world may set (the pipeline's are never part of a world).
WORLD_SECTIONS = ("operator", "sim_camera", "sim_robot", "standin_robot")

_NOMINAL_HAND_EYE = Rig().hand_eye.flange_T_camera_x


def _hand_eye(dx_mm: float = 0.0, dpitch_deg: float = 0.0) -> list[float]:
    x = list(_NOMINAL_HAND_EYE)
    x[0] += dx_mm
    x[4] += dpitch_deg
    return x


@dataclass(frozen=True)
class ErrorSource:
    """One way the world differs from the rig or from a perfect sensor/robot/operator.

    ``name``: a short key (``--only``); ``what``: what is wrong, for a person; ``size``: how
    much, in units; ``overrides``: {section: {key: value}} of the twin's configs;
    ``robot``: which robot it needs (``"puma"`` for the arm's kinematics, else any)."""

    name: str
    what: str
    size: str
    overrides: dict[str, dict]
    robot: str = ""
    # In ``realistic``: False for a source another one contains (the parts of the hand-eye,
    # which set the same key: alone they are the budget's rows, together one source).
    realistic: bool = True


def _mirror_tilt() -> dict[str, dict]:
    rot = [float(v) for v in virtual_rotation_from_mirror_tilt_deg(0.05)]  # about the camera's y: pan
    return {"sim_camera": {"psvs": {"rotvec_left_deg": rot}}}


ERROR_SOURCES: tuple[ErrorSource, ...] = (
    # optics and calibration (what a nominal rig gets wrong)
    ErrorSource("hand_eye_mm", "camera on the flange off its nominal place", "0.5 mm along flange x",
                {"sim_camera": {"flange_T_camera_mm_deg": _hand_eye(dx_mm=0.5)}}, realistic=False),
    ErrorSource("hand_eye_deg", "camera on the flange turned", "0.1 deg pitch",
                {"sim_camera": {"flange_T_camera_mm_deg": _hand_eye(dpitch_deg=0.1)}}, realistic=False),
    ErrorSource("hand_eye", "camera on the flange off and turned (both of the above)", "0.5 mm, 0.1 deg",
                {"sim_camera": {"flange_T_camera_mm_deg": _hand_eye(dx_mm=0.5, dpitch_deg=0.1)}}),
    ErrorSource("focal", "true focal length longer than nominal", "+0.3 % (a_u, a_v 1003 px)",
                {"sim_camera": {"psvs": {"a_u": 1003.0, "a_v": 1003.0}}}),
    ErrorSource("mirror_tilt", "one mirror tilted (the left virtual camera pans twice as far)",
                "0.05 deg (virtual camera 0.1 deg)", _mirror_tilt()),
    ErrorSource("principal_point", "left view's image centre off nominal", "0.5 px in u",
                {"sim_camera": {"psvs": {"du0_left_px": 0.5}}}),
    ErrorSource("distortion", "lens distortion the rig does not know", "k1 = -0.01",
                {"sim_camera": {"psvs": {"dist_coeffs": [-0.01, 0.0, 0.0, 0.0, 0.0]}}}),
    ErrorSource("splitter", "beam splitter thicker than nominal (m, l of eq. 5, 6)", "1.05 mm (nominal 1 mm)",
                {"sim_camera": {"psvs": {"splitter_thickness_mm": 1.05}}}),
    ErrorSource("ghost", "ghost image from the splitter's second surface", "4 % of the left view, 1.1 px",
                {"sim_camera": {"ghost_gain": 0.04}}),
    # sensor (blooming first: the sensor's own well, below, wins when both are on)
    ErrorSource("blooming", "saturated sources bloom along columns", "brighter sources (x1.5), 80 % spill",
                {"sim_camera": {"blooming": 0.8, "full_well_e": 10200.0, "source_dn_per_ms": 630.0}}),
    ErrorSource("sensor_noise", "2005-era sensor: read and shot noise", "~0.03 px centroid SD (10 e-/DN, 52 e- read, 2550 e- well)",
                {"sim_camera": {"gain_e_per_dn": 10.0, "read_noise_e": 52.0, "full_well_e": 2550.0}}),
    ErrorSource("fixed_pattern", "fixed-pattern noise", "DSNU 1 DN, PRNU 1 %",
                {"sim_camera": {"dsnu_dn": 1.0, "prnu": 0.01}}),
    ErrorSource("falloff", "sources dim with their viewing angle (LED behind a diffuser)", "cos^1.5",
                {"sim_camera": {"source_falloff_exponent": 1.5}}),
    ErrorSource("motion_blur", "motion blur over a longer exposure", "4 ms exposure (same brightness)",
                {"sim_camera": {"motion_blur": True, "exposure_ms": 4.0, "source_dn_per_ms": 105.0,
                                "background_dn_per_ms": 2.5}}),
    # timing
    ErrorSource("stamp_offset", "image stamps off the robot's clock", "5 ms late",
                {"sim_camera": {"stamp_offset_ms": 5.0}}),
    ErrorSource("stamp_jitter", "image stamp jitter", "1 ms SD", {"sim_camera": {"stamp_jitter_ms": 1.0}}),
    ErrorSource("frame_drops", "dropped frames", "1 %", {"sim_camera": {"frame_drop_probability": 0.01}}),
    # robot
    ErrorSource("kinematics", "the arm's true kinematics differ from the nominal model",
                "joint offsets up to 0.03 deg, link lengths up to 0.3 mm (absolute accuracy ~1 mm)",
                {"sim_robot": {"joint_offsets_deg": [0.03, -0.02, 0.03, -0.03, 0.02, -0.02],
                               "link_length_errors_mm": [0.3, -0.2, 0.3, -0.2, 0.1]}}, robot="puma"),
    ErrorSource("robot_lag", "the arm lags its command", "first order, 20 ms",
                {"sim_robot": {"lag_time_constant_ms": 20.0}, "standin_robot": {"lag_time_constant_ms": 20.0}}),
    # operator
    ErrorSource("tip", "the driver's true tip off its design value (a needle slightly bent)",
                "(0.3, -0.2, 0.4) mm", {"operator": {"driver_error_mm": [0.3, -0.2, 0.4]}}),
    ErrorSource("tremor", "the operator's hand trembles", "0.2 mm, 0.2 deg RMS",
                {"operator": {"tremor_mm": 0.2, "tremor_deg": 0.2}}),
)

_BY_NAME = {s.name: s for s in ERROR_SOURCES}


def merge_overrides(*layers: Mapping[str, Any]) -> dict[str, Any]:
    """Nested tables merged left to right (a later value wins; tables merge key by key)."""
    out: dict[str, Any] = {}
    for layer in layers:
        for k, v in layer.items():
            if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
                out[k] = merge_overrides(out[k], v)
            elif isinstance(v, Mapping):
                out[k] = merge_overrides(v)
            else:
                out[k] = v
    return out


@dataclass(frozen=True)
class World:
    """A named world: the error sources it switches on and its own extra overrides."""

    name: str = "ideal"
    sources: tuple[str, ...] = ()
    extra: dict[str, dict] = field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = [s for s in self.sources if s not in _BY_NAME]
        if unknown:
            raise ConfigError(f"world {self.name!r}: no error source {unknown[0]!r}; known: "
                              f"{', '.join(_BY_NAME)}")
        bad = [s for s in self.extra if s not in WORLD_SECTIONS]
        if bad:
            raise ConfigError(f"world {self.name!r}: [{bad[0]}] is not a twin section ({', '.join(WORLD_SECTIONS)}); "
                              f"what the pipeline believes is the rig, not the world")

    @classmethod
    def ideal(cls) -> World:
        return cls("ideal")

    @classmethod
    def realistic(cls) -> World:
        return cls("realistic", tuple(s.name for s in ERROR_SOURCES if s.realistic))

    @classmethod
    def only(cls, *names: str) -> World:
        """The ideal world with just these error sources on."""
        return cls("+".join(names) or "ideal", tuple(names))

    def overrides(self) -> dict[str, dict]:
        """{section: {key: value}} of the twin's configs."""
        return merge_overrides(*(_BY_NAME[s].overrides for s in self.sources), self.extra)

    @classmethod
    def named(cls, spec: str) -> World:
        """``ideal``, ``realistic``, ``ideal+SOURCE+SOURCE...`` (the ideal world with these
        error sources on, e.g. ``ideal+focal+tip``) or a world file (:func:`load_world`)."""
        if spec == "ideal":
            return cls.ideal()
        if spec.startswith("ideal+"):
            return cls.only(*spec.split("+")[1:])
        if spec == "realistic":
            return cls.realistic()
        if Path(spec).suffix or Path(spec).exists():
            return load_world(spec)
        raise ConfigError(f"--world {spec!r}: not 'ideal', 'realistic', 'ideal+SOURCE...' ({', '.join(_BY_NAME)}) "
                          "or a world file (.toml)")


def load_world(path: str | Path) -> World:
    """Read a world file (see the module docstring); ConfigError naming the problem."""
    p = Path(path)
    data = read_toml(p, "world")
    name = data.pop("name", p.stem)
    sources = data.pop("sources", [])
    if sources == "all":
        sources = [s.name for s in ERROR_SOURCES if s.realistic]
    if not isinstance(sources, list) or not all(isinstance(s, str) for s in sources):
        raise ConfigError(f"{p}: sources: a list of error source names or \"all\", got {sources!r}")
    for k, v in data.items():
        if not isinstance(v, Mapping):
            raise ConfigError(f"{p}: {k!r} must be a [section] (one of {', '.join(WORLD_SECTIONS)})")
    try:
        return World(str(name), tuple(sources), {k: dict(v) for k, v in data.items()})
    except ConfigError as e:
        raise ConfigError(f"{p}: {e}") from None
