"""The job's accuracy report (issue 32.5): what a welder reads at the end of ``humanpt demo
--calibrate``.

For each calibration stage its estimate, its uncertainty (the rig's 1-sigma) and whether
it met its acceptance (on the twin: against the world's truth, :class:`Check`); the
camera-to-robot time offset and what it does at the taught speed; the playing arm's
absolute kinematic error; for the seam (taught points, fitted seam, played-back torch)
the RMS, max and coverage against the seam as designed and the worst place; a PNG of the
seam coloured by the played-back error; one PASS or WARN line.  Every figure beyond its
tolerance is a ``WARN`` line of its own.

It reads the twin's truth (the seam as designed, the world's arm and hand-eye), so it is a
twin module; :func:`report_lines` takes plain figures and could serve a real cell's
report given its own measurements.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Check", "TruthLines", "SeamFigures", "seam_figures", "JobReport", "job_report", "plot_seam_errors",
           "SEAM_TOLERANCES_MM", "COVER_MM", "arm_error_mm", "arm_share_mm"]

# The acceptance for a job on the realistic world (issue 32): the taught seam within
# 0.3 mm RMS, the played-back torch within 0.5 mm RMS; a seam point counts as covered when
# the torch passed within COVER_MM of it; coverage at least 99 %.
# The raw taught points carry the hand's tremor, which the fit takes out: shown, not judged.
SEAM_TOLERANCES_MM = {"taught": math.inf, "fitted": 0.3, "played": 0.5}
COVER_MM = 1.0
MIN_COVERAGE = 0.99


@dataclass(frozen=True)
class Check:
    """One figure against its acceptance: ``stage``, ``what``, ``value`` and ``limit`` in
    ``unit``; met when ``value <= limit``."""

    stage: str
    what: str
    value: float
    limit: float
    unit: str

    @property
    def met(self) -> bool:
        return bool(math.isfinite(self.value) and self.value <= self.limit)

    def line(self) -> str:
        return (f"{'ok  ' if self.met else 'WARN'} {self.stage}: {self.what} {self.value:.4g} {self.unit} "
                f"({'within' if self.met else 'beyond'} {self.limit:g} {self.unit})")


class TruthLines(list):
    """A stage's lines against the twin's truth (a list of str, as before), with the
    :class:`Check` s they make in ``checks``."""

    def __init__(self, lines=()):
        super().__init__(lines)
        self.checks: list[Check] = []


@dataclass(frozen=True)
class SeamFigures:
    """Distances (mm) of one path to the seam: RMS, max, how many points; coverage (the
    fraction of the seam, sampled every 0.5 mm, within COVER_MM of the path) and the
    largest stretch not covered (mm); the worst point (mm) and its distance."""

    name: str
    rms_mm: float
    max_mm: float
    n: int
    coverage: float
    gap_mm: float
    worst_mm: tuple[float, float, float] | None
    tolerance_mm: float

    @property
    def met(self) -> bool:
        return bool(self.n and self.rms_mm <= self.tolerance_mm and self.coverage >= MIN_COVERAGE)


def _distances(points: np.ndarray, seam_mm: np.ndarray) -> np.ndarray:
    """(N,) distance of each point (N, 3) to the seam polyline ``seam_mm`` (K, 3), mm
    (:func:`humanpt.seam.compare.distance_to_seam`)."""
    from humanpt.seam.compare import distance_to_seam, polyline_seam

    return distance_to_seam(polyline_seam(seam_mm), np.asarray(points, dtype=float).reshape(-1, 3))


def seam_figures(name: str, path_mm: np.ndarray, seam_mm: np.ndarray, tolerance_mm: float,
                 cover_mm: float = COVER_MM) -> SeamFigures:
    """:class:`SeamFigures` of ``path_mm`` (N, 3) (a polyline: points in order) against the
    seam ``seam_mm`` (K, 3) (its start and end included): humanpt.seam.compare's
    ``compare_points`` (every point counted; consecutive points within ``cover_mm`` of the
    seam cover the stretch between them)."""
    from humanpt.seam.compare import compare_points, polyline_seam

    path = np.asarray(path_mm, dtype=float).reshape(-1, 3)
    if len(path) == 0:
        return SeamFigures(name, math.nan, math.nan, 0, 0.0, math.nan, None, tolerance_mm)
    c = compare_points(polyline_seam(seam_mm), path, cover_mm=cover_mm, approach_mm=None, window=name)
    return SeamFigures(name, c.rms_mm, c.max_mm, c.n, c.covered, c.largest_gap_mm, c.worst_mm, tolerance_mm)


@dataclass
class JobReport:
    """The report: its lines (stages, seam, warnings, verdict), the checks and seam figures
    behind them, and the PNG's path (None when none was drawn)."""

    lines: list[str]
    checks: list[Check] = field(default_factory=list)
    seam: list[SeamFigures] = field(default_factory=list)
    png: Path | None = None
    notes: list[str] = field(default_factory=list)  # warnings that are no figure (a skipped stage, a doubt)

    @property
    def warnings(self) -> list[str]:
        return [f"WARN {n}" for n in self.notes] + [c.line() for c in self.checks if not c.met] + [
            f"WARN seam: {f.name} RMS {f.rms_mm:.3f} mm (tolerance {f.tolerance_mm:g}), coverage "
            f"{100 * f.coverage:.1f} % (at least {100 * MIN_COVERAGE:g} %)" for f in self.seam if not f.met]

    @property
    def passed(self) -> bool:
        return not self.warnings

    def text(self) -> str:
        return "\n".join(self.lines)


def plot_seam_errors(path: Path, seam_mm: np.ndarray, played_mm: np.ndarray, played_err_mm: np.ndarray,
                     tolerance_mm: float, title: str = "") -> Path:
    """A PNG of the seam from above, the played-back torch coloured by its distance to the
    seam (mm), the worst place marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 6), dpi=100)
    ax.plot(seam_mm[:, 0], seam_mm[:, 1], color="0.6", lw=4, alpha=0.5, label="seam (as designed)")
    if len(played_mm):
        sc = ax.scatter(played_mm[:, 0], played_mm[:, 1], c=played_err_mm, s=6, cmap="viridis_r",
                        vmin=0.0, vmax=max(tolerance_mm, float(np.max(played_err_mm))))
        fig.colorbar(sc, ax=ax, label="played-back torch: distance to the seam (mm)")
        k = int(np.argmax(played_err_mm))
        ax.plot(*played_mm[k, :2], "rx", ms=12, mew=2, label=f"worst: {played_err_mm[k]:.2f} mm")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "played-back torch against the seam")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def job_report(res, png: Path | None = None) -> JobReport:
    """The report of a :class:`humanpt.twin.teach.TeachResult` (module doc); the PNG
    written to ``png`` when given."""
    lines = ["accuracy report"]
    checks: list[Check] = []
    notes: list[str] = []
    lines.append("  calibration (estimate, 1-sigma from the rig; checks against the twin's truth)")
    rig = res.rig
    parts = {"camera": rig.psvs_calibration, "psvs": rig.psvs_calibration, "hand-eye": rig.hand_eye.calibration,
             "tip": rig.tip.calibration, "arm": rig.arm.calibration, "stereo": rig.stereo.calibration}
    for s in res.stages:
        if getattr(s, "skipped", ""):  # nothing to do here (the arm on the stand-in): said, not warned
            lines.append(f"    {s.name:10s} not run: {s.skipped}")
            continue
        if not s.ok:
            lines.append(f"    {s.name:10s} SKIPPED: {s.error}")
            notes.append(f"{s.name}: stage skipped, the rig keeps its previous values ({s.error})")
            continue
        cal = parts.get(s.name)
        shown = _SIGMA_KEYS.get(s.name)
        sigma = ", ".join(f"{k} {v:.3g}" for k, v in (cal.sigma if cal else {}).items()
                          if shown is None or k in shown) or "-"
        est = _estimate(s.name, rig)
        stage_checks = list(getattr(s, "checks", []))
        if s.name == "hand-eye" and _arm_replaced_hand_eye(res):
            # the arm's stage estimated the hand-eye again, with the arm: the rig has that one
            # (checked there); this stage's own estimate, on the nominal arm, is history
            old = [c for c in stage_checks if c.stage == "hand-eye"]
            stage_checks = [c for c in stage_checks if c.stage != "hand-eye"]
            lines.append(f"    {s.name:10s} superseded by the arm's stage (the rig's hand-eye is the one estimated with "
                         f"the arm, below); its own on the nominal arm: " + ", ".join(
                             f"{c.what} {c.value:.4g} {c.unit}" for c in old))
            checks += stage_checks
            continue
        checks += stage_checks
        verdict = ("met" if all(c.met for c in stage_checks) else "NOT met") if stage_checks else "no acceptance stated"
        lines.append(f"    {s.name:10s} {est}; 1-sigma {sigma}; acceptance {verdict}")
    t = rig.timing
    if t.calibration.method != "nominal":
        sig = t.calibration.sigma.get("camera_time_offset_ms", math.nan)
        lines.append(f"    {'timing':10s} camera-to-robot offset {t.camera_time_offset_ms:+.2f} ms; 1-sigma {sig:.2f} ms")
    extra = list(getattr(res, "checks", []))
    checks += extra
    if extra:
        lines += ["", "  the job's checks"]
    for c in extra:
        lines.append(f"    {c.line()}")
    seam = getattr(res, "seam_mm", None)
    figs: list[SeamFigures] = []
    if seam is not None:
        lines += ["", f"  seam (distance to the seam as designed; covered: within {COVER_MM:g} mm of the path)"]
        frame = getattr(res, "seam_arm_frame_mm", None)  # a calibrated arm's frame (humanpt.twin.teach)
        if frame is not None:
            lines.append(f"    ({res.arm_frame_note})")
        rows = [("taught", "taught points (the driver's tip)", getattr(res, "taught_path_mm", None)),
                ("fitted", "fitted seam (lines and arcs)", getattr(res, "fitted_path_mm", None)),
                ("played", "played-back torch (true path)", getattr(res, "played_path_mm", None))]
        for key, name, pts in rows:
            if pts is None:
                continue
            f = seam_figures(name, pts, frame if frame is not None and key != "played" else seam,
                             SEAM_TOLERANCES_MM[key])
            where = (f"worst at ({', '.join(f'{v:.1f}' for v in f.worst_mm)}) mm" if f.worst_mm else "no points")
            judged = math.isfinite(f.tolerance_mm)
            if judged:
                figs.append(f)
            lines.append(f"    {('ok  ' if f.met else 'WARN') if judged else 'info'} {name:34s} RMS {f.rms_mm:6.3f}  "
                         f"max {f.max_mm:6.3f} mm  covered {100 * f.coverage:5.1f} % (largest gap {f.gap_mm:.1f} mm)  "
                         f"{where}  " + (f"(tolerance {f.tolerance_mm:g} mm RMS)" if judged else
                                         "(with the hand's tremor: the fitted seam is what is played)"))
        played = getattr(res, "played_path_mm", None)
        if png is not None and played is not None:
            png = plot_seam_errors(png, seam, played, _distances(played, seam) if len(played) else
                                   np.zeros(0), SEAM_TOLERANCES_MM["played"])
            lines.append(f"    picture: {png}")
        else:
            png = None
    doubts = list(getattr(res.fitted, "doubts", []) if getattr(res, "fitted", None) is not None else [])
    notes += [f"fit: {d}" for d in doubts]
    rep = JobReport(lines, checks, figs, png, notes)
    warn = rep.warnings
    rep.lines += [""] + warn + [("PASS: every figure within its tolerance" if not warn else
                                 f"WARN: {len(warn)} figure{'s' if len(warn) > 1 else ''} beyond tolerance (above)")]
    return rep


def _arm_replaced_hand_eye(res) -> bool:
    """Whether the job's arm stage ran and wrote the rig's hand-eye."""
    from humanpt.calibration.arm import METHOD

    return (any(s.name == "arm" and s.ok for s in res.stages)
            and res.rig.hand_eye.calibration.method == METHOD)


# The camera and the PSVS stages share the rig's [psvs] table: each shows its own keys.
_SIGMA_KEYS = {"camera": ("a_u", "a_v", "u0", "v0", "dist_coeffs"),
               "psvs": ("du0_left_px", "dv0_left_px", "rotvec_left_deg", "baseline_mm")}


def _estimate(stage: str, rig) -> str:
    if stage == "camera":
        p = rig.psvs
        return f"a_u {p.a_u:.2f} px, a_v {p.a_v:.2f} px"
    if stage == "psvs":
        p = rig.psvs
        return f"baseline {getattr(p, 'baseline_mm', float('nan')):.3f} mm ({rig.psvs_calibration.method})"
    if stage == "stereo":
        st = rig.stereo
        return (f"baseline {st.baseline_mm():.3f} mm, a_u left {st.left.a_u:.2f} px, right {st.right.a_u:.2f} px "
                f"({st.calibration.method})")
    if stage == "hand-eye":
        return "flange_T_camera [" + ", ".join(f"{v:.3f}" for v in rig.hand_eye.flange_T_camera_x) + "] mm/deg"
    if stage == "tip":
        return "tob_t_tip [" + ", ".join(f"{v:.3f}" for v in rig.tip.tob_t_tip_mm) + "] mm"
    if stage == "arm":
        a = rig.arm
        return (f"{a.model}: joint offsets [" + ", ".join(f"{v:+.4f}" for v in a.joint_offsets_deg) + "] deg, "
                "d2 a2 a3 d4 d6 errors [" + ", ".join(f"{v:+.3f}" for v in a.link_length_errors_mm) + "] mm")
    return ""


def arm_error_mm(robot_overrides: dict | None, mount_world_T_flange_mm: np.ndarray, world_T_tool_mm: np.ndarray,
                 flange_T_tool_mm: np.ndarray) -> np.ndarray:
    """(N,) how far (mm) the world's Puma puts the tool from each of the poses
    ``world_T_tool_mm`` (N, 4, 4) when it goes there with its nominal model (the absolute
    kinematic error a cartesian playback meets): the joints by the nominal inverse
    kinematics, the flange by the world's true arm (``robot_overrides``' ``sim_robot``
    joint offsets and link errors), the Puma mounted as the job mounts it around
    ``mount_world_T_flange_mm``.  Poses out of the nominal arm's reach are left out."""
    from humanpt.geometry.puma import UnreachableError
    from humanpt.geometry.transforms import invert_transform, transform_from_x, x_from_transform

    from .system import _with_robot_overrides, puma_cores

    rcfg, _ = puma_cores(transform_from_x(np.asarray(x_from_transform(mount_world_T_flange_mm))))
    rcfg = _with_robot_overrides(rcfg, robot_overrides, "sim_robot")
    kin, arm = rcfg.kinematics(), rcfg.true_arm()
    world_T_base = transform_from_x(np.asarray(rcfg.world_T_base_mm_deg, dtype=float))
    base_T_world = invert_transform(world_T_base)
    tool_T_flange = invert_transform(np.asarray(flange_T_tool_mm, dtype=float))
    q = rcfg.start_joints_rad()
    out = []
    for T in np.asarray(world_T_tool_mm, dtype=float):
        try:
            q = kin.inverse(base_T_world @ T @ tool_T_flange, q)
        except UnreachableError:
            continue
        true_tool = world_T_base @ arm.forward(q) @ np.asarray(flange_T_tool_mm, dtype=float)
        out.append(float(np.linalg.norm(true_tool[:3, 3] - T[:3, 3])))
    return np.array(out)


def arm_share_mm(robot_overrides: dict | None, mount_world_T_flange_mm: np.ndarray, mount_joints_deg,
                 watch_world_T_flange_mm: np.ndarray, seam_world_T_tool_mm: np.ndarray, flange_T_tool_mm: np.ndarray,
                 rig_flange_T_camera_mm: np.ndarray, true_flange_T_camera_mm: np.ndarray, model_arm=None) -> np.ndarray:
    """(N,) the arm's share of the played-back error (mm) at each seam pose
    ``seam_world_T_tool_mm`` (N, 4, 4): the world's Puma (``robot_overrides``' sim_robot
    errors, mounted as the job mounts it) teaches the seam point watching it from
    ``watch_world_T_flange_mm`` (N, 4, 4), as the cell believes (the rig's hand-eye and arm
    model ``model_arm``: a calibrated :class:`humanpt.geometry.puma.TrueArm`, None: the
    nominal arm), then plays it (commanded through the same model:
    :func:`humanpt.controller.playback.command_poses`); the distance from the true torch to
    the true point.  The camera is exact here: what is left is the arm's and the hand-eye's.
    Poses out of the nominal arm's reach are left out."""
    from humanpt.controller.playback import command_poses
    from humanpt.geometry.puma import UnreachableError
    from humanpt.geometry.transforms import invert_transform, transform_from_x, x_from_transform

    from .system import _with_robot_overrides, puma_cores

    rcfg, _ = puma_cores(transform_from_x(np.asarray(x_from_transform(mount_world_T_flange_mm))),
                         joints_deg=mount_joints_deg)
    rcfg = _with_robot_overrides(rcfg, robot_overrides, "sim_robot")
    kin, true = rcfg.kinematics(), rcfg.true_arm()
    believed = kin if model_arm is None else model_arm
    W = transform_from_x(np.asarray(rcfg.world_T_base_mm_deg, dtype=float))
    Wi = invert_transform(W)
    tool = np.asarray(flange_T_tool_mm, dtype=float)
    tool_i = invert_transform(tool)
    Xr, Xt = np.asarray(rig_flange_T_camera_mm, dtype=float), np.asarray(true_flange_T_camera_mm, dtype=float)
    q = rcfg.start_joints_rad()
    out = []
    for V, S in zip(np.asarray(watch_world_T_flange_mm, dtype=float), np.asarray(seam_world_T_tool_mm, dtype=float),
                    strict=True):
        try:
            q_t = kin.inverse(Wi @ V, q)  # the servo takes the reported (nominal) flange there
            p = S[:3, 3]
            cam_true = W @ true.forward(q_t) @ Xt
            m = invert_transform(cam_true)[:3, :3] @ p + invert_transform(cam_true)[:3, 3]
            cam_bel = W @ believed.forward(q_t) @ Xr
            taught = S.copy()
            taught[:3, 3] = cam_bel[:3, :3] @ m + cam_bel[:3, 3]
            goal = Wi @ taught @ tool_i
            q_p = kin.inverse(goal, q_t)
            if model_arm is not None:
                q_p = command_poses(kin, model_arm, goal[None], q_p[None])[0][0]
        except UnreachableError:
            continue
        torch = W @ true.forward(q_p) @ tool
        out.append(float(np.linalg.norm(torch[:3, 3] - p)))
        q = q_t
    return np.array(out)
