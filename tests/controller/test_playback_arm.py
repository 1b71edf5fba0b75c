"""Playback planned on an arm with kinematics (issue 33.1, controller.playback.plan_on_arm):
a joint-space approach that keeps the wrist on its side of the singularity, the seam slowed
where a joint would be too fast, and a refusal with the reason before any motion when the
Puma cannot play a seam at its mounting.  The limits are the stated ones: the sim_robot
faults beyond max_joint_speed_deg_s (250 deg/s) x 28 ms = 7 deg a cycle; a plan keeps
PLAYBACK_LIMIT_SHARE (90 %) of it, 6.3 deg, and of the gateway's 100 mm/s and 60 deg/s."""

from __future__ import annotations

import math

import numpy as np
import pytest

from humanpt.controller.playback import PLAYBACK_LIMIT_SHARE, PlaybackError, RobotArm, plan_on_arm
from humanpt.geometry.puma import HOME_JOINTS_DEG, PumaKinematics, follow
from humanpt.geometry.transforms import interpolate_transform, transform_from_x, x_from_transform

KIN = PumaKinematics()
TOOL = transform_from_x(np.array([0.0, 0, 200, 0, 0, 0]))  # the torch, 200 mm along the flange's z
HOME = np.radians(HOME_JOINTS_DEG)
DT = 0.028
STEP_LIMIT_DEG = PLAYBACK_LIMIT_SHARE * 250.0 * DT  # 6.3 deg a cycle


def _tool_x(q):
    return x_from_transform(KIN.forward(q) @ TOOL)


def _between(qa, qb, n):
    """n tool poses on the Cartesian straight line (and slerp) between two joint poses."""
    Ta, Tb = KIN.forward(qa) @ TOOL, KIN.forward(qb) @ TOOL
    return np.array([x_from_transform(interpolate_transform(Ta, Tb, s)) for s in np.linspace(0.0, 1.0, n)])


def _world_x(x, world_T_base):
    return x_from_transform(world_T_base @ transform_from_x(x))


@pytest.mark.parametrize("world_T_base_x", [(0.0, 0, 0, 0, 0, 0), (1500.0, -300, 2000, 30, 0, 180)])
def test_the_approach_is_in_joint_space_and_within_every_limit(world_T_base_x):
    """From the home pose (q5 = +25 deg) to a seam whose closest branch is on the other side
    of the wrist singularity (q4 = 100, q5 = -30 deg): the plan takes the flipped wrist on
    the same side (q4 = -80, q5 = +30: q5 > 0 all the way), every joint step of a cycle within 6.3 deg, the flange within
    90 mm/s, and it ends on the seam's first pose; floor and ceiling mountings alike."""
    world_T_base = transform_from_x(np.array(world_T_base_x))
    q_seam = HOME + np.radians([20.0, 5, -10, 100, -55, 30])  # q5 = 25 - 55 = -30 deg; its flip +30
    x = _world_x(_between(q_seam, q_seam + np.radians([10.0, 0, 0, 0, 0, 0]), 100), world_T_base)
    plan = plan_on_arm(x, np.arange(100) * DT, TOOL, RobotArm(KIN, world_T_base, HOME))
    q = plan.joints_rad
    assert np.all(q[:, 4] > math.radians(2.0)), np.degrees(q[:, 4].min())  # never across q5 = 0
    np.testing.assert_allclose(np.degrees(q[plan.approach, 3:5]), [-80.0, 30.0], atol=1e-6)
    assert plan.max_joint_speed_deg_s * DT <= STEP_LIMIT_DEG + 1e-9
    flange = np.array([world_T_base @ KIN.forward(qi) for qi in q])[:, :3, 3]
    v = np.linalg.norm(np.diff(flange, axis=0), axis=1) / np.diff(plan.t_s)
    assert v.max() <= 0.9 * 100.0 + 1e-6
    # The arm's controller takes the planned poses to the planned joints (closest branch).
    base_T_flange = np.linalg.inv(world_T_base) @ transform_from_x(plan.x) @ np.linalg.inv(TOOL)
    np.testing.assert_allclose(follow(KIN, base_T_flange, HOME), q, atol=1e-6)
    np.testing.assert_allclose(plan.x[plan.approach], x[0], atol=1e-6)
    np.testing.assert_allclose(plan.x[plan.approach:], x)  # the seam itself as given, in Cartesian space


def test_a_seam_near_the_wrist_singularity_is_slowed_where_a_joint_would_be_too_fast():
    """Near the wrist singularity a small motion of the flange turns joints 4 and 6 a lot:
    a seam (the poses of a joint path: q5 from 25 down to 4 deg and back, joints 4 and 6
    turning 80 deg in 15 cycles at the bottom, up to 8 deg a cycle) timed one pose a
    cycle is too fast for the 6.3 deg; the plan stretches the timing there (the same poses,
    later) and every joint step stays within it."""
    n = 100
    s = np.linspace(0.0, 1.0, n)
    u = np.clip((np.arange(n) - 40) / 15.0, 0.0, 1.0)
    turn = 80.0 * (3 * u**2 - 2 * u**3)  # smoothstep: 1.5 x the mean rate at its middle (joint 6 to -260 deg, in limits)
    q = np.tile(HOME, (n, 1))
    q[:, 4] = np.radians(25.0 - 21.0 * np.sin(np.pi * s))
    q[:, 3] += np.radians(turn)
    q[:, 5] -= np.radians(turn)
    x = np.array([_tool_x(qi) for qi in q])
    t = np.arange(n) * DT
    assert np.degrees(np.abs(np.diff(q, axis=0)).max()) > STEP_LIMIT_DEG  # as timed, too fast
    plan = plan_on_arm(x, t, TOOL, RobotArm(KIN, np.eye(4), HOME))
    assert plan.slowdown == pytest.approx(1.5 * 80.0 / 15 / STEP_LIMIT_DEG, rel=0.01)  # 8 deg a cycle over 6.3
    assert plan.max_joint_speed_deg_s * DT <= STEP_LIMIT_DEG * (1 + 1e-9)
    np.testing.assert_allclose(plan.x[plan.approach:], x)
    np.testing.assert_allclose(plan.joints_rad[plan.approach:], q, atol=1e-6)  # the arm's joints as planned
    assert plan.min_wrist_deg == pytest.approx(4.0, abs=0.05)


def test_a_seam_through_the_wrist_singularity_is_refused_with_the_reason():
    """The straight line between q5 = +20 and q5 = -20 deg (the rest the same) passes through
    q5 = 0: no branch plays it without crossing; refused before anything moves."""
    qa, qb = HOME.copy(), HOME.copy()
    qa[4], qb[4] = math.radians(20.0), math.radians(-20.0)
    x = _between(qa, qb, 100)
    with pytest.raises(PlaybackError, match="wrist singularity"):
        plan_on_arm(x, np.arange(100) * DT, TOOL, RobotArm(KIN, np.eye(4), qa))


def test_a_seam_out_of_reach_is_refused_with_the_point():
    """The Puma 762 reaches about 1.2 m from its shoulder (a2 + hypot(a3, d4) + d6 +
    the torch); a seam 3 m off is refused naming its first point."""
    x = np.tile(_tool_x(HOME), (20, 1))
    x[:, 0] += 3000.0
    with pytest.raises(PlaybackError, match=r"point 0 \(tool at \[.*\] mm\) is out of the arm's reach"):
        plan_on_arm(x, np.arange(20) * DT, TOOL, RobotArm(KIN, np.eye(4), HOME))
    # reachable at first, then out of reach: the point named is the first one out
    y = np.tile(_tool_x(HOME), (60, 1))
    y[:, 0] += np.linspace(0.0, 3000.0, 60)
    with pytest.raises(PlaybackError, match="out of the arm's reach"):
        plan_on_arm(y, np.arange(60) * DT * 20, TOOL, RobotArm(KIN, np.eye(4), HOME))
