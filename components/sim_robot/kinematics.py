"""The old import path of the Puma model, now :mod:`humanpt.geometry.puma` (product code:
the calibration plans with it; issue 30). Kept for the simulator modules and old scripts."""

from humanpt.geometry.puma import (  # noqa: F401
    GEOMETRY,
    HOME_JOINTS_DEG,
    PUMA_JOINT_LIMITS_DEG,
    DhLink,
    IkSolution,
    PumaGeometry,
    PumaKinematics,
    PumaModel,
    RobotModelConfig,
    TrueArm,
    UnreachableError,
    dh_transform,
    perturbed_geometry,
)
