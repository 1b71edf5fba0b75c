"""Playback on a calibrated arm (issue 32.4, controller.playback.command_poses and
plan_on_arm's ``RobotArm.true_arm``): each seam pose is commanded as the pose the nominal
model reaches with the joints that put the calibrated arm on the seam.  Expected values:
the physical arm's forward kinematics (geometry.puma.TrueArm) at the planned joints is the
seam itself; without the calibration it is off by the arm's absolute error (the realistic
world's errors: about 1 mm)."""

from __future__ import annotations

import numpy as np

from humanpt.controller.playback import RobotArm, command_poses, plan_on_arm
from humanpt.geometry.puma import (
    HOME_JOINTS_DEG,
    PumaKinematics,
    TrueArm,
    follow,
    perturbed_geometry,
)
from humanpt.geometry.transforms import interpolate_transform, transform_from_x, x_from_transform

KIN = PumaKinematics()
TOOL = transform_from_x(np.array([0.0, 0, 200, 0, 0, 0]))
HOME = np.radians(HOME_JOINTS_DEG)
DT = 0.028
TRUE = TrueArm(perturbed_geometry(KIN.geometry, [0.3, -0.2, 0.3, -0.2, 0.1]),
               np.radians([0.03, -0.02, 0.03, -0.03, 0.02, -0.02]))  # twin/worlds.py's realistic arm
W = transform_from_x(np.array([200.0, 100.0, 0.0, 10.0, 0.0, 0.0]))


def _seam() -> np.ndarray:
    qa, qb = HOME + np.radians([5.0, 3, -4, 0, 5, 0]), HOME + np.radians([-5.0, -2, 4, 0, 5, 0])
    Ta, Tb = W @ KIN.forward(qa) @ TOOL, W @ KIN.forward(qb) @ TOOL
    return np.array([x_from_transform(interpolate_transform(Ta, Tb, s)) for s in np.linspace(0.0, 1.0, 80)])


def test_command_poses_put_the_calibrated_arm_on_the_desired_poses():
    x = _seam()
    desired = np.linalg.inv(W) @ transform_from_x(x) @ np.linalg.inv(TOOL)
    q, cmd = command_poses(KIN, TRUE, desired, follow(KIN, desired, HOME))
    np.testing.assert_allclose([TRUE.forward(qi) for qi in q], desired, atol=1e-6)
    np.testing.assert_allclose([KIN.forward(qi) for qi in q], cmd, atol=1e-9)
    shift = np.linalg.norm(cmd[:, :3, 3] - desired[:, :3, 3], axis=1)
    assert 0.3 < shift.min() and shift.max() < 3.0  # the arm's absolute error, about a millimetre


def test_a_plan_on_the_calibrated_arm_puts_the_true_torch_on_the_seam():
    x = _seam()
    t = np.arange(len(x)) * DT * 4
    nominal = plan_on_arm(x, t, TOOL, RobotArm(KIN, W, HOME))
    calibrated = plan_on_arm(x, t, TOOL, RobotArm(KIN, W, HOME, true_arm=TRUE))

    def torch(plan):  # where the physical arm puts the torch along the seam
        q = plan.joints_rad[plan.approach:]
        return np.array([W @ TRUE.forward(qi) @ TOOL for qi in q])[:, :3, 3]

    seam = transform_from_x(x)[:, :3, 3]
    err_nominal = np.linalg.norm(torch(nominal) - seam, axis=1)
    err_calibrated = np.linalg.norm(torch(calibrated) - seam, axis=1)
    assert err_nominal.min() > 0.3
    assert err_calibrated.max() < 1e-5
    # What is sent are the commands, and the controller's closest-branch IK takes them to
    # the planned joints.
    k = calibrated.approach
    base_T_flange = np.linalg.inv(W) @ transform_from_x(calibrated.x[k:]) @ np.linalg.inv(TOOL)
    np.testing.assert_allclose(follow(KIN, base_T_flange, calibrated.joints_rad[k]), calibrated.joints_rad[k:],
                               atol=1e-6)
