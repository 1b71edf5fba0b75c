"""Hand-eye AX = YB (humanpt.calibration.handeye): the solver against known transforms
(made up here, independent of the solver), its rejections, the OpenCV cross-check, the
pose planner, the pose collector's state machine and apply_to_rig."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from humanpt.calibration.handeye import (
    CollectorSettings,
    HandEyeError,
    PoseCollector,
    apply_to_rig,
    check_motion,
    closed_form_ax_yb,
    plan_poses,
    pose_difference,
    puma_move_check,
    solve_ax_yb,
)
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import (
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    transform_from_x,
)

# The truth of these tests: a camera 0.5 mm and a few tenths of a degree off the nominal
# hand-eye, and a target somewhere in the world, seen from 600 mm.
X_TRUE = transform_from_x([0.5, 60.2, 99.7, 0.3, 0.1, -0.2])
Y_TRUE = transform_from_x([236.1, 1248.8, 85.3, -2.6, -0.9, -4.5])
NOMINAL_X = Rig().hand_eye.flange_T_camera_mm()


def start_flange() -> np.ndarray:
    """The flange from which the true camera sees the target on its axis at 600 mm."""
    return Y_TRUE @ invert_transform(transform_from_x([0, 0, 600, 0, 0, 0])) @ invert_transform(X_TRUE)


def pairs(poses: np.ndarray, noise_mm=0.0, noise_deg=0.0, seed=0) -> np.ndarray:
    """camera_T_target at each flange pose: B = inv(X) inv(A) Y, with noise on the
    measurement (translation mm per axis, rotation deg per axis, camera frame)."""
    rng = np.random.default_rng(seed)
    out = []
    for A in poses:
        B = invert_transform(X_TRUE) @ invert_transform(A) @ Y_TRUE
        if noise_mm or noise_deg:
            B[:3, :3] = matrix_from_rotvec(rng.normal(0, np.radians(noise_deg), 3)) @ B[:3, :3]
            B[:3, 3] += rng.normal(0, noise_mm, 3)
        out.append(B)
    return np.array(out)


@pytest.fixture(scope="module")
def poses() -> np.ndarray:
    A, notes = plan_poses(start_flange(), NOMINAL_X, 600.0, n_poses=12, seed=3)
    assert len(A) == 12 and notes == []
    return A


def test_exact_pairs_give_the_true_x_and_y(poses):
    r = solve_ax_yb(poses, pairs(poses), cross_check=False)
    dt, da = pose_difference(r.flange_T_camera_mm, X_TRUE)
    assert dt < 1e-6 and da < 1e-6
    dt, da = pose_difference(r.world_T_target_mm, Y_TRUE)
    assert dt < 1e-5 and da < 1e-6
    # the closed form alone is exact too (no noise)
    X0, Y0 = closed_form_ax_yb(poses, pairs(poses))
    assert pose_difference(X0, X_TRUE)[0] < 1e-6
    assert np.all(r.residual_mm < 1e-6) and np.all(r.residual_deg < 1e-6)


def test_noisy_pairs_land_within_their_sigma(poses):
    # A PSVS measures depth (camera z) and the target's tilt worse than the rest.
    rng = np.random.default_rng(7)
    B = pairs(poses)
    for b in B:
        b[:3, 3] += rng.normal(0, [0.02, 0.02, 0.08])
        b[:3, :3] = matrix_from_rotvec(rng.normal(0, np.radians([0.03, 0.03, 0.005]))) @ b[:3, :3]
    r = solve_ax_yb(poses, B, cross_check=False)
    err = r.flange_T_camera_x - np.array([0.5, 60.2, 99.7, 0.3, 0.1, -0.2])
    assert np.all(np.abs(err) < 4 * r.flange_T_camera_sigma + 1e-9), (err, r.flange_T_camera_sigma)
    assert np.all(r.flange_T_camera_sigma > 0)
    # The residuals are about the noise that went in.
    assert 0.02 < np.sqrt(np.mean(r.residual_mm**2)) < 0.2
    lines = r.summary_lines()
    assert len([s for s in lines if s.strip()[:1].isdigit()]) == len(poses)
    assert any("spread" in s for s in lines)


def test_an_outlier_pose_is_dropped(poses):
    B = pairs(poses, noise_mm=0.01, noise_deg=0.01)
    B[5, :3, 3] += [3.0, 0.0, 0.0]  # a bad measurement
    r = solve_ax_yb(poses, B, cross_check=False)
    assert not r.used[5] and r.used.sum() == len(poses) - 1
    assert pose_difference(r.flange_T_camera_mm, X_TRUE)[0] < 0.1


def test_too_few_poses_is_refused(poses):
    with pytest.raises(HandEyeError, match="too few poses: 2"):
        solve_ax_yb(poses[:2], pairs(poses[:2]))
    same = np.array([poses[0], poses[0], poses[0], poses[1]])
    with pytest.raises(HandEyeError, match="too few distinct rotations: 2"):
        solve_ax_yb(same, pairs(same))


def test_rotations_about_one_axis_are_refused():
    F0 = start_flange()
    # turn the flange about one world axis only (through its origin): X's translation
    # along that axis cannot be found
    A = np.array([make_transform(matrix_from_rotvec([0, 0, np.radians(a)]), np.zeros(3)) @ F0
                  for a in (0, 10, 20, -15)])
    with pytest.raises(HandEyeError, match="degenerate motion: every relative rotation is about one axis"):
        check_motion(A)
    with pytest.raises(HandEyeError, match="degenerate motion"):
        solve_ax_yb(A, pairs(A))


def test_bad_inputs_are_refused(poses):
    with pytest.raises(HandEyeError, match="12 robot poses but 11"):
        solve_ax_yb(poses, pairs(poses)[:11])
    bad = pairs(poses)
    bad[3, :3, :3] *= 1.1
    with pytest.raises(HandEyeError, match=r"camera_T_target\[3\]"):
        solve_ax_yb(poses, bad)
    with pytest.raises(HandEyeError, match="expected"):
        solve_ax_yb(poses[:, :3, :], pairs(poses))


@pytest.mark.skipif(not (hasattr(cv2, "calibrateHandEye") and hasattr(cv2, "calibrateRobotWorldHandEye")),
                    reason="this OpenCV (5.0) does not export calibrateHandEye / calibrateRobotWorldHandEye")
def test_opencv_agrees_on_clean_pairs(poses):
    r = solve_ax_yb(poses, pairs(poses, noise_mm=0.005, noise_deg=0.002))
    assert len(r.cross_check) == 3
    for name, T in r.cross_check.items():
        dt, da = pose_difference(T, X_TRUE)
        assert dt < 0.1 and da < 0.01, name


def park_martin_x(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """X of A_i X B_i = Y by Park & Martin (1994), "Robot sensor calibration: solving AX = XB
    on the Euclidean group", IEEE Trans. Robot. Automat. 10(5), written here from the paper
    with scipy's rotation logarithm (independent of humanpt's maths and of OpenCV): each
    pair (i, j) of poses gives a motion Ai X = X Bi with Ai = inv(A_j) A_i, Bi = B_j inv(B_i);
    the rotation is (M^T M)^(-1/2) M^T with M = sum beta alpha^T (alpha, beta: the motions'
    rotation logarithms), the translation the least squares of (R_Ai - I) t = R t_Bi - t_Ai."""
    from scipy.spatial.transform import Rotation

    motions = []
    for i in range(len(A)):
        for j in range(i + 1, len(A)):
            motions.append((np.linalg.inv(A[j]) @ A[i], B[j] @ np.linalg.inv(B[i])))
    M = np.zeros((3, 3))
    for Ai, Bi in motions:
        alpha = Rotation.from_matrix(Ai[:3, :3]).as_rotvec()
        beta = Rotation.from_matrix(Bi[:3, :3]).as_rotvec()
        M += np.outer(beta, alpha)
    w, V = np.linalg.eigh(M.T @ M)
    R = V @ np.diag(w ** -0.5) @ V.T @ M.T
    C = np.vstack([Ai[:3, :3] - np.eye(3) for Ai, _ in motions])
    d = np.concatenate([R @ Bi[:3, 3] - Ai[:3, 3] for Ai, Bi in motions])
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, np.linalg.lstsq(C, d, rcond=None)[0]
    return X


def test_park_martin_solver_finds_the_truth_of_exact_pairs(poses):
    """The reference itself, before it judges the solver: exact pairs give X_TRUE."""
    dt, da = pose_difference(park_martin_x(poses, pairs(poses)), X_TRUE)
    assert dt < 1e-6 and da < 1e-6


def test_an_independent_published_solver_agrees_on_clean_pairs(poses):
    """The cross-check every install runs (OpenCV 5.0 has no calibrateHandEye): the solver's
    X against Park & Martin's on the same slightly noisy pairs, and both against the truth
    within what that noise allows (0.005 mm, 0.002 deg per axis)."""
    B = pairs(poses, noise_mm=0.005, noise_deg=0.002)
    r = solve_ax_yb(poses, B, cross_check=False)
    ref = park_martin_x(poses, B)
    dt, da = pose_difference(r.flange_T_camera_mm, ref)
    assert dt < 0.1 and da < 0.01, (dt, da)
    for X in (r.flange_T_camera_mm, ref):
        dt, da = pose_difference(X, X_TRUE)
        assert dt < 0.1 and da < 0.01, (dt, da)
    # a wrong solver would not pass: X off by 0.5 mm along x is told apart
    dt, _ = pose_difference(r.flange_T_camera_mm @ transform_from_x([0.5, 0, 0, 0, 0, 0]), ref)
    assert dt > 0.4


def test_without_opencv_solvers_the_cross_check_says_it_was_skipped(poses, monkeypatch):
    monkeypatch.delattr(cv2, "calibrateHandEye", raising=False)
    monkeypatch.delattr(cv2, "calibrateRobotWorldHandEye", raising=False)
    r = solve_ax_yb(poses, pairs(poses))
    assert r.cross_check == {}
    assert "skipped calibrateRobotWorldHandEye" in r.cross_check_note
    assert "skipped calibrateHandEye" in r.cross_check_note
    assert any("cross-check: skipped" in s for s in r.summary_lines())


def test_planned_poses_keep_the_target_in_view_and_vary(poses):
    # Where the planned cameras (as the rig believes) see the target.
    target = start_flange() @ NOMINAL_X @ np.array([0, 0, 600.0, 1])
    for A in poses:
        p = invert_transform(A @ NOMINAL_X) @ target
        off_deg = np.degrees(np.arctan2(np.hypot(p[0], p[1]), p[2]))
        assert 530 < p[2] < 670 and off_deg < 4.5
    tilts = [np.degrees(np.arccos(np.clip((A @ NOMINAL_X)[:3, 2] @ (start_flange() @ NOMINAL_X)[:3, 2], -1, 1)))
             for A in poses[1:]]
    assert min(tilts) > 5 and max(tilts) < 30
    check_motion(poses)  # not degenerate


def test_the_planner_skips_what_the_envelope_or_the_robot_refuses():
    F0 = start_flange()
    p0 = F0[:3, 3]
    A, notes = plan_poses(F0, NOMINAL_X, 600.0, n_poses=8, envelope_min_mm=p0 - 1000, envelope_max_mm=p0 + [1000, 1000, 0])
    assert all(a[2, 3] <= p0[2] + 1e-9 for a in A)
    assert any("leaves the workspace envelope" in n for n in notes)
    refuse_x = lambda a, b: "joint limit" if b[0, 3] > p0[0] else None  # noqa: E731
    A, notes = plan_poses(F0, NOMINAL_X, 600.0, n_poses=6, check=refuse_x)
    assert all(a[0, 3] <= p0[0] + 1e-9 for a in A) and any("joint limit: skipped" in n for n in notes)


def test_a_real_cell_plans_with_the_products_puma_model():
    # issue 30: the check lives in the product (calibration, with geometry.puma), not the
    # twin. The Puma 762's home flange (sim_robot's start: 786, 190, -296 mm, roll 180 deg,
    # geometry/puma.py) moved 20 mm sideways is a fine move; 3 m away is out of its reach
    # (the 762's arm is 1.25 m); the wrist straightened to q5 = 2 deg is a singularity.
    from humanpt.geometry.puma import HOME_JOINTS_DEG, PumaKinematics, RobotModelConfig

    home = transform_from_x(np.array([786.0, 190.0, -296.0, 0.0, 0.0, 180.0]))
    check = puma_move_check((0.0,) * 6)
    assert check(home, home @ transform_from_x(np.array([0.0, 20.0, 0.0, 0, 0, 0]))) is None
    far = transform_from_x(np.array([3000.0, 190.0, -296.0, 0.0, 0.0, 180.0]))
    assert check(far, home).startswith("unreachable")  # (from far: its first IK fails)
    q = np.radians(np.array(HOME_JOINTS_DEG, dtype=float))
    q[4] = np.radians(2.0)
    straight = PumaKinematics(RobotModelConfig()).forward(q)
    assert "wrist singularity" in check(home, straight)
    # the base elsewhere in the world: the same move, shifted with it, is still fine
    world_T_base = transform_from_x(np.array([1000.0, 0, 0, 0, 0, 0]))
    moved = puma_move_check((1000.0, 0, 0, 0, 0, 0))
    assert moved(world_T_base @ home, world_T_base @ home @ transform_from_x(np.array([0.0, 20.0, 0, 0, 0, 0]))) is None
    assert moved(far, home).startswith("unreachable")


def test_apply_to_rig_sets_the_hand_eye_and_its_calibration(poses):
    r = solve_ax_yb(poses, pairs(poses, noise_mm=0.02, noise_deg=0.01), cross_check=False)
    rig = apply_to_rig(Rig(), r, "2026-11-23T15:00:00Z")
    assert np.allclose(rig.hand_eye.flange_T_camera_mm(), r.flange_T_camera_mm, atol=1e-9)
    cal = rig.hand_eye.calibration
    assert cal.method == "ax=yb" and cal.date == "2026-11-23T15:00:00Z"
    assert 0 < cal.sigma["flange_T_camera_x"] == pytest.approx(float(r.flange_T_camera_sigma.max()), abs=1e-6)
    assert "12 poses" in cal.note
    assert rig.psvs == Rig().psvs and rig.tip == Rig().tip  # nothing else changed


# --------------------------------------------------------------------------- the collector

def _drive(c: PoseCollector, script) -> list:
    """Feed (t_s, kind, payload) in order, polling after each; returns the commands."""
    cmds = [c.start(0)]
    for t_s, kind, payload in script:
        t = round(t_s * 1e9)
        if kind == "robot":
            c.on_robot_state(t, payload)
        elif kind == "meas":
            c.on_measurement(t, payload)
        elif kind == "event":
            c.on_controller_event(t, *payload)
        cmd = c.poll(t)
        if cmd is not None:
            cmds.append(cmd)
    return cmds


def test_the_collector_moves_waits_measures_and_skips(poses):
    P = poses[:3]
    c = PoseCollector(P, np.eye(4), CollectorSettings(move_timeout_s=2.0, settle_s=0.2, average_s=0.5,
                                                      min_measurements=5))
    B = pairs(P)
    script = [(0.5, "event", ("playback_done", ""))]
    # pose 0: still, measured 10 times
    script += [(0.7 + 0.05 * k, kind, val) for k in range(12)
               for kind, val in (("robot", P[0]), ("meas", B[0]))]
    # pose 1: never arrives (timeout), pose 2: arrives but the target is not seen
    script += [(1.4 + 0.1 * k, "robot", P[0]) for k in range(25)]
    script += [(4.0, "event", ("playback_done", ""))]
    script += [(4.3 + 0.05 * k, kind, val) for k in range(12) for kind, val in (("robot", P[2]), ("meas", None))]
    cmds = _drive(c, script)
    assert [v for v, _ in cmds] == ["playback", "playback", "playback", "hold"]
    assert c.done and not c.aborted
    assert [s.index for s in c.samples] == [0]
    assert np.allclose(c.samples[0].camera_T_target_mm, B[0]) and c.samples[0].measurements >= 5
    assert "pose 1: skipped, not reached in 2 s" in c.notes[0]
    assert "pose 2: skipped, target seen in 0 of" in c.notes[1]


def test_a_console_stop_ends_the_collection(poses):
    c = PoseCollector(poses[:3], np.eye(4))
    cmds = _drive(c, [(0.3, "event", ("command", "hold (stop on current location)"))])
    assert c.done and "stopped by a console command" in c.aborted and cmds[-1][0] == "hold"
    # the playback sent for each pose puts the flange on the planned pose through the tool
    c2 = PoseCollector(poses[:3], transform_from_x([0, 0, 200, 0, 0, 0]))
    verb, args = c2.start(0)
    tool = transform_from_x(np.array(args["points"][0]))
    assert verb == "playback" and pose_difference(tool @ invert_transform(transform_from_x([0, 0, 200, 0, 0, 0])),
                                                  poses[0])[0] < 1e-4


def test_a_robot_that_follows_no_pose_ends_the_collection(poses):
    c = PoseCollector(poses[:6], np.eye(4), CollectorSettings(move_timeout_s=1.0, max_missed_in_a_row=3))
    cmds = _drive(c, [(0.1 * k, "robot", poses[0]) for k in range(60)])
    assert c.done and not c.aborted and c.samples == []
    assert [v for v, _ in cmds] == ["playback", "playback", "playback", "hold"]
    assert "3 poses in a row not reached" in c.notes[-1]
