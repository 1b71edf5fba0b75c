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
    of the wrist singularity (q5 = -30 deg): the plan takes the branch on the same side
    (q5 > 0 all the way), every joint step of a cycle within 6.3 deg, the flange within
    90 mm/s, and it ends on the seam's first pose; floor and ceiling mountings alike."""
    world_T_base = transform_from_x(np.array(world_T_base_x))
    q_seam = HOME + np.radians([40.0, 10, -20, 60, -55, 30])  # q5 = 25 - 55 = -30 deg
    x = _world_x(_between(q_seam, q_seam + np.radians([10.0, 0, 0, 0, 0, 0]), 100), world_T_base)
    plan = plan_on_arm(x, np.arange(100) * DT, TOOL, RobotArm(KIN, world_T_base, HOME))
    q = plan.joints_rad
    assert np.all(q[:, 4] > math.radians(2.0)), np.degrees(q[:, 4].min())  # never across q5 = 0
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
    """q5 from 20 deg down to 3 deg and back over 50 cycles: joint 4 would turn faster than
    its share near q5 = 3 deg; the plan stretches the timing there (same poses, later) and
    every joint step stays within 6.3 deg a cycle."""
    qa = HOME.copy()
    qb = HOME + np.radians([0.0, 0, 0, 0, -22, 0])
    qb[3] += math.radians(0.0)
    # a path that makes the wrist sweep about the singularity: rotate about the forearm near q5 = 3 deg
    qc = qb + np.radians([0.0, 0, 0, 120, 0, -120])
    x = np.vstack([_between(qa, qb, 40), _between(qb, qc, 30)[1:], _between(qc, qa, 40)[1:]])
    t = np.arange(len(x)) * DT
    base_T_flange = transform_from_x(x) @ np.linalg.inv(TOOL)
    raw = follow(KIN, base_T_flange, HOME)
    assert np.degrees(np.abs(np.diff(raw, axis=0)).max()) > STEP_LIMIT_DEG  # as timed, too fast
    plan = plan_on_arm(x, t, TOOL, RobotArm(KIN, np.eye(4), HOME))
    assert plan.slowdown > 1.0
    assert plan.max_joint_speed_deg_s * DT <= STEP_LIMIT_DEG * (1 + 1e-9)
    np.testing.assert_allclose(plan.x[plan.approach:], x)


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
