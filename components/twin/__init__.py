"""The digital twin's lock-step world: operator + stand-in robot + sim_camera on virtual
time (``world``), and the stand-in robot core (``standin``). See ``README.md``."""

from .standin import (
    DEFAULT_START_FLANGE_MM_DEG,
    StandInRobotConfig,
    StandInRobotCore,
    viewing_start_flange,
)
from .world import TwinWorld, build_world, start_flange_for

__all__ = [
    "DEFAULT_START_FLANGE_MM_DEG",
    "StandInRobotConfig",
    "StandInRobotCore",
    "TwinWorld",
    "build_world",
    "start_flange_for",
    "viewing_start_flange",
]
