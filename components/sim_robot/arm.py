"""The simulated robots' one set-up: the arm every simulated controller moves (the Puma over
ALTER and RSI, the UR over RTDE, the ABB arm over EGM), made from ``[sim_robot]`` in one
place: the kinematics the config chooses (``model``: a Puma, the UR5e, the IRB 1600; the
core :mod:`humanpt.geometry.arm`), the start joints, the mounting (``world_T_base``), the
joint-speed limit per cycle, the true arm (the world's: nominal unless joint offsets or
length errors are set) and the two ways a controller moves it:

* :meth:`SimArm.step`: a relative correction (ALTER, RSI's RKorr) in the base frame about
  the flange origin or in the flange frame, on the inverse-kinematics solution closest to
  the current joints (:func:`corrected_joints`);
* :meth:`SimArm.servo`: toward an absolute target with a first-order response (EGM's
  position guidance, the UR program's servoing), the fraction :func:`lag_gain` of the way
  each cycle.

Either raises UnreachableError or :class:`JointStepError` (a joint step beyond the speed
limit: near a singularity the closest solution can jump), which each controller turns into
its own fault (ALTER's FAULT, RSI stopped, EGM stopped, a UR protective stop).
"""

from __future__ import annotations

import math

import numpy as np

from humanpt.geometry.arm import UnreachableError
from humanpt.geometry.transforms import interpolate_transform, invert_transform, transform_from_x

__all__ = ["JointStepError", "SimArm", "UnreachableError", "corrected_joints", "lag_gain"]


class JointStepError(ValueError):
    """A correction that needs a joint step beyond the joint speed limit."""


def lag_gain(cycle_ms: float, time_constant_ms: float) -> float:
    """The fraction of the way to its setpoint a first-order system of time constant
    ``time_constant_ms`` covers in one cycle of ``cycle_ms`` (1 - exp(-cycle/tau); 1: no
    lag when the time constant is 0)."""
    return 1.0 if time_constant_ms <= 0 else -math.expm1(-cycle_ms / time_constant_ms)


def corrected_joints(kin, base_T_flange_mm: np.ndarray, delta_T_mm: np.ndarray, mode: str,
                     q_ref_rad: np.ndarray, max_step_deg: float) -> np.ndarray:
    """The joints (rad, (6,)) that put the flange at ``base_T_flange_mm`` (4, 4) moved by one
    relative correction ``delta_T_mm`` (4, 4): ``mode`` "tool" = in the flange frame
    (T @ delta), else in the base frame about the flange origin ([dR R, p + dp]); inverse
    kinematics on the solution closest to ``q_ref_rad``. Shared by every simulated link:
    one robot model. Raises UnreachableError ("is unreachable: ...") or JointStepError
    ("needs a joint step of ...") if the step is beyond ``max_step_deg`` per cycle on any
    joint."""
    T = base_T_flange_mm
    if mode == "tool":
        target = T @ delta_T_mm
    else:
        target = np.eye(4)
        target[:3, :3] = delta_T_mm[:3, :3] @ T[:3, :3]
        target[:3, 3] = T[:3, 3] + delta_T_mm[:3, 3]
    try:
        q = kin.inverse(target, q_ref_rad)
    except UnreachableError as e:
        raise UnreachableError(f"is unreachable: {e}") from None
    steps = [abs(a - b) for a, b in zip(q.tolist(), q_ref_rad.tolist(), strict=True)]
    step_deg = math.degrees(max(steps))
    if step_deg > max_step_deg:
        raise JointStepError(f"needs a joint step of {step_deg:.2f} deg "
                             f"(> {max_step_deg:.2f} deg per cycle; near a singularity?)")
    return q


class SimArm:
    """The arm of a simulated controller as ``[sim_robot]`` sets it up (module docstring).
    ``cycle_ms``: the controller's cycle (default the config's: the link's), for the joint
    step a cycle allows. ``q_rad`` (the joints, the encoders' angles) is the state."""

    def __init__(self, config, cycle_ms: float | None = None) -> None:
        self.model = config.model
        self.kin = config.kinematics()
        self.q_rad = config.start_joints_rad()
        self.world_T_base = transform_from_x(np.asarray(config.world_T_base_mm_deg, dtype=float))
        self.true_arm = None if config.ideal_arm else config.true_arm()
        cycle = config.cycle_ms if cycle_ms is None else cycle_ms
        self.max_joint_step_deg = config.max_joint_speed_deg_s * cycle / 1000.0
        self._fk: tuple[bytes, np.ndarray] | None = None  # (q_rad bytes, base_T_flange)

    # -- where the flange is ------------------------------------------------------------------
    def forward(self) -> np.ndarray:
        """(4, 4) base_T_flange (mm) of the nominal kinematics at the joints, computed once
        per joint position. Shared: do not modify."""
        key = self.q_rad.tobytes()
        if self._fk is None or self._fk[0] != key:
            self._fk = (key, self.kin.forward(self.q_rad))
        return self._fk[1]

    @property
    def base_T_flange_mm(self) -> np.ndarray:
        """(4, 4) the flange in the base frame as the controller believes it, mm (a copy)."""
        return self.forward().copy()

    @property
    def world_T_flange_mm(self) -> np.ndarray:
        """(4, 4) the flange in the world as the controller believes it (nominal), mm."""
        return self.world_T_base @ self.forward()

    @property
    def true_world_T_flange_mm(self) -> np.ndarray:
        """(4, 4) where the flange really is (the world's arm), mm."""
        if self.true_arm is None:
            return self.world_T_flange_mm
        return self.world_T_base @ self.true_arm.forward(self.q_rad)

    def true_world_T_flange_m(self) -> np.ndarray:
        """(4, 4) the true flange in the world, m (the ``sim_robot/truth`` pose)."""
        T = self.true_world_T_flange_mm
        T[:3, 3] /= 1000.0
        return T

    # -- moving -------------------------------------------------------------------------------
    def corrected(self, base_T_flange_mm: np.ndarray, delta_T_mm: np.ndarray, mode: str,
                  q_ref_rad: np.ndarray) -> np.ndarray:
        """:func:`corrected_joints` with this arm's kinematics and joint-step limit."""
        return corrected_joints(self.kin, base_T_flange_mm, delta_T_mm, mode, q_ref_rad, self.max_joint_step_deg)

    def step(self, delta_T_mm: np.ndarray, mode: str) -> np.ndarray:
        """Move the joints by one relative correction (:func:`corrected_joints`) from where
        they are; the new joints. Raises as corrected_joints does (the arm stays)."""
        self.q_rad = self.corrected(self.forward(), delta_T_mm, mode, self.q_rad)
        return self.q_rad

    def servo(self, target_T_mm: np.ndarray, gain: float) -> bool:
        """One cycle toward the absolute target ``target_T_mm`` (base frame, mm): the
        fraction ``gain`` of the way (straight line, geodesic), in the base frame about the
        flange origin. False when already there (nothing moved). Raises as
        corrected_joints does (the arm stays)."""
        T = self.forward()
        want = interpolate_transform(T, target_T_mm, gain)
        delta = want @ invert_transform(T)  # in the base frame: [dR, p' - dR p]
        delta[:3, 3] = want[:3, 3] - T[:3, 3]  # (corrected_joints' base-frame step: about the flange origin)
        if float(np.abs(delta[:3, 3]).max()) < 1e-9 and np.allclose(delta[:3, :3], np.eye(3), atol=1e-12):
            return False
        self.q_rad = self.corrected(T, delta, "world", self.q_rad)
        return True


class ArmViews:
    """The arm's state as properties of the simulated controller that owns ``self.arm`` (a
    :class:`SimArm`): one set of views for every simulated controller (ALTER, RSI, EGM, RTDE)."""

    arm: SimArm

    @property
    def kin(self):
        return self.arm.kin

    @property
    def q_rad(self) -> np.ndarray:
        """(6,) the joints (encoders), rad."""
        return self.arm.q_rad

    @q_rad.setter
    def q_rad(self, value: np.ndarray) -> None:
        self.arm.q_rad = value

    @property
    def world_T_base(self) -> np.ndarray:
        return self.arm.world_T_base

    @property
    def true_arm(self):
        return self.arm.true_arm

    @property
    def base_T_flange_mm(self) -> np.ndarray:
        """(4, 4) the flange in the robot base frame as the controller believes it, mm (a copy)."""
        return self.arm.base_T_flange_mm

    @property
    def world_T_flange_mm(self) -> np.ndarray:
        """(4, 4) the flange in the world as the controller believes it (nominal), mm."""
        return self.arm.world_T_flange_mm

    @property
    def true_world_T_flange_mm(self) -> np.ndarray:
        """(4, 4) where the flange really is (the world's arm), mm."""
        return self.arm.true_world_T_flange_mm
