"""The arms humanpt knows, each one model on the arm kinematics core
(:mod:`humanpt.geometry.arm`): a name, its standard DH table, joint limits, a comfortable
start pose and where the numbers come from.

    from humanpt.geometry.arms import arm_kinematics
    kin = arm_kinematics("ur5e")            # UrKinematics
    kin.forward(np.zeros(6))                # flange at (-817.2, -232.9, 62.8) mm

``puma762``/``puma560``: :class:`humanpt.geometry.puma.PumaKinematics` (its tables there).
``ur5e``: Universal Robots' published DH parameters for the UR5e (UR's support article
"DH parameters for calculations of kinematics and dynamics": d1 162.5, a2 -425, a3 -392.2,
d4 133.3, d5 99.7, d6 99.6 mm; alpha 90, 0, 0, 90, -90, 0 deg; no theta offsets: UR's
joint angles are the DH thetas); limits +-360 deg, the elbow +-180 (humanpt keeps the
elbow within a turn: beyond it the forearm meets the upper arm).
``irb1600``: ABB IRB 1600-6/1.45 (the 1.45 m reach variant). Dimensions from ABB's product
specification's figures (base to axis 2 486.5 mm, axis 1 to axis 2 150 mm, upper arm 700,
axis 3 to the wrist centre 600, wrist centre to flange 65), the same as the DH table
published with Corke's toolbox models of it (alpha -90, 0, -90, 90, -90, 0; theta offsets
0, -90, 0, 0, 0, 180 deg: ABB's calibration pose, upper arm up and forearm level, is all
axes 0). Axis ranges: axis 1 +-180, axis 2 -90..+120, axis 3 -245..+65, axis 4 +-200, axis
5 +-115, axis 6 +-400 deg, as ROS-Industrial's model of the 1.45 m arm gives them
(ros-industrial/abb_experimental, abb_irb1600_support/urdf/irb1600_8_145_macro.xacro, "from
ABB's data sheets"; its dimensions are the ones above: 486.5, 150, 700, 300 + 300, 65 mm).
The ranges first written here (axis 2 -63..+136, axis 3 -235..+55) were from memory of the
product specification, not checked against a copy; no copy of it is reachable here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humanpt.geometry.arm import ArmKinematics, DhLink, SphericalWristKinematics, UrKinematics

_H = np.pi / 2


@dataclass(frozen=True)
class ArmModel:
    """One arm: ``dh`` (six rows, mm and rad), ``theta_offsets_deg`` (DH theta minus the
    controller's joint angle), ``joint_limits_deg`` ((lo, hi) per joint, the controller's
    angles), ``home_joints_deg`` (a comfortable pose: the simulated robot starts there and
    the twin mounts the arm around it), ``solver`` (``spherical``, ``ur``, ``puma`` or
    ``numeric``) and ``source`` (where the numbers come from)."""

    name: str
    dh: tuple[DhLink, ...]
    theta_offsets_deg: tuple[float, ...]
    joint_limits_deg: tuple[tuple[float, float], ...]
    home_joints_deg: tuple[float, ...]
    solver: str
    source: str

    def kinematics(self, joint_limits_deg: tuple[tuple[float, float], ...] | None = None) -> ArmKinematics:
        """This arm's kinematics (its limits, or ``joint_limits_deg``)."""
        limits = np.radians(np.asarray(joint_limits_deg or self.joint_limits_deg, dtype=float))
        if self.solver == "puma":
            from humanpt.geometry.puma import PumaKinematics, RobotModelConfig

            return PumaKinematics(RobotModelConfig(model=self.name, joint_limits_deg=joint_limits_deg
                                                   or self.joint_limits_deg))
        cls = {"spherical": SphericalWristKinematics, "ur": UrKinematics, "numeric": ArmKinematics}[self.solver]
        return cls(self.dh, limits, np.radians(self.theta_offsets_deg))


def _puma(name: str) -> ArmModel:
    from humanpt.geometry.puma import GEOMETRY, HOME_JOINTS_DEG, PUMA_JOINT_LIMITS_DEG, PumaModel

    return ArmModel(name, GEOMETRY[PumaModel(name)].dh(), (0.0,) * 6, PUMA_JOINT_LIMITS_DEG, HOME_JOINTS_DEG,
                    "puma", "humanpt.geometry.puma (Fu, Gonzalez & Lee; Corke's limits)")


UR5E = ArmModel(
    "ur5e",
    (DhLink(_H, 0.0, 162.5), DhLink(0.0, -425.0, 0.0), DhLink(0.0, -392.2, 0.0),
     DhLink(_H, 0.0, 133.3), DhLink(-_H, 0.0, 99.7), DhLink(0.0, 0.0, 99.6)),
    (0.0,) * 6,
    ((-360.0, 360.0), (-360.0, 360.0), (-180.0, 180.0), (-360.0, 360.0), (-360.0, 360.0), (-360.0, 360.0)),
    # Flange down in front of the robot, elbow up, wrist 2 at 90 deg (well off its
    # singularity at 0): at (584.7, -133.3, 266.2) mm, the tool pointing down.
    (0.0, -110.0, -100.0, -60.0, 90.0, 0.0),
    "ur",
    "UR's published DH parameters for the UR5e; limits +-360 deg, elbow +-180",
)

IRB1600 = ArmModel(
    "irb1600",
    (DhLink(-_H, 150.0, 486.5), DhLink(0.0, 700.0, 0.0), DhLink(-_H, 0.0, 0.0),
     DhLink(_H, 0.0, 600.0), DhLink(-_H, 0.0, 0.0), DhLink(0.0, 0.0, 65.0)),
    (0.0, -90.0, 0.0, 0.0, 0.0, 180.0),
    ((-180.0, 180.0), (-90.0, 120.0), (-245.0, 65.0), (-200.0, 200.0), (-115.0, 115.0), (-400.0, 400.0)),
    # Flange straight down in front of the robot (axis 5 at 60 deg, away from its singularity).
    (0.0, 20.0, 10.0, 0.0, 60.0, 0.0),
    "spherical",
    "ABB IRB 1600-6/1.45 product specification (dimensions and axis ranges)",
)

ARM_NAMES = ("puma762", "puma560", "ur5e", "irb1600")


def arm_model(name: str) -> ArmModel:
    """The model called ``name`` (one of :data:`ARM_NAMES`); ValueError naming the choices."""
    if name in ("puma762", "puma560"):
        return _puma(name)
    if name == "ur5e":
        return UR5E
    if name == "irb1600":
        return IRB1600
    raise ValueError(f"unknown arm {name!r}; choose one of {', '.join(ARM_NAMES)}")


def arm_kinematics(name: str, joint_limits_deg=None) -> ArmKinematics:
    """The kinematics of the arm called ``name`` (:class:`ArmModel.kinematics`)."""
    return arm_model(name).kinematics(joint_limits_deg)
