"""Puma forward/inverse kinematics: known poses, FK(IK(T)) == T, branch choice, limits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from humanpt.geometry.puma import (
    PUMA_JOINT_LIMITS_DEG,
    PumaKinematics,
    PumaModel,
    RobotModelConfig,
    UnreachableError,
)

FAST = settings(max_examples=120, deadline=None, derandomize=True)
MODELS = [PumaModel.PUMA_762, PumaModel.PUMA_560]
KIN = {m: PumaKinematics(RobotModelConfig(model=m)) for m in MODELS}
LIMITS = np.radians(np.array(PUMA_JOINT_LIMITS_DEG))


def random_q(seed: int, margin_rad: float = 0.05) -> np.ndarray:
    """Joint angles inside the limits, away from the wrist singularity (|q5| > 3 deg)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(LIMITS[:, 0] + margin_rad, LIMITS[:, 1] - margin_rad)
    if abs(q[4]) < np.radians(3):
        q[4] = np.radians(3) * (1 if q[4] >= 0 else -1) + q[4]
    return q


def pose_error(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(position error mm, rotation error rad)."""
    dp = float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]))
    dr = float(
        (Rotation.from_matrix(T_a[:3, :3]).inv() * Rotation.from_matrix(T_b[:3, :3])).magnitude()
    )
    return dp, dr


def test_forward_at_zero_matches_the_dh_table():
    T = KIN[PumaModel.PUMA_762].forward(np.zeros(6))
    assert np.allclose(T[:3, :3], np.eye(3))
    assert np.allclose(T[:3, 3], [650.0, 190.0, 600.0 + 125.0])
    T = KIN[PumaModel.PUMA_560].forward(np.zeros(6))
    assert np.allclose(T[:3, 3], [431.8 - 20.32, 149.09, 433.07 + 56.25])


def test_arm_straight_up():
    q = np.radians([0, -90, 90, 0, 0, 0])
    T = KIN[PumaModel.PUMA_762].forward(q)
    assert np.allclose(T[:3, 3], [0.0, 190.0, 650.0 + 600.0 + 125.0])
    assert np.allclose(T[:3, 2], [0, 0, 1])  # flange z up
    # Joint 1 turns the whole arm about base z.
    T1 = KIN[PumaModel.PUMA_762].forward(q + np.radians([90, 0, 0, 0, 0, 0]))
    assert np.allclose(T1[:3, 3], [-190.0, 0.0, 1375.0])


@pytest.mark.parametrize("model", MODELS)
@FAST
@given(seed=st.integers(0, 2**32 - 1))
def test_every_ik_branch_reproduces_the_pose(model, seed):
    kin = KIN[model]
    q = random_q(seed)
    T = kin.forward(q)
    solutions = kin.inverse_all(T, q)
    assert len(solutions) == 8
    assert len({s.config for s in solutions}) == 8  # each branch labelled distinctly
    for s in solutions:
        dp, dr = pose_error(kin.forward(s.q_rad), T)
        assert dp < 1e-6 and dr < 1e-9, (s.config, dp, dr)
        assert s.within_limits == kin.within_limits(s.q_rad)
    # The original joints are one of the branches, and the chooser returns them.
    assert kin.inverse(T, q) == pytest.approx(q, abs=1e-7)


@pytest.mark.parametrize("model", MODELS)
@FAST
@given(seed=st.integers(0, 2**32 - 1))
def test_ik_picks_the_branch_closest_to_the_current_joints(model, seed):
    kin = KIN[model]
    rng = np.random.default_rng([seed, 1])
    q_true = random_q(seed)
    T = kin.forward(q_true)
    # The robot is 1 deg per joint away from q_true, e.g. last cycle's joints.
    q_now = q_true + np.radians(rng.uniform(-1, 1, 6))
    q = kin.inverse(T, q_now)
    valid = [s.q_rad for s in kin.inverse_all(T, q_now) if s.within_limits]
    distances = [np.linalg.norm(v - q_now) for v in valid]
    assert np.linalg.norm(q - q_now) == pytest.approx(min(distances))
    if len(distances) == 1 or sorted(distances)[1] > np.radians(10):
        # The other branches are well apart: it must be q_true's.
        assert q == pytest.approx(q_true, abs=1e-7)


def test_ik_keeps_joint_6_on_its_own_turn():
    """Joint 6 turns +-266 deg: the solution nearest the current joints uses q6 + 360."""
    kin = KIN[PumaModel.PUMA_762]
    q_now = np.radians([10, -70, 110, 0, 30, 250])
    T = kin.forward(q_now)
    assert np.degrees(kin.inverse(T, q_now))[5] == pytest.approx(250)
    q_other = q_now.copy()
    q_other[5] = np.radians(-100)
    assert np.degrees(kin.inverse(T, q_other))[5] == pytest.approx(-110)


def test_wrist_singularity_keeps_q4():
    kin = KIN[PumaModel.PUMA_762]
    q_now = np.radians([20, -80, 100, 35, 0, -10])
    T = kin.forward(q_now)
    q = kin.inverse(T, q_now)
    assert q == pytest.approx(q_now, abs=1e-9)
    dp, dr = pose_error(kin.forward(q), T)
    assert dp < 1e-6 and dr < 1e-9


@pytest.mark.parametrize("model", MODELS)
def test_out_of_reach_raises(model):
    kin = KIN[model]
    g = kin.geometry
    reach = g.a2_mm + np.hypot(g.a3_mm, g.d4_mm) + g.d6_mm
    T = np.eye(4)
    T[:3, 3] = [reach + np.hypot(reach, g.d2_mm), 0.0, 0.0]
    assert kin.inverse_all(T) == []
    with pytest.raises(UnreachableError, match="out of reach"):
        kin.inverse(T, np.zeros(6))
    T[:3, 3] = [0.0, 0.0, 0.0]  # wrist centre inside the shoulder-offset cylinder
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[2, 3] = -g.d6_mm
    with pytest.raises(UnreachableError, match="out of reach"):
        kin.inverse(T, np.zeros(6))


def test_reachable_but_outside_joint_limits_raises():
    kin = KIN[PumaModel.PUMA_762]
    q = np.radians([0, -60, 100, 0, 150, 0])  # |q5| = 150 deg on either wrist branch
    T = kin.forward(q)
    assert kin.inverse_all(T)  # the pose itself is reachable
    with pytest.raises(UnreachableError, match="joint limits"):
        kin.inverse(T, np.zeros(6))


def test_jacobian_matches_finite_differences():
    kin = KIN[PumaModel.PUMA_560]
    q = random_q(7)
    J = kin.jacobian(q)
    eps = 1e-7
    T0 = kin.forward(q)
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = eps
        T1 = kin.forward(q + dq)
        assert np.allclose((T1[:3, 3] - T0[:3, 3]) / eps, J[:3, j], atol=1e-4)
        w = Rotation.from_matrix(T1[:3, :3] @ T0[:3, :3].T).as_rotvec() / eps
        assert np.allclose(w, J[3:, j], atol=1e-6)


def test_config_validation():
    assert RobotModelConfig(model="puma560").model is PumaModel.PUMA_560
    with pytest.raises(ValueError, match="unknown robot model"):
        RobotModelConfig(model="puma999")
    with pytest.raises(ValueError, match="6"):
        RobotModelConfig(joint_limits_deg=((-10, 10),) * 5)
    with pytest.raises(ValueError, match="lo < hi"):
        RobotModelConfig(joint_limits_deg=((10, -10),) + PUMA_JOINT_LIMITS_DEG[1:])
    with pytest.raises(ValueError, match="two turns"):
        RobotModelConfig(joint_limits_deg=((-400, 400),) + PUMA_JOINT_LIMITS_DEG[1:])
    kin = KIN[PumaModel.PUMA_762]
    with pytest.raises(ValueError):
        kin.forward(np.zeros(5))
    with pytest.raises(ValueError):
        kin.inverse_all(np.eye(3))
