"""Calibration of the driver attached to the TOB: Section 4.1, eq. (10)-(13), plus a
least-squares pivot calibration.

The driver's endpoint P is fixed in the TOB frame (``tob_t_tip``, eq. (9)). The operator
keeps P on a fixed point P' and rotates the TOB while its poses are recorded.

* The paper's method needs P' measured beforehand in the world frame (eq. (10), (11):
  the mean of PSVS measurements from N robot poses), then maps it into the TOB frame for
  every recorded pose (eq. (12)) and averages (eq. (13)).
* The pivot calibration needs no P': every pose i gives three equations
  ``world_R_tob,i tob_t_tip + world_t_tob,i = world_p_pivot``, and the 3N equations are
  solved together for the tip offset and the pivot point (6 unknowns) by least squares.
  It needs rotations about at least two different axes.

Units: mm; transforms are 4x4 ``a_T_b`` stacks (N, 4, 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import GeometryError
from .transforms import check_rigid, compose, invert_transform, transform_points

__all__ = [
    "TipCalibration",
    "world_point_from_samples",
    "calibrate_tip_paper",
    "calibrate_tip_pivot",
    "pivot_block_jackknife_sigma",
]


@dataclass(frozen=True)
class TipCalibration:
    """Result of a driver-tip calibration (mm).

    ``tob_t_tip_mm`` (3,): the tip in the TOB frame (eq. (9)'s ``G t_P``).
    ``world_p_pivot_mm`` (3,): the fixed point P' (given, or estimated by the pivot method).
    ``residuals_mm`` (N, 3): per sample, ``world_T_tob,i @ tip - pivot`` in the world frame.
    ``residual_rms_mm``: RMS of the residual lengths.
    ``tob_t_tip_sigma_mm``, ``world_p_pivot_sigma_mm`` (3,): predicted standard deviations
    of the estimates (from the residual scatter; zeros for the given P' of the paper's
    method). ``method``: ``"paper"`` or ``"pivot"``.
    """

    tob_t_tip_mm: np.ndarray
    world_p_pivot_mm: np.ndarray
    residuals_mm: np.ndarray
    residual_rms_mm: float
    tob_t_tip_sigma_mm: np.ndarray
    world_p_pivot_sigma_mm: np.ndarray
    n_samples: int
    method: str


def _stack(name: str, transforms, min_count: int = 1) -> np.ndarray:
    t = np.asarray(transforms, dtype=float)
    if t.ndim == 2:
        t = t[None]
    if t.ndim != 3 or t.shape[1:] != (4, 4):
        raise ValueError(f"{name} must have shape (N, 4, 4), got {t.shape}")
    if t.shape[0] < min_count:
        raise GeometryError(f"{name}: need at least {min_count} samples, got {t.shape[0]}")
    check_rigid(t, tol=1e-6, name=name)
    return t


def world_point_from_samples(
    world_T_flange: np.ndarray, flange_T_camera: np.ndarray, camera_p_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (10), (11): P' measured by the PSVS (eq. (4)) from N robot poses.

    ``world_T_flange`` (N, 4, 4), ``flange_T_camera`` (4, 4), ``camera_p_mm`` (N, 3) ->
    (``world_p_mm`` (3,), the mean; ``per_sample_mm`` (N, 3), eq. (10) for each pose)."""
    w_T_f = _stack("world_T_flange", world_T_flange)
    check_rigid(flange_T_camera, name="flange_T_camera")
    cam_p = np.asarray(camera_p_mm, dtype=float).reshape(-1, 3)
    if cam_p.shape[0] != w_T_f.shape[0]:
        raise ValueError(
            f"{w_T_f.shape[0]} flange poses but {cam_p.shape[0]} camera points; need one each"
        )
    per_sample = transform_points(compose(w_T_f, flange_T_camera), cam_p)
    return per_sample.mean(axis=0), per_sample


def _finish(method, tip, pivot, world_T_tob, tip_sigma, pivot_sigma) -> TipCalibration:
    residuals = transform_points(world_T_tob, tip) - pivot
    rms = float(np.sqrt(np.mean(np.sum(residuals**2, axis=-1))))
    return TipCalibration(
        tob_t_tip_mm=tip,
        world_p_pivot_mm=pivot,
        residuals_mm=residuals,
        residual_rms_mm=rms,
        tob_t_tip_sigma_mm=tip_sigma,
        world_p_pivot_sigma_mm=pivot_sigma,
        n_samples=int(world_T_tob.shape[0]),
        method=method,
    )


def calibrate_tip_paper(
    world_T_flange: np.ndarray,
    flange_T_camera: np.ndarray,
    camera_T_tob: np.ndarray,
    world_p_pivot_mm: np.ndarray,
) -> TipCalibration:
    """Eq. (12), (13): the paper's driver calibration with a known P'.

    For each recorded pose i (``world_T_flange`` and ``camera_T_tob``, (N, 4, 4)),
    ``tob_t_tip,i = camera_T_tob,i^-1 flange_T_camera^-1 world_T_flange,i^-1 world_p_P'``
    (eq. (12)); the result is their mean (eq. (13)). ``world_p_pivot_mm`` (3,) is P' from
    :func:`world_point_from_samples`. The tip's sigma is the standard error of the mean.
    """
    w_T_f = _stack("world_T_flange", world_T_flange)
    c_T_t = _stack("camera_T_tob", camera_T_tob)
    if w_T_f.shape[0] != c_T_t.shape[0]:
        raise ValueError(
            f"{w_T_f.shape[0]} flange poses but {c_T_t.shape[0]} TOB poses; need one each"
        )
    check_rigid(flange_T_camera, name="flange_T_camera")
    pivot = np.asarray(world_p_pivot_mm, dtype=float).reshape(3)
    tob_T_world = compose(
        invert_transform(c_T_t), invert_transform(flange_T_camera), invert_transform(w_T_f)
    )
    per_sample = transform_points(tob_T_world, pivot)  # eq. (12)
    tip = per_sample.mean(axis=0)  # eq. (13)
    n = per_sample.shape[0]
    sigma = per_sample.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.full(3, np.inf)
    world_T_tob = compose(w_T_f, flange_T_camera, c_T_t)
    return _finish("paper", tip, pivot, world_T_tob, sigma, np.zeros(3))


# The pivot fit's delete-a-block jackknife: this many contiguous blocks of the samples (in
# the order they were taken), when every block has at least JACKKNIFE_MIN_BLOCK samples.
JACKKNIFE_BLOCKS = 10
JACKKNIFE_MIN_BLOCK = 6


def _pivot_solve(w_T_t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A (3N, 6), b (3N,), solution (6,)) of ``[R_i  -I] [tob_t_tip; world_p_pivot] = -t_i``."""
    n = w_T_t.shape[0]
    a_mat = np.zeros((n, 3, 6))
    a_mat[:, :, :3] = w_T_t[:, :3, :3]
    a_mat[:, :, 3:] = -np.eye(3)
    a_mat = a_mat.reshape(3 * n, 6)
    b_vec = -w_T_t[:, :3, 3].reshape(3 * n)
    solution, *_ = np.linalg.lstsq(a_mat, b_vec, rcond=None)
    return a_mat, b_vec, solution


def pivot_block_jackknife_sigma(world_T_tob: np.ndarray, blocks: int = JACKKNIFE_BLOCKS) -> np.ndarray | None:
    """The pivot fit's standard deviations (6,: tip, pivot point, mm) by a delete-a-block
    jackknife over ``blocks`` contiguous blocks of the samples, in the order they were taken:
    ``sqrt((g - 1) / g * sum_j (x_(j) - mean x_(.))^2)``.  Unlike the residuals' formula it
    holds when the errors of neighbouring samples are alike (a filtered pose, the hand's slow
    tremor, an error that changes with the pose along a smooth motion).  None when a block
    would have fewer than :data:`JACKKNIFE_MIN_BLOCK` samples."""
    w_T_t = np.asarray(world_T_tob, dtype=float)
    n = w_T_t.shape[0]
    if blocks < 2 or n < blocks * JACKKNIFE_MIN_BLOCK:
        return None
    parts = np.array_split(np.arange(n), blocks)
    est = np.array([_pivot_solve(np.delete(w_T_t, part, axis=0))[2] for part in parts])
    return np.sqrt((blocks - 1) / blocks * np.sum((est - est.mean(axis=0)) ** 2, axis=0))


def calibrate_tip_pivot(world_T_tob: np.ndarray, min_condition: float = 1e-6) -> TipCalibration:
    """Least-squares pivot calibration: the tip offset and the fixed point together.

    ``world_T_tob`` (N, 4, 4), N >= 3 poses of the TOB while its tip rests on one point, in
    the order they were taken. Solves ``[R_i  -I] [tob_t_tip; world_p_pivot] = -t_i`` for all
    i. The predicted sigmas are the larger, per coordinate, of ``sqrt(diag(s^2 (A^T A)^-1))``
    with ``s^2 = RSS / (3N - 6)`` (right for independent errors) and a delete-a-block
    jackknife over the samples in their order (:func:`pivot_block_jackknife_sigma`: right
    when neighbouring samples' errors are alike, which the residuals' formula takes for
    independent information and so understates; N >= 60).

    Raises :class:`GeometryError` when the rotations do not determine the solution
    (fewer than 3 poses, or rotation about a single axis: smallest/largest singular value
    of A below ``min_condition``).
    """
    w_T_t = _stack("world_T_tob", world_T_tob, min_count=3)
    n = w_T_t.shape[0]
    a_mat, b_vec, solution = _pivot_solve(w_T_t)
    sv = np.linalg.svd(a_mat, compute_uv=False)
    if sv[-1] < min_condition * sv[0]:
        raise GeometryError(
            "pivot calibration is ill-posed: the TOB poses must rotate about at least two "
            f"different axes (singular value ratio {sv[-1] / sv[0]:.3g})"
        )
    tip, pivot = solution[:3], solution[3:]
    resid = a_mat @ solution - b_vec
    dof = 3 * n - 6
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.inv(a_mat.T @ a_mat)
    sigma = np.sqrt(np.diag(cov))
    jack = pivot_block_jackknife_sigma(w_T_t)
    if jack is not None:
        sigma = np.maximum(sigma, jack)
    return _finish("pivot", tip, pivot, w_T_t, sigma[:3], sigma[3:])
