"""The arm's kinematic calibration (humanpt.calibration.arm, issue 32.4) on synthetic data.

The data come from :class:`humanpt.geometry.puma.TrueArm` with the realistic world's arm
errors (twin/worlds.py, the ``kinematics`` source: joint offsets up to 0.03 deg, lengths up
to 0.3 mm) at poses planned as the twin plans them (humanpt.calibration.handeye.plan_poses,
the Puma's own move check); the reported flanges are the nominal model's (what a Puma
reports), the measurements where the true arm puts the camera.  Expected values: the
errors put in; the three the module says no camera on the flange can see (joint 1's and
joint 6's offsets, d6) held at 0 and taken by the target's pose and the hand-eye (X becomes
Rz(q6 offset) Tz(d6) X_true, by the DH algebra of the last link)."""

from __future__ import annotations

import dataclasses
import tomllib

import numpy as np
import pytest

from humanpt.calibration.arm import (
    PARAMETERS,
    UNOBSERVABLE,
    ArmCalibrationError,
    apply_to_rig,
    correct_path,
    simulate_measurements,
    solve_arm,
    true_world_T_flange,
)
from humanpt.calibration.handeye import plan_poses, pose_difference, puma_move_check
from humanpt.geometry.puma import (
    HOME_JOINTS_DEG,
    PumaKinematics,
    TrueArm,
    follow,
    perturbed_geometry,
)
from humanpt.geometry.rig import DEFAULT_FLANGE_T_CAMERA_MM, Rig
from humanpt.geometry.transforms import (
    make_transform,
    matrix_from_rotvec,
    transform_from_x,
    x_from_transform,
)
from humanpt.runtime.rigfile import rig_from_table, rig_to_table, rig_to_toml
from humanpt.twin.worlds import ERROR_SOURCES

KIN = PumaKinematics()
HOME = np.radians(HOME_JOINTS_DEG)
_REAL = next(s for s in ERROR_SOURCES if s.name == "kinematics").overrides["sim_robot"]
OFFSETS_DEG = np.array(_REAL["joint_offsets_deg"])
LENGTHS_MM = np.array(_REAL["link_length_errors_mm"])
TRUE = TrueArm(perturbed_geometry(KIN.geometry, LENGTHS_MM), np.radians(OFFSETS_DEG))
W = transform_from_x(np.array([400.0, -200.0, 50.0, 20.0, 0.0, 0.0]))  # the base somewhere in the world
X = DEFAULT_FLANGE_T_CAMERA_MM
DZ = 300.0
# The PSVS's noise on a target averaged for 1 s while still (1-sigma per pose): the twin's
# hand-eye stage measures 0.01-0.03 mm across the image, about 3x that in depth, 0.01 deg.
NOISE_MM, NOISE_DEPTH_MM, NOISE_DEG = 0.02, 0.06, 0.01


def _poses(n: int, seed: int = 0) -> np.ndarray:
    """Joints (n', 6) of the poses the twin's arm stage plans (its wider tilts) from home."""
    F0 = W @ KIN.forward(HOME)
    poses, _ = plan_poses(F0, X, DZ, n_poses=n, tilt_deg=(12.0, 25.0), roll_deg=30.0, distance_mm=80.0,
                          check=puma_move_check(x_from_transform(W)), seed=seed)
    return follow(KIN, np.linalg.inv(W) @ poses, HOME)


def _target() -> np.ndarray:
    return W @ KIN.forward(HOME) @ X @ make_transform(matrix_from_rotvec([np.pi, 0, 0]), [0.0, 0.0, DZ])


@pytest.fixture(scope="module")
def data():
    q = _poses(16)
    A, B = simulate_measurements(TRUE, q, W, X, _target(), KIN)
    return q, A, B


def _noisy(B: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.array([b @ make_transform(matrix_from_rotvec(rng.normal(0.0, np.radians(NOISE_DEG), 3)),
                                        rng.normal(0.0, [NOISE_MM, NOISE_MM, NOISE_DEPTH_MM])) for b in B])


def test_noise_free_data_give_the_arm_exactly(data):
    q, A, B = data
    r = solve_arm(A, B, W, q_ref_rad=HOME)
    assert r.n_poses == len(q) >= 14
    assert set(r.fixed) == set(UNOBSERVABLE)
    for p, (v, _) in r.values().items():
        i = PARAMETERS.index(p)
        true = np.r_[OFFSETS_DEG, LENGTHS_MM][i]
        assert v == pytest.approx(0.0 if p in UNOBSERVABLE else true, abs=1e-6), p
    # The hand-eye takes d6 and joint 6's offset (a shift along and a turn about the flange's z).
    expect = make_transform(matrix_from_rotvec([0, 0, np.radians(OFFSETS_DEG[5])]), [0, 0, LENGTHS_MM[4]]) @ X
    dt, da = pose_difference(r.flange_T_camera_mm, expect)
    assert dt < 1e-6 and da < 1e-6
    assert r.residual_mm.max() < 1e-6
    # The nominal arm cannot fit these data: about 0.15-0.2 mm RMS per pose (the hand-eye alone).
    assert np.sqrt(np.mean(r.nominal_residual_mm ** 2)) > 0.1


def test_noisy_data_give_the_arm_within_its_sigma_and_predict_it(data):
    """At the PSVS's noise each identified error is within 3 of its 1-sigma of the truth,
    and the calibrated arm (with its hand-eye and target pose) predicts what the camera
    measures at 16 other poses (gauge-free: no frame choice enters) 3x better than the
    nominal arm with the hand-eye fitted to it."""
    q, A, B = data
    Bn = _noisy(B, 1)
    r = solve_arm(A, Bn, W, q_ref_rad=HOME)
    true = dict(zip(PARAMETERS, np.r_[OFFSETS_DEG, LENGTHS_MM], strict=True))
    for p, (v, s) in r.values().items():
        if p in r.fixed:
            continue
        assert 0 < s < 0.2, (p, s)
        assert abs(v - true[p]) <= 3 * s, (p, v, s, true[p])
    q2 = _poses(16, seed=5)
    _, B2 = simulate_measurements(TRUE, q2, W, X, _target(), KIN)
    model = r.true_arm()
    pred_cal = np.array([np.linalg.inv(W @ model.forward(qi) @ r.flange_T_camera_mm) @ r.world_T_target_mm
                         for qi in q2])
    from humanpt.calibration.handeye import solve_ax_yb

    he = solve_ax_yb(A, Bn, cross_check=False)
    pred_nom = np.array([np.linalg.inv(W @ KIN.forward(qi) @ he.flange_T_camera_mm) @ he.world_T_target_mm
                         for qi in q2])

    def rms(P):
        return float(np.sqrt(np.mean(np.sum((P[:, :3, 3] - B2[:, :3, 3]) ** 2, axis=1))))

    assert rms(pred_cal) < rms(pred_nom) / 3, (rms(pred_cal), rms(pred_nom))


def test_an_error_the_poses_do_not_move_is_held_and_named():
    """Poses that only turn the wrist (joints 1-3 still) cannot tell the upper arm's
    lengths or joints 2 and 3's offsets from the target's pose: held at 0, each with its
    sigma; the wrist's offsets are still found."""
    rng = np.random.default_rng(3)
    q = HOME + np.c_[np.zeros((12, 3)), np.radians(rng.uniform(-20, 20, (12, 3)))]
    A, B = simulate_measurements(TRUE, q, W, X, _target(), KIN)
    r = solve_arm(A, B, W, q_ref_rad=HOME)
    for p in ("q2_offset_deg", "q3_offset_deg", "d2_mm", "a2_mm"):
        assert p in r.fixed and "not determined by these poses" in r.fixed[p], (p, r.fixed)
    assert r.values()["q5_offset_deg"][0] == pytest.approx(OFFSETS_DEG[4], abs=1e-6)


@pytest.mark.parametrize("bad, message", [
    (lambda A, B: (A[:5], B[:5]), "too few poses: 5"),
    (lambda A, B: (A, B[:-1]), "16 robot poses but 15 target measurements"),
    (lambda A, B: (np.where(np.arange(16)[:, None, None] == 3, np.nan, A), B), "world_T_flange: contains NaN"),
])
def test_bad_input_is_one_clear_line(data, bad, message):
    _, A, B = data
    with pytest.raises(ArmCalibrationError) as e:
        solve_arm(*bad(A, B), W, q_ref_rad=HOME)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_a_taught_path_is_moved_to_where_the_calibrated_arm_had_the_flange():
    """The pipeline placed a fixed point with the reported (nominal) flange: ~0.5 mm off;
    corrected with the true arm it is the point itself, at every robot pose."""
    q = HOME + np.radians(np.c_[np.linspace(0, 8, 30), np.linspace(0, -5, 30), np.zeros((30, 4))])
    p = transform_from_x(np.array([900.0, 0.0, -100.0, 0.0, 180.0, 0.0]))
    stamps = np.arange(30) * 28_000_000
    reported = np.array([W @ KIN.forward(qi) for qi in q])
    seen = np.array([np.linalg.inv(W @ TRUE.forward(qi) @ X) @ W @ p for qi in q])  # the camera's view of it
    taught = x_from_transform(np.array([R @ X @ m for R, m in zip(reported, seen, strict=True)]))
    before = np.linalg.norm(transform_from_x(taught)[:, :3, 3] - (W @ p)[:3, 3], axis=1)
    assert before.min() > 0.3
    fixed = correct_path(taught, stamps + 3_000_000, stamps, reported, TRUE, W, KIN, HOME)
    np.testing.assert_allclose(transform_from_x(fixed), np.broadcast_to(W @ p, (30, 4, 4)), atol=1e-6)
    np.testing.assert_allclose(true_world_T_flange(TRUE, reported, W, KIN, HOME),
                               [W @ TRUE.forward(qi) for qi in q], atol=1e-9)


def test_the_rig_stores_the_arm_with_its_sigma_and_old_rigs_have_none(data):
    _, A, B = data
    r = solve_arm(A, _noisy(B, 2), W, q_ref_rad=HOME)
    rig = apply_to_rig(Rig(), r, "2026-11-27T15:00:00Z")
    back = rig_from_table(tomllib.loads(rig_to_toml(rig)))
    assert back.arm == rig.arm and back.arm.present and back.arm.model == "puma762"
    assert back.arm.calibration.sigma["link_length_errors_mm"] == pytest.approx(
        r.link_length_errors_sigma_mm.max(), abs=1e-6)
    assert back.hand_eye.calibration.method == "arm+ax=yb"
    np.testing.assert_allclose(back.arm.true_arm().forward(HOME), r.true_arm().forward(HOME), atol=1e-6)
    old = Rig()
    assert "arm" not in rig_to_table(old) and not old.arm.present and old.arm.true_arm() is None
    assert rig_from_table(rig_to_table(old)) == old
    assert "arm" in rig_to_table(dataclasses.replace(rig))


def test_the_cli_solves_collected_pairs_into_the_rig(data, tmp_path, capsys, cli_main):
    """`humanpt calibrate arm --pairs FILE --world-T-base ...`: the rig gets [arm] and the
    hand-eye; a missing mounting or too few pairs: one line, exit 2, the rig untouched."""
    from humanpt.console.calibration import save_pairs
    from humanpt.runtime.rigfile import load_rig, write_rig

    _, A, B = data
    pairs = tmp_path / "pairs.json"
    save_pairs(pairs, A, B)
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    before = rig.read_bytes()
    wtb = ",".join(f"{v:.9f}" for v in x_from_transform(W))
    assert cli_main(["calibrate", "arm", "--pairs", str(pairs), "--rig", str(rig)]) == 2
    assert "--pairs needs --world-T-base" in capsys.readouterr().err
    few = tmp_path / "few.json"
    save_pairs(few, A[:4], B[:4])
    assert cli_main(["calibrate", "arm", "--pairs", str(few), "--world-T-base", wtb, "--rig", str(rig)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("humanpt calibrate arm: too few poses: 4; the arm's calibration needs at least 8 (8 arm errors, "
                   "the hand-eye and the target's pose: 20 unknowns)")
    assert rig.read_bytes() == before
    assert cli_main(["calibrate", "arm", "--pairs", str(pairs), "--world-T-base", wtb, "--rig", str(rig)]) == 0
    out = capsys.readouterr().out
    assert "wrote [arm] and [hand_eye]" in out and "q1_offset_deg  held at 0" in out
    arm = load_rig(rig).arm
    np.testing.assert_allclose(arm.joint_offsets_deg[1:5], OFFSETS_DEG[1:5], atol=1e-5)
    np.testing.assert_allclose(arm.link_length_errors_mm[:4], LENGTHS_MM[:4], atol=1e-4)
