"""sim_robot configuration (the ``[sim_robot]`` section)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np

from humanpt.geometry.arm import ArmKinematics
from humanpt.geometry.arms import ARM_NAMES, arm_model
from humanpt.geometry.puma import (
    HOME_JOINTS_DEG,
    TrueArm,
    UnreachableError,
    perturbed_geometry,
)
from humanpt.runtime import cycle as cell_cycle
from humanpt.runtime.config import ConfigError, Deg, Mm, Range

# Flange straight down in front of the robot, elbow up (humanpt.geometry.puma): the Puma's.
DEFAULT_START_JOINTS_DEG = HOME_JOINTS_DEG
# The arm each link's simulated controller moves unless ``model`` says otherwise.
PROTOCOL_ARMS = {"alter": "puma762", "rsi": "puma762", "egm": "irb1600", "rtde": "ur5e"}


@dataclass(frozen=True)
class SimRobotConfig:
    """A simulated robot controller at the far end of the robot link (ALTER, RSI, EGM, RTDE),
    with the arm ``model`` (default: the link's, :data:`PROTOCOL_ARMS`: the Puma over ALTER
    and RSI, the IRB 1600 over EGM, the UR5e over RTDE) starting at ``start_joints_deg``
    (default: the arm's comfortable pose, :mod:`humanpt.geometry.arms`). The set-up every
    simulated controller shares: :class:`humanpt.sim_robot.arm.SimArm`.

    The world frame is the robot base (as in the paper) unless ``world_T_base_mm_deg``
    (x, y, z mm, yaw, pitch, roll deg, Z-Y-X) places the base elsewhere; ALTER's "world"
    mode means the base frame, as on the real controller.
    """

    # The arm (humanpt.geometry.arms); "": the link's (PROTOCOL_ARMS), filled in when built.
    model: Literal["", "puma762", "puma560", "ur5e", "irb1600"] = ""
    # The robot runs the link's cycle: the launcher gives it from [robot_gateway]
    # (cell_defaults, humanpt.runtime.cycle); a [sim_robot] section does not set it.
    cycle_period_ns: Annotated[int, Range(1_000_000, 1_000_000_000, "ns")] = cell_cycle.FALLBACK_NS
    # world: a correction moves the flange in the base frame, rotating about the flange
    # origin; tool: the step is expressed in the flange frame.
    alter_mode: Literal["world", "tool"] = "world"
    # Empty: the arm's comfortable pose (ArmModel.home_joints_deg), filled in when built.
    start_joints_deg: tuple[Deg, ...] = ()
    # If given (six values), overrides start_joints_deg: base_T_flange as x, y, z mm, yaw,
    # pitch, roll deg, solved by IK on the branch closest to start_joints_deg. Empty: unset.
    start_pose_mm_deg: tuple[Annotated[float, Range(-5000, 5000, "mm or deg")], ...] = ()
    world_T_base_mm_deg: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (0.0,) * 6
    # Symlink to the pty's slave side; the gateway opens this path as its port.
    pty_link: str = "/tmp/humanpt-alter"
    # Oldest correction (cycles behind the latest STATUS) the controller still applies.
    max_correction_age_cycles: Annotated[int, Range(0, 100, "cycles")] = 2
    # A correction needing a faster joint motion than this faults the controller (near a
    # singularity the closest IK branch can jump).
    max_joint_speed_deg_s: Annotated[float, Range(1e-3, 1000, "deg/s")] = 250.0
    alter_on_start: bool = True
    event_interval_ms: Annotated[float, Range(0, 3600000, "ms")] = 1000.0
    # the world's arm (truth; default: the nominal arm)
    joint_offsets_deg: tuple[Annotated[float, Range(-5, 5, "deg")], ...] = (0.0,) * 6
    link_length_errors_mm: tuple[Annotated[float, Range(-50, 50, "mm")], ...] = (0.0,) * 5
    lag_time_constant_ms: Annotated[float, Range(0, 10000, "ms")] = 0.0
    # The link to the gateway: "alter" (the Puma's serial line, this core) or "rsi" (a KUKA
    # RSI-style controller over UDP: humanpt.sim_robot.rsi; the link's cycle 4 or 12 ms;
    # alter_mode world = RKorr in the base frame, tool = in the flange frame).
    # "egm": an ABB controller running EGM position guidance over UDP (humanpt.sim_robot.egm;
    # the link's cycle 4 ms or a multiple; absolute targets in the base frame).
    # "rtde": a Universal Robots controller running humanpt's URScript program behind RTDE
    # (humanpt.sim_robot.ur; the link's cycle 2 ms e-Series or 8 ms CB3; absolute targets).
    protocol: Literal["alter", "rsi", "egm", "rtde"] = "alter"
    # RSI: where the gateway listens (the robot's IP_NUMBER:PORT for its <Rob> datagrams).
    rsi_gateway: str = "127.0.0.1:49152"
    # RSI: this many late (or missing, wrong-IPOC, malformed) answers in a row stop RSI (the
    # ETHERNET object's late limit). Low, as required of a real robot (components/rsi/README.md).
    rsi_late_limit: Annotated[int, Range(1, 100000, "replies")] = 10
    # RSI HOLDON on RKorr: a missed answer repeats the last correction (True) or applies zero
    # (False, the required setting: a relative correction repeated moves the robot on its own).
    rsi_holdon: bool = False
    # RSI correction limits per cycle (the robot's RSI POSCORR limits): beyond -> RSI stops.
    rsi_max_correction_mm: Annotated[float, Range(0.001, 100, "mm")] = 5.0
    rsi_max_correction_deg: Annotated[float, Range(0.001, 45, "deg")] = 2.0
    # RTDE: where the simulated UR's RTDE server listens (a real controller: port 30004); the
    # gateway's rtde_address (live; the lock-step twin wires the stream itself).
    rtde_bind: str = "127.0.0.1:30004"
    # RTDE: where its Dashboard server listens (a real controller: port 29999); "": the RTDE
    # port less 5 on the same host (29999 beside 30004; port 0: a free one).
    dashboard_bind: str = ""
    # EGM: where the gateway listens (the controller's UDPUC RemoteAddress:RemotePortNumber).
    egm_gateway: str = "127.0.0.1:6510"
    # EGM: no EgmSensor for this long stops EGM (EGMRunPose \CommTimeout), counted from the
    # sensor's first answer (the RAPID program is started once humanpt is up).
    egm_comm_timeout_s: Annotated[float, Range(0.004, 60, "s")] = 1.0
    # EGM: the position controller's first-order time constant (humanpt's assumption).
    egm_time_constant_ms: Annotated[float, Range(0.1, 1000, "ms")] = 20.0

    @classmethod
    def cell_defaults(cls, sections: Mapping[str, Mapping[str, Any]], source: str = "config") -> dict[str, Any]:
        """The robot's cycle: the cell's link's ([robot_gateway]; ConfigFile.component calls
        this). A [sim_robot] table may repeat it (a written config's round trip) but not
        change it: the cell has one cycle."""
        link_ns = cell_cycle.cell_cycle_ns(sections, source)
        own = sections.get("sim_robot", {}).get("cycle_period_ns", link_ns)
        if own != link_ns:
            raise ConfigError(f"{source}: [sim_robot] cycle_period_ns = {own!r}: the simulated robot runs the link's "
                              f"cycle, {cell_cycle.ms(link_ns):g} ms; set the cycle as [{cell_cycle.OWNER}] "
                              f"{cell_cycle.KEY} and leave it out here")
        return {"cycle_period_ns": link_ns}

    def __post_init__(self) -> None:
        if self.protocol not in PROTOCOL_ARMS:
            raise ValueError(f"protocol must be one of {', '.join(PROTOCOL_ARMS)}, got {self.protocol!r}")
        if not self.model:
            object.__setattr__(self, "model", PROTOCOL_ARMS[self.protocol])
        if self.model not in ARM_NAMES:
            raise ValueError(f"unknown arm model {self.model!r}; choose one of {', '.join(ARM_NAMES)}")
        if not self.start_joints_deg:
            object.__setattr__(self, "start_joints_deg", tuple(arm_model(self.model).home_joints_deg))
        object.__setattr__(self, "start_joints_deg", tuple(float(v) for v in self.start_joints_deg))
        if not self.model.startswith("puma") and any(self.link_length_errors_mm):
            raise ValueError(f"link_length_errors_mm (d2, a2, a3, d4, d6) are the Puma's lengths; the {self.model} "
                             "takes joint_offsets_deg only")
        if not cell_cycle.MIN_NS <= self.cycle_period_ns <= cell_cycle.MAX_NS:
            raise ValueError(f"cycle_period_ns must be within 1 and 1000 ms, got {self.cycle_period_ns} ns")
        if not 0 <= self.max_correction_age_cycles <= 100:
            raise ValueError(
                f"max_correction_age_cycles must be within 0 and 100, got {self.max_correction_age_cycles}"
            )
        if not self.max_joint_speed_deg_s > 0:
            raise ValueError(f"max_joint_speed_deg_s must be > 0, got {self.max_joint_speed_deg_s}")
        if not self.pty_link:
            raise ValueError("pty_link must be a path")
        if self.event_interval_ms < 0:
            raise ValueError(f"event_interval_ms must be >= 0, got {self.event_interval_ms}")
        for name in ("start_joints_deg", "world_T_base_mm_deg", "start_pose_mm_deg"):
            value = getattr(self, name)
            if name == "start_pose_mm_deg" and not value:
                continue
            if len(value) != 6 or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} needs six finite values, got {value!r}")
        for name, n, bound in (("joint_offsets_deg", 6, 5.0), ("link_length_errors_mm", 5, 50.0)):
            value = getattr(self, name)
            if len(value) != n or not np.all(np.isfinite(value)) or np.any(np.abs(value) > bound):
                raise ValueError(f"{name} needs {n} finite values within +-{bound:g}, got {value!r}")
        if not (np.isfinite(self.lag_time_constant_ms) and 0.0 <= self.lag_time_constant_ms <= 10000.0):
            raise ValueError(f"lag_time_constant_ms must be within 0 and 10000, got {self.lag_time_constant_ms}")
        if self.protocol == "rsi" and self.cycle_ms not in (4.0, 12.0):
            raise ValueError(f"the link's cycle must be 4 or 12 ms over RSI, got {self.cycle_ms:g} ms")
        if self.protocol == "rtde" and self.cycle_ms not in (2.0, 8.0):
            raise ValueError(f"the link's cycle must be 2 ms (e-Series) or 8 ms (CB3) over RTDE, got {self.cycle_ms:g} ms")
        if self.protocol == "egm" and abs(self.cycle_ms / 4.0 - round(self.cycle_ms / 4.0)) > 1e-9:
            raise ValueError(f"the link's cycle must be a multiple of 4 ms over EGM, got {self.cycle_ms:g} ms")
        for name in ("egm_comm_timeout_s", "egm_time_constant_ms"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        from humanpt.robot_gateway.links.rsi.config import parse_address

        parse_address(self.rtde_bind)  # (ValueError naming it)
        try:
            parse_address(self.dashboard_address)
        except ValueError as e:
            raise ValueError(f"dashboard_bind: {e}") from None
        if not self.rsi_late_limit >= 1:
            raise ValueError(f"rsi_late_limit must be >= 1, got {self.rsi_late_limit}")
        for name in ("rsi_max_correction_mm", "rsi_max_correction_deg"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        self.start_joints_rad()  # raises ValueError when the start is not reachable

    @property
    def dashboard_address(self) -> str:
        """The simulated UR's Dashboard server, "host:port": ``dashboard_bind``, or the RTDE
        port less 5 (29999 beside 30004, as on a UR; port 0: a free one)."""
        if self.dashboard_bind:
            return self.dashboard_bind
        from humanpt.robot_gateway.links.rsi.config import parse_address

        host, port = parse_address(self.rtde_bind)
        return f"{host}:{port - 5 if port > 5 else 0}"

    @property
    def cycle_ms(self) -> float:
        """The link's cycle in ms (exact for whole ms)."""
        return cell_cycle.ms(self.cycle_period_ns)

    def kinematics(self) -> ArmKinematics:
        """The arm's nominal kinematics (what the controller believes)."""
        return arm_model(self.model).kinematics()

    @property
    def ideal_arm(self) -> bool:
        """Whether the world's arm is the nominal one (no joint offsets, no length errors)."""
        return not any(self.joint_offsets_deg) and not any(self.link_length_errors_mm)

    def true_arm(self) -> TrueArm:
        """The world's physical arm (forward kinematics of the truth)."""
        offsets = np.radians(np.asarray(self.joint_offsets_deg, dtype=float))
        model = arm_model(self.model)
        if model.solver == "puma":
            return TrueArm(perturbed_geometry(self.kinematics().geometry, self.link_length_errors_mm), offsets)
        return TrueArm(model.dh, offsets, np.radians(model.theta_offsets_deg))

    def start_joints_rad(self) -> np.ndarray:
        """(6,) the start joints (rad): start_joints_deg, or IK of start_pose_mm_deg."""
        from humanpt.geometry.transforms import transform_from_x

        kin = self.kinematics()
        q0 = np.radians(np.asarray(self.start_joints_deg, dtype=float))
        if not self.start_pose_mm_deg:
            if not kin.within_limits(q0):
                raise ValueError(
                    f"start_joints_deg {self.start_joints_deg} are outside the joint limits "
                    f"{kin.config.joint_limits_deg}"
                )
            return q0
        try:
            return kin.inverse(
                transform_from_x(np.asarray(self.start_pose_mm_deg, dtype=float)), q0
            )
        except UnreachableError as e:
            raise ValueError(
                f"start_pose_mm_deg {self.start_pose_mm_deg} is not reachable: {e}"
            ) from None
