"""The arm kinematics core (geometry/arm.py, arms.py): forward kinematics at published poses
by hand, inverse round trips over random reachable poses on each solver, the Puma as one
model on it, limits, singularities."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry.arm import (
    ArmKinematics,
    SphericalWristKinematics,
    UnreachableError,
    UrKinematics,
)
from humanpt.geometry.arms import ARM_NAMES, IRB1600, UR5E, arm_kinematics, arm_model
from humanpt.geometry.puma import GEOMETRY, PUMA_JOINT_LIMITS_DEG, PumaKinematics, PumaModel

# UR's published UR5e table (mm), written out again here: the hand calculations use these.
D1, A2, A3, D4, D5, D6 = 162.5, -425.0, -392.2, 133.3, 99.7, 99.6


def pose_error(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(position error mm, rotation error rad), the rotation by scipy."""
    dp = float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]))
    dr = float((Rotation.from_matrix(T_a[:3, :3]).inv() * Rotation.from_matrix(T_b[:3, :3])).magnitude())
    return dp, dr


def random_q(kin: ArmKinematics, rng: np.random.Generator, margin_rad: float = 0.05) -> np.ndarray:
    """Joints inside the limits (within one turn of 0), away from the wrist and elbow
    singularities."""
    lo = np.maximum(kin.limits_rad[:, 0], -np.pi) + margin_rad
    hi = np.minimum(kin.limits_rad[:, 1], np.pi) - margin_rad
    while True:
        q = rng.uniform(lo, hi)
        s = kin.singularity(q)
        if s.wrist > 0.05 and s.elbow > 0.05:
            return q


def test_ur5e_at_zero_joints_by_hand():
    # q = 0: every link along the base x axis, the wrist offsets along -y, d5 down:
    # flange at x = a2 + a3, y = -(d4 + d6), z = d1 - d5, its z axis along -y, x along +x.
    T = arm_kinematics("ur5e").forward(np.zeros(6))
    assert T[:3, 3] == pytest.approx([A2 + A3, -(D4 + D6), D1 - D5], abs=1e-9)
    assert T[:3, 3] == pytest.approx([-817.2, -232.9, 62.8], abs=1e-9)
    assert T[:3, 0] == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)
    assert T[:3, 1] == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert T[:3, 2] == pytest.approx([0.0, -1.0, 0.0], abs=1e-12)


def test_ur5e_upright_by_hand():
    # q = (0, -90, 0, -90, 0, 0) deg: upper arm and forearm straight up (-a2 - a3 above the
    # shoulder), d5 further up, the wrist offsets d4 + d6 along -y.
    T = arm_kinematics("ur5e").forward(np.radians([0.0, -90.0, 0.0, -90.0, 0.0, 0.0]))
    assert T[:3, 3] == pytest.approx([0.0, -(D4 + D6), D1 - A2 - A3 + D5], abs=1e-9)


def test_irb1600_calibration_pose_by_hand():
    # ABB's calibration pose (all axes 0): upper arm vertical, forearm level; the flange is
    # a1 + d4 + d6 ahead of axis 1 at d1 + a2, pointing forward (+x).
    T = arm_kinematics("irb1600").forward(np.zeros(6))
    assert T[:3, 3] == pytest.approx([150.0 + 600.0 + 65.0, 0.0, 486.5 + 700.0], abs=1e-9)
    assert T[:3, 2] == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)
    # axis 2 +90 deg: the upper arm tilts forward to level, the forearm then points down.
    T = arm_kinematics("irb1600").forward(np.radians([0.0, 90.0, 0.0, 0.0, 0.0, 0.0]))
    assert T[:3, 3] == pytest.approx([150.0 + 700.0, 0.0, 486.5 - 600.0 - 65.0], abs=1e-9)


def test_solvers_and_models():
    assert isinstance(arm_kinematics("ur5e"), UrKinematics)
    assert isinstance(arm_kinematics("irb1600"), SphericalWristKinematics)
    assert isinstance(arm_kinematics("puma762"), PumaKinematics)
    assert isinstance(arm_kinematics("puma762"), ArmKinematics)
    with pytest.raises(ValueError, match="unknown arm 'kr6'.*ur5e"):
        arm_model("kr6")
    assert np.degrees(arm_kinematics("ur5e").limits_rad[2]).tolist() == [-180.0, 180.0]


@pytest.mark.parametrize("name", ARM_NAMES)
def test_inverse_round_trip_random_poses(name):
    """Random joints within the limits -> FK -> inverse seeded near them: back to the same
    joints (the closest solution), within the limits, the same pose; every analytic
    solution reaches the pose."""
    kin = arm_kinematics(name)
    rng = np.random.default_rng(7)
    for _ in range(60):
        q = random_q(kin, rng)
        T = kin.forward(q)
        seed = q + rng.uniform(-0.02, 0.02, 6)
        q_ik = kin.inverse(T, seed)
        assert kin.within_limits(q_ik)
        dp, dr = pose_error(kin.forward(q_ik), T)
        assert dp < 1e-6 and dr < 1e-9
        assert q_ik == pytest.approx(q, abs=1e-7)
        sols = kin.solutions(T, q) if not isinstance(kin, PumaKinematics) else None
        for s in sols or ():
            dp, dr = pose_error(kin.forward(s), T)
            assert dp < 1e-6 and dr < 1e-9


def test_ur5e_has_eight_solutions_in_general():
    kin = arm_kinematics("ur5e")
    q = np.radians([20.0, -100.0, 70.0, -50.0, 60.0, 30.0])
    sols = kin.solutions(kin.forward(q), q)
    assert len(sols) == 8
    assert len({tuple(np.round(s, 6)) for s in sols}) == 8


@pytest.mark.parametrize("model", [PumaModel.PUMA_762, PumaModel.PUMA_560])
def test_spherical_solver_agrees_with_the_pumas_own(model):
    """The generic spherical-wrist solver on the Puma's table finds the Puma solver's answer."""
    puma = PumaKinematics()
    puma = PumaKinematics(type(puma.config)(model=model))
    generic = SphericalWristKinematics(GEOMETRY[model].dh(), np.radians(PUMA_JOINT_LIMITS_DEG))
    rng = np.random.default_rng(3)
    for _ in range(40):
        q = random_q(puma, rng)
        T = puma.forward(q)
        assert generic.forward(q) == pytest.approx(T, abs=1e-12)
        seed = q + rng.uniform(-0.3, 0.3, 6)
        assert generic.inverse(T, seed) == pytest.approx(puma.inverse(T, seed), abs=1e-9)


@pytest.mark.parametrize("model", [UR5E, IRB1600])
def test_numeric_inverse_agrees_with_analytic(model):
    """The damped least squares from joints near the solution converges to it (the
    analytic solver's closest one)."""
    analytic = model.kinematics()
    numeric = ArmKinematics(model.dh, analytic.limits_rad, analytic.theta_offsets_rad)
    rng = np.random.default_rng(11)
    for _ in range(15):
        q = random_q(analytic, rng)
        T = analytic.forward(q)
        seed = q + rng.uniform(-0.05, 0.05, 6)
        q_num = numeric.inverse(T, seed)
        assert q_num == pytest.approx(analytic.inverse(T, seed), abs=1e-8)
        dp, dr = pose_error(numeric.forward(q_num), T)
        assert dp < 1e-8 and dr < 1e-11


def test_limits_respected_and_out_of_reach():
    kin = arm_kinematics("irb1600")
    # axis 5 at 125 deg (beyond +-115): the same pose on the other wrist has axis 5 at
    # -125 deg, also beyond: the other solutions move axes 1-3 far; each returned one
    # is within limits.
    wide = IRB1600.kinematics(((-180, 180), (-90, 120), (-245, 65), (-200, 200), (-130, 130), (-400, 400)))
    q = np.radians([0.0, 20.0, 10.0, 0.0, 125.0, 0.0])
    T = wide.forward(q)
    for s in kin.solutions(T, q):
        fit = kin._fit_limits(list(s), q.tolist())
        assert fit is None or kin.within_limits(np.array(fit))
    try:
        q_ik = kin.inverse(T, q)
    except UnreachableError:
        pass
    else:
        assert kin.within_limits(q_ik) and abs(np.degrees(q_ik[4])) <= 115.0 + 1e-9
    for name in ARM_NAMES:
        k = arm_kinematics(name)
        far = np.eye(4)
        far[:3, 3] = (3000.0, 0.0, 0.0)
        with pytest.raises(UnreachableError, match="out of reach|did not converge"):
            k.inverse(far, np.radians(arm_model(name).home_joints_deg))
    # UR5e: joints beyond one turn are still within +-360 (a 2*pi-equivalent closest to the seed)
    ur = arm_kinematics("ur5e")
    q = np.radians([300.0, -100.0, 70.0, -50.0, 60.0, -300.0])
    assert ur.inverse(ur.forward(q), q) == pytest.approx(q, abs=1e-9)


def test_singularity_measure():
    ur = arm_kinematics("ur5e")
    assert ur.singularity(np.radians([0, -90, 45, 0, 0, 0])).wrist == pytest.approx(0.0, abs=1e-15)
    assert ur.singularity(np.radians([0, -90, 0, 0, 90, 0])).elbow == pytest.approx(0.0, abs=1e-15)
    assert ur.singularity(np.radians([0, -90, 90, 0, 90, 0])).least == pytest.approx(1.0)
    irb = arm_kinematics("irb1600")
    # calibration pose: forearm at right angles to the upper arm, wrist axis 5 at 0
    s = irb.singularity(np.zeros(6))
    assert s.elbow == pytest.approx(1.0) and s.wrist == pytest.approx(0.0, abs=1e-15)
    # axis 3 at -90: the forearm in line with the upper arm (stretched up)
    assert irb.singularity(np.radians([0, 0, -90, 0, 30, 0])).elbow == pytest.approx(0.0, abs=1e-15)
    puma = arm_kinematics("puma762")
    s = puma.singularity(np.radians([0.0, -90.0, 90.0, 0.0, 0.0, 0.0]))  # straight up
    assert s.elbow == pytest.approx(0.0, abs=1e-15) and s.wrist == pytest.approx(0.0, abs=1e-15)
