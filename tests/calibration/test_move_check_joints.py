"""The hand-eye and arm stages' move check follows the robot's own joints (issue 32.4):
on the arc of seed 4 the wrist had wound to q6 = -266 deg (its limit) while the check,
starting every move from the Puma's home branch, saw q6 near -180 + k*360 and passed the
move; the robot flipped its wrist, faulted, and the arm stage fitted 8 poses of 28 (its
joint offsets 4-7 sigma off). The check is the nominal Puma model alone (no twin): a
few inverse kinematics, milliseconds."""

from __future__ import annotations

import numpy as np

from humanpt.calibration.handeye import puma_move_check
from humanpt.geometry.puma import HOME_JOINTS_DEG, PumaKinematics, RobotModelConfig

KIN = PumaKinematics(RobotModelConfig())
BASE = (0.0,) * 6  # the robot's base at the world's origin


def _flange(q6_deg: float) -> np.ndarray:
    """The home pose with joint 6 at ``q6_deg`` (a roll of the flange about its axis)."""
    q = np.array(HOME_JOINTS_DEG, dtype=float)
    q[5] = q6_deg
    return KIN.forward(np.radians(q))


def _joints(q6_deg: float) -> np.ndarray:
    q = np.array(HOME_JOINTS_DEG, dtype=float)
    q[5] = q6_deg
    return q


def test_a_wound_wrist_is_seen_from_the_robots_joints():
    # the robot's q6 at +220 deg (the pose is the same as at -140 deg, which the home
    # branch, q6 = -180, picks): turning on by +20 deg takes it to +240, within 30 deg of
    # its +266 deg limit; back by -20 deg is fine
    a, on, back = _flange(220.0), _flange(240.0), _flange(200.0)
    from_home = puma_move_check(BASE)
    assert from_home(a, on) is None  # what planned the fault
    robots = puma_move_check(BASE, start_joints_deg=_joints(220.0))
    assert "joint 6's limit" in robots(a, on)
    assert robots(a, back) is None


def test_the_next_move_starts_where_the_last_one_passed_ended():
    robots = puma_move_check(BASE, start_joints_deg=_joints(220.0))
    assert robots(_flange(220.0), _flange(200.0)) is None  # now at q6 = +200
    # +45 deg from there is +245: refused; a fresh check from the home branch (-160 -> -115) passes it
    assert "joint 6's limit" in robots(_flange(200.0), _flange(245.0))
    assert puma_move_check(BASE)(_flange(200.0), _flange(245.0)) is None
    # a move that does not start where the last passed one ended starts from the start joints again
    assert robots(_flange(150.0), _flange(170.0)) is None


def test_the_move_is_the_tools():
    # a tool 300 mm along the flange's z: a roll of the tool about its own point swings the
    # flange; the same end poses, the same verdicts (the ends are the robot's), and the
    # path between is the tool's line, so a move with the tool off the flange still
    # reaches its end joints
    tool = np.eye(4)
    tool[2, 3] = 300.0
    robots = puma_move_check(BASE, start_joints_deg=_joints(-180.0), flange_T_tool_mm=tool)
    assert robots(_flange(-180.0), _flange(-170.0)) is None
    assert "joint 6's limit" in puma_move_check(BASE, start_joints_deg=_joints(220.0),
                                                flange_T_tool_mm=tool)(_flange(220.0), _flange(240.0))
