"""The pivot fit's tip and its 1-sigma held to the twin's truth (issue 32.4).

On the realistic world the tip stage reported a 1-sigma of 0.066-0.074 mm while its tip was
0.17-0.43 mm off the truth.  Most of that was a bias of the measured TOB frame that the tip
takes up and that cancels while teaching (the same camera-to-target pose); the rest, the
fit's own error (0.05-0.19 mm where the tip lands in the world), came from a rotation error
that follows the tilt on a +-20 deg cone and from poses whose errors were alike for
neighbours, which the residuals' formula counts as independent.  The stage now pivots
+-30 deg with poses 1.5 deg apart, and the fit's sigma is also taken by a delete-a-block
jackknife over the poses in their order
(:func:`humanpt.geometry.calibration.pivot_block_jackknife_sigma`).

The first two tests are pure (the old +-20 deg pivot's 300 poses, errors drawn here); the
last runs the tip stage on the twin once per seed (module-scoped) on a world with every
noise source of ``realistic`` and the needle off its design, but none of the rig's model
errors (those the pipeline's own calibrations remove first), and holds the fit to the
truth it can see (the true tip in the measured TOB frame) and the tip point to its
acceptance"""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.geometry.calibration import calibrate_tip_pivot, pivot_block_jackknife_sigma
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import matrix_from_rotvec
from humanpt.operator import OperatorConfig
from humanpt.operator.scenario import NEEDLE_MM, Trajectory
from humanpt.twin.cal_tip import ACCEPT_MM, PIVOT_SAMPLES, pivot_scenario
from humanpt.twin.tip_bias import diagnose, pivot_run
from humanpt.twin.worlds import World

TRUE_TIP = np.asarray(NEEDLE_MM, dtype=float) + [0.3, -0.2, 0.4]  # the world source "tip"
# realistic's sources that add noise, not a model error of the rig (no hand-eye, optics,
# stamp offset: calibrated before the tip; no kinematics: the stage pivots on the stand-in).
NOISE_WORLD = ("ideal+ghost+blooming+sensor_noise+fixed_pattern+falloff+motion_blur+stamp_jitter+frame_drops"
               "+robot_lag+tip+tremor")


def _pivot_poses(n: int = 300) -> np.ndarray:
    """(n, 4, 4) mm: the twin operator's +-20 deg pivot (cal_tip.pivot_scenario's default,
    the tip stage's before issue 32.4), evenly in time."""
    traj = Trajectory(OperatorConfig(scenario_text=pivot_scenario(TRUE_TIP)).build_scenario())
    ts = np.linspace(1.5, traj.duration_s, n)  # after the dwell
    return np.array([traj.pose(t)[0] for t in ts])


def _ar1(rng, n: int, rho: float, sd: float) -> np.ndarray:
    """(n, 3) errors, each coordinate first-order autoregressive: correlation rho between
    neighbours, standard deviation sd."""
    e = np.zeros((n, 3))
    e[0] = rng.normal(0.0, sd, 3)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + np.sqrt(1.0 - rho**2) * rng.normal(0.0, sd, 3)
    return e


def _draws(rho: float, repeats: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Over ``repeats`` draws of errors with neighbour correlation ``rho`` (0.25 deg about the
    lateral axes, 0.3 mm) on the operator's pivot: the tip's errors (repeats, 3) mm, the
    sigmas the residuals' formula alone gives (what the fit reported before) and the fit's
    sigmas."""
    poses = _pivot_poses()
    n = len(poses)
    rng = np.random.default_rng(7)
    errs, ols, fit = [], [], []
    for _ in range(repeats):
        noisy = poses.copy()
        rot = np.radians(_ar1(rng, n, rho, 0.25)) * [1.0, 1.0, 0.3]
        noisy[:, :3, 3] += _ar1(rng, n, rho, 0.3)
        noisy[:, :3, :3] = noisy[:, :3, :3] @ np.array([matrix_from_rotvec(r) for r in rot])
        cal = calibrate_tip_pivot(noisy)
        errs.append(cal.tob_t_tip_mm - TRUE_TIP)
        a = np.zeros((n, 3, 6))  # s^2 (A^T A)^-1 of [R_i  -I]
        a[:, :, :3] = noisy[:, :3, :3]
        a[:, :, 3:] = -np.eye(3)
        a = a.reshape(3 * n, 6)
        s2 = np.sum(cal.residuals_mm**2) / (3 * n - 6)
        ols.append(np.sqrt(np.diag(s2 * np.linalg.inv(a.T @ a)))[:3])
        fit.append(cal.tob_t_tip_sigma_mm)
    return np.array(errs), np.array(ols), np.array(fit)


def test_correlated_errors_the_sigma_covers_the_tip():
    """Neighbouring samples' errors alike (rho 0.9, as the filtered poses' are): the tip
    within 2 sigmas about 95 % of the time is what a sigma promises; with the residuals'
    formula it is about 30 % (0.28-0.37 over 200 draws; its sigma 3-5x too small), with the
    fit's jackknife sigma 0.78-0.92 (a block jackknife has 9 degrees of freedom, and blocks of
    30 samples only just hold the errors' correlation: its RMS 0.72-0.89 of the true scatter)."""
    errs, ols, fit = _draws(0.9, 60)
    assert np.all(np.mean(np.abs(errs) < 2.0 * ols, axis=0) < 0.6), ols
    assert np.all(np.mean(np.abs(errs) < 2.0 * fit, axis=0) >= 0.75), fit
    spread = np.std(errs, axis=0)
    assert np.all(np.sqrt(np.mean(ols**2, axis=0)) < 0.5 * spread)
    assert np.all(np.sqrt(np.mean(fit**2, axis=0)) > 0.65 * spread), (fit, spread)  # 0.72-0.89


def test_independent_errors_the_sigma_stays_near_the_residuals_one():
    """Independent errors: the fit's sigma is not inflated for nothing: its RMS over the
    draws within 0.85-1.4 of the tips' true scatter (measured 1.00-1.15: the block jackknife
    is a little conservative where blocks differ in leverage; the residuals' formula 0.82-1.05)."""
    errs, ols, fit = _draws(0.0, 60)
    spread = np.std(errs, axis=0)
    r_ols = np.sqrt(np.mean(ols**2, axis=0)) / spread
    r_fit = np.sqrt(np.mean(fit**2, axis=0)) / spread
    assert np.all((r_ols > 0.75) & (r_ols < 1.25)), (r_ols, r_fit)
    assert np.all((r_fit > 0.85) & (r_fit < 1.4)), r_fit
    assert np.all(fit >= ols * (1.0 - 1e-9))  # never below the residuals' formula
    noisy = _pivot_poses(59)
    assert pivot_block_jackknife_sigma(noisy) is None  # fewer than 6 per block: the residuals' only


@pytest.fixture(scope="module", params=[0, 1], ids=["seed0", "seed1"])
def tip_stage(request):
    """The tip stage on the twin (the nominal rig, the noise world), once per seed, with the
    fitted poses and the truth at their stamps (humanpt.twin.tip_bias)."""
    run = pivot_run(World.named(NOISE_WORLD), Rig(), seed=request.param)
    return run, diagnose(run)


@pytest.mark.twin
def test_the_tip_on_the_twin_is_within_its_sigma(tip_stage):
    """The fit's own error (the tip against the true tip in the measured TOB frame, whose
    mean bias against the truth the tip takes up: about 0.2 mm along the TOB's z on this
    world) within 3 reported sigmas; where the tip lands in the world within the
    stage's acceptance, and the stage's truth lines say so."""
    run, d = tip_stage
    res, truth = run["result"], run["truth"]
    np.testing.assert_allclose(res.tob_t_tip_mm, d["tip"], atol=1e-3)  # the controller's fit is the one diagnosed
    own = np.abs(d["off_measured_frame_tip"])
    assert np.all(own <= 3.0 * d["sigma_after"]), (own, d["sigma_after"])
    np.testing.assert_allclose(res.sigma_mm, np.max(d["sigma_after"]), rtol=1e-3)  # the rig gets this sigma
    assert res.sigma_mm < ACCEPT_MM, res  # and the tip is still worth having
    assert np.linalg.norm(d["tip_point_mm"]) <= ACCEPT_MM, d["tip_point_mm"]
    checks = {c.what: c for c in truth.checks}
    assert checks["tip point in the world off the truth"].met, list(truth)
    np.testing.assert_allclose(checks["tip point in the world off the truth"].value,
                               np.linalg.norm(d["tip_point_mm"]), atol=0.02)  # the mean over the run vs at the poses
    assert d["n"] == PIVOT_SAMPLES and np.all(np.isfinite(d["frame_bias_mm"]))
