"""Where the pivot fit's tip error comes from, against the twin's truth (issue 32.4).

``python -m humanpt.twin.tip_bias --rig RIG --seeds 0-4 [--world realistic]`` runs the tip
stage's pivot (:func:`humanpt.twin.cal_tip.pivot_scenario`, the controller's ``calibrate``)
per seed, keeps the poses the controller fitted and the filter's states, looks the true
TOB up at each one's stamp (the pipeline never does) and prints one row per seed:

* the tip, its error against the true tip and the fit's 1-sigma (the residuals' formula
  alone, as before, and the fit's own: with the block jackknife);
* the measured TOB frame's mean bias against the truth (``true^-1 @ measured``, averaged
  over the poses): a bias that is the same at every pose moves the fitted tip by
  ``E^-1 tip - tip`` and cancels when the tip is carried on measured poses again (taught
  points at the same camera-to-target pose); the tip's error against ``E^-1 tip`` is what
  the fit itself got wrong;
* where the calibrated tip lands in the world (the fitted pivot point against the true tip's
  mean position): what a taught point gets from this stage;
* the part of the fit's error the rotation error's tilt-dependent part makes (the rotation
  error regressed on the driver axis's direction, put on the true poses alone), and the
  neighbour correlation of the poses' errors.
"""

from __future__ import annotations

import argparse

import numpy as np

from humanpt.geometry.calibration import calibrate_tip_pivot
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import invert_transform, matrix_from_rotvec, rotvec_from_matrix

from .cal_tip import (
    PIVOT_SAMPLES,
    PIVOT_SPEED_DEG_S,
    PIVOT_SPREAD_DEG,
    PIVOT_TILT_DEG,
    calibrate_tip_on_twin,
)
from .worlds import World

__all__ = ["pivot_run", "diagnose"]


def pivot_run(world: World, rig: Rig | None, seed: int, samples: int = PIVOT_SAMPLES,
              spread_deg: float = PIVOT_SPREAD_DEG, tilt_deg: float = PIVOT_TILT_DEG,
              speed_deg_s: float = PIVOT_SPEED_DEG_S) -> dict:
    """The tip stage (:func:`humanpt.twin.cal_tip.calibrate_tip_on_twin`, ``rig`` None: the
    nominal one) keeping what the diagnosis needs: the fitted poses (N, 4, 4) mm in their
    order, the true TOB and tip at their stamps, the true tip (3,), the stage's result and
    truth lines."""
    keep: dict = {}
    res, report, truth = calibrate_tip_on_twin(world, Rig() if rig is None else rig, seed, samples,
                                               min_spread_deg=spread_deg, tilt_deg=tilt_deg,
                                               angular_speed_deg_s=speed_deg_s, keep=keep)
    return {**keep, "result": res, "report": report, "truth": truth}


def _ols_sigma(poses: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    n = len(poses)
    a = np.zeros((n, 3, 6))
    a[:, :, :3] = poses[:, :3, :3]
    a[:, :, 3:] = -np.eye(3)
    a = a.reshape(3 * n, 6)
    return np.sqrt(np.diag(np.sum(residuals**2) / (3 * n - 6) * np.linalg.inv(a.T @ a)))[:3]


def diagnose(run: dict) -> dict:
    """The figures of one :func:`pivot_run` (mm, deg)."""
    P, T, tip = run["fitted"], run["true_tob"], run["true_tip"]
    fit = calibrate_tip_pivot(P)
    E = np.array([invert_transform(t) @ m for t, m in zip(T, P, strict=True)])
    rv = np.array([rotvec_from_matrix(e[:3, :3]) for e in E])
    E_mean = np.eye(4)
    E_mean[:3, :3] = matrix_from_rotvec(rv.mean(axis=0))
    E_mean[:3, 3] = E[:, :3, 3].mean(axis=0)
    tip_in_measured = (invert_transform(E_mean) @ np.r_[tip, 1.0])[:3]
    # the rotation error's part that follows the driver axis's direction (quadratic), alone
    z = T[:, :3, 2]
    feats = np.c_[np.ones(len(z)), z[:, 0], z[:, 1], z[:, 0] ** 2, z[:, 1] ** 2, z[:, 0] * z[:, 1]]
    coef, *_ = np.linalg.lstsq(feats, rv, rcond=None)

    def on_truth(rot):
        out = T.copy()
        out[:, :3, :3] = T[:, :3, :3] @ np.array([matrix_from_rotvec(r) for r in rot])
        out[:, :3, 3] = T[:, :3, 3] + np.einsum("nij,j->ni", T[:, :3, :3], E_mean[:3, 3])
        return calibrate_tip_pivot(out).tob_t_tip_mm

    base = on_truth(np.tile(rv.mean(axis=0), (len(rv), 1)))
    tilt_part = on_truth(feats @ coef) - base
    pe = fit.tob_t_tip_mm - tip
    tip_point = fit.world_p_pivot_mm - run["true_tip_world"].mean(axis=0)
    # neighbour correlation of the true tip carried by the measured poses minus by the true ones
    e = np.einsum("nij,j->ni", P[:, :3, :3], tip) + P[:, :3, 3] - (np.einsum("nij,j->ni", T[:, :3, :3], tip) + T[:, :3, 3])
    e = e - e.mean(axis=0)
    rho = float(np.sum(e[1:] * e[:-1]) / np.sum(e * e))
    zt = T[:, :3, 2] @ np.array([0.0, 0.0, -1.0])
    return {"tip": fit.tob_t_tip_mm, "off_truth": pe, "sigma_before": _ols_sigma(P, fit.residuals_mm),
            "sigma_after": fit.tob_t_tip_sigma_mm, "frame_bias_mm": E_mean[:3, 3], "frame_bias_deg": np.degrees(rv.mean(axis=0)),
            "off_measured_frame_tip": fit.tob_t_tip_mm - tip_in_measured, "tip_point_mm": tip_point,
            "tilt_part": tilt_part, "rho": rho, "n": len(P), "span_s": run["span_s"],
            "tilt_max_deg": float(np.degrees(np.arccos(np.clip(zt.min(), -1, 1))))}


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m humanpt.twin.tip_bias", description=__doc__.split("\n\n")[0])
    ap.add_argument("--rig", help="the rig file the pipeline believes (default: the nominal rig)")
    ap.add_argument("--world", default="realistic")
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--samples", type=int, default=PIVOT_SAMPLES)
    ap.add_argument("--spread", type=float, default=PIVOT_SPREAD_DEG, help="min. rotation between fitted poses (deg)")
    ap.add_argument("--tilt", type=float, default=PIVOT_TILT_DEG, help="the pivot's +- tilt (deg)")
    ap.add_argument("--speed", type=float, default=PIVOT_SPEED_DEG_S, help="the pivot's angular speed (deg/s)")
    args = ap.parse_args(argv)
    from humanpt.runtime.rigfile import load_rig

    rig = load_rig(args.rig) if args.rig else None
    f3 = lambda v: "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"  # noqa: E731
    print("| seed | tip - true tip, mm (length) | 1-sigma before / after (largest) | off / sigma, before / after "
          "| measured TOB frame's bias (truth) | tip - E^-1 tip: the fit's own error | of it, the tilt-dependent rotation error's "
          "| the tip point in the world off the truth | poses, over s, neighbour corr. |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed in _seeds(args.seeds):
        d = diagnose(pivot_run(World.named(args.world), rig, seed, args.samples, args.spread, args.tilt, args.speed))
        e, sb, sa = d["off_truth"], d["sigma_before"], d["sigma_after"]
        print(f"| {seed} | {f3(e)} ({np.linalg.norm(e):.3f}) | {sb.max():.3f} / {sa.max():.3f} | "
              f"{np.max(np.abs(e) / sb):.1f} / {np.max(np.abs(e) / sa):.1f} | {f3(d['frame_bias_mm'])} mm, "
              f"{f3(d['frame_bias_deg'])} deg | {f3(d['off_measured_frame_tip'])} | {f3(d['tilt_part'])} | "
              f"{np.linalg.norm(d['tip_point_mm']):.3f} | {d['n']}, {d['span_s']:.1f}, {d['rho']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
