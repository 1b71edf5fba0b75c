"""Accuracy of both methods on twin images with ground truth (used by the acceptance
tests, ``humanpt bench perception`` and the README's figures).

Images come from the digital twin's renderer (:class:`humanpt.sim_camera.render.Renderer`,
the default sensor noise unless a case says otherwise); the truth is the renderer's own
scene: every blob's projected centre, view and label, and ``camera_T_tob``. Three sets:

* ``standard``: the poses the target takes in the operator's built-in scenarios (static,
  arc, trapezium, freehand; :mod:`humanpt.operator.scenario`), seen by a camera that tracks
  it as the servo would - the desired point D (600 mm on the optical axis) placed on the
  target as it was ``lag_s`` earlier, plus a few mm / deg of seeded tracking error;
* ``random``: random poses in the working volume (x, y within +-60 mm, z 450-900 mm, each
  angle within +-25 deg);
* ``clutter``: the hard cases - the target's mirror image in a shiny plane fixed to it
  (dimmer, blurred), a bright lamp near the target, and poses with yaw near +-90 deg so
  that two sources share a scan line (four blobs on one line);
* ``range``: random poses at the ends of the working range (250, 350, 1200, 1800 mm).

Figures per method: image counts by status, wrong correspondences (an image with any
reported pair that is not both views of one source - or, for a FULL measurement, not the
right source A, B, C), centre error RMS (px) over correctly paired blobs, 3D point error
RMS per axis (mm) next to the geometry library's stereo bound
(:func:`humanpt.geometry.point_sigma_mm` at the true points, with the measured centre RMS
as sigma and the method's triangulation), and the pose error (translation of G, mm;
rotation angle, deg) of FULL measurements next to its bound
(:func:`humanpt.geometry.pose_sigma`, same sigma: the root sum of squares of the three
position and of the three angle sigmas).

Test machinery (``humanpt.testing``): the perception package never imports it; it needs
``humanpt.sim_camera`` and ``humanpt.operator``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from humanpt.geometry import (
    invert_transform,
    point_sigma_mm,
    pose_sigma,
    rotation_angle_rad,
    transform_from_x,
    transform_points,
    viewing_world_T_flange,
)
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.correspondence import FULL, LOST, POSITION_ONLY
from humanpt.perception.pipeline import Perception
from humanpt.runtime import tables

__all__ = [
    "Case",
    "Stats",
    "SETS",
    "standard_cases",
    "random_cases",
    "clutter_cases",
    "range_cases",
    "cases_for",
    "evaluate",
    "format_table",
]

SETS = ("standard", "random", "clutter", "range")


@dataclass(frozen=True)
class Case:
    """One image to render: ``camera_T_tob`` (4, 4) mm, ``world_T_camera`` (4, 4) mm or
    None (only a world-fixed lamp needs it), the renderer's config, the frame index (noise
    seed) and a name."""

    name: str
    camera_T_tob: np.ndarray
    sim: object  # humanpt.sim_camera.SimCameraConfig
    frame_index: int = 0
    world_T_camera: np.ndarray | None = None


@dataclass
class Stats:
    """Figures of one method on one set (see the module docstring); lengths in mm, angles
    in degrees, image coordinates in px."""

    method: str
    images: int = 0
    full: int = 0
    position_only: int = 0
    lost: int = 0
    wrong: int = 0
    centre_err_px: list = field(default_factory=list)
    point_err_mm: list = field(default_factory=list)
    true_points_mm: list = field(default_factory=list)
    translation_err_mm: list = field(default_factory=list)
    rotation_err_deg: list = field(default_factory=list)
    true_poses: list = field(default_factory=list)
    bound_mm: np.ndarray | None = None
    pose_bound: tuple[float, float] = (math.nan, math.nan)

    @property
    def wrong_rate(self) -> float:
        return self.wrong / max(self.images, 1)

    @property
    def centre_rms_px(self) -> float:
        e = np.asarray(self.centre_err_px, dtype=float).reshape(-1)
        return float(np.sqrt(np.mean(e**2))) if e.size else math.nan

    @property
    def point_rms_mm(self) -> np.ndarray:
        e = np.asarray(self.point_err_mm, dtype=float).reshape(-1, 3)
        return np.sqrt(np.mean(e**2, axis=0)) if len(e) else np.full(3, math.nan)

    @property
    def translation_rms_mm(self) -> float:
        e = np.asarray(self.translation_err_mm, dtype=float)
        return float(np.sqrt(np.mean(e**2))) if e.size else math.nan

    @property
    def rotation_rms_deg(self) -> float:
        e = np.asarray(self.rotation_err_deg, dtype=float)
        return float(np.sqrt(np.mean(e**2))) if e.size else math.nan


# --------------------------------------------------------------------------- case sets


def _sim_config(**changes):
    from humanpt.sim_camera import SimCameraConfig

    return dataclasses.replace(SimCameraConfig(), **changes)


def standard_cases(per_scenario: int = 25, seed: int = 0, lag_s: float = 0.1) -> list[Case]:
    """``per_scenario`` images from each built-in scenario (see the module docstring)."""
    from humanpt.operator.scenario import BUILTIN_SCENARIOS, Trajectory, builtin_scenario

    sim = _sim_config(seed=seed)
    flange_T_camera = sim.flange_T_camera
    rng = np.random.default_rng([seed, 1])
    cases = []
    for s_index, name in enumerate(BUILTIN_SCENARIOS):
        traj = Trajectory(builtin_scenario(name, seed=seed))
        times = np.linspace(0.0, max(traj.duration_s, 1.0), per_scenario)
        for k, t in enumerate(times):
            world_T_tob, _ = traj.pose(float(t))
            seen, _ = traj.pose(max(float(t) - lag_s, 0.0))
            jitter = transform_from_x(
                np.concatenate([rng.normal(0, 3.0, 3), rng.normal(0, 1.0, 3)])
            )
            world_T_flange = viewing_world_T_flange(seen @ jitter, 600.0, flange_T_camera)
            world_T_camera = world_T_flange @ flange_T_camera
            cases.append(
                Case(
                    f"{name}@{t:.2f}s",
                    invert_transform(world_T_camera) @ world_T_tob,
                    sim,
                    1000 * s_index + k,
                    world_T_camera,
                )
            )
    return cases


def _random_pose(rng, yaw_deg=None) -> np.ndarray:
    x = np.concatenate([rng.uniform([-60, -40, 450], [60, 40, 900]), rng.uniform(-25, 25, 3)])
    if yaw_deg is not None:
        x[3] = yaw_deg
    return transform_from_x(x)


def random_cases(n: int = 100, seed: int = 0) -> list[Case]:
    """``n`` random poses in the working volume, default sensor."""
    rng = np.random.default_rng([seed, 2])
    sim = _sim_config(seed=seed)
    return [Case(f"random#{k}", _random_pose(rng), sim, k) for k in range(n)]


def clutter_cases(n: int = 90, seed: int = 0) -> list[Case]:
    """``n`` images, a third each with the mirror image (gain 0.3-0.6), a lamp beside and
    200 mm behind the target (30 mm, in the camera frame; it sometimes hides a source), and
    two sources on one scan line (yaw 90 or -90 deg +- 0.1 deg, with a faint reflection
    too)."""
    rng = np.random.default_rng([seed, 3])
    cases = []
    for k in range(n):
        kind = k % 3
        if kind == 0:
            sim = _sim_config(seed=seed, reflection_gain=float(rng.uniform(0.3, 0.6)))
            T = _random_pose(rng)
            name = "reflection"
        elif kind == 1:
            T = _random_pose(rng)
            side = rng.choice([-1, 1]) * rng.uniform(60, 160)
            lamp = T[:3, 3] + np.array([side, rng.uniform(-30, 30), 200.0])
            sim = _sim_config(
                seed=seed, lamp_position_mm=tuple(float(v) for v in lamp), lamp_frame="camera"
            )
            name = "lamp"
        else:
            yaw = float(rng.choice([-90.0, 90.0]) + rng.uniform(-0.1, 0.1))
            T = _random_pose(rng, yaw_deg=yaw)
            sim = _sim_config(seed=seed, reflection_gain=0.25)
            name = "shared scan line"
        cases.append(Case(f"{name}#{k}", T, sim, k))
    return cases


def range_cases(
    n: int = 160, seed: int = 0, depths_mm=(250.0, 350.0, 1200.0, 1800.0)
) -> list[Case]:
    """``n`` random poses split over the given depths (z of G, mm; x, y within +-5 % of z,
    angles within +-25 deg), default sensor: the ends of the working range."""
    rng = np.random.default_rng([seed, 4])
    sim = _sim_config(seed=seed)
    per = max(1, n // len(depths_mm))
    cases = []
    for z in depths_mm:
        for k in range(per):
            x = np.concatenate([rng.uniform(-0.05 * z, 0.05 * z, 2), [z], rng.uniform(-25, 25, 3)])
            cases.append(Case(f"z={z:.0f}#{k}", transform_from_x(x), sim, len(cases)))
    return cases


def cases_for(name: str, n: int, seed: int = 0) -> list[Case]:
    """The set ``name`` (one of :data:`SETS`) with about ``n`` images."""
    if name == "standard":
        return standard_cases(max(1, n // 4), seed)
    if name == "random":
        return random_cases(n, seed)
    if name == "clutter":
        return clutter_cases(n, seed)
    if name == "range":
        return range_cases(n, seed)
    raise ValueError(f"no case set {name!r}; sets: {', '.join(SETS)}")


# --------------------------------------------------------------------------- evaluation


def _rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(rotation_angle_rad(a[:3, :3].T @ b[:3, :3]))


def evaluate(
    cases: list[Case],
    methods: tuple[str, ...] = ("weighted", "paper"),
    config: PerceptionConfig | None = None,
) -> dict[str, Stats]:
    """Render every case once and measure it with each method (whole image, no tracking).
    Returns ``{method: Stats}`` with the bound filled in."""
    from humanpt.sim_camera.render import Renderer

    base = config or PerceptionConfig()
    perceptions = {m: Perception(dataclasses.replace(base, method=m)) for m in methods}
    stats = {m: Stats(m) for m in methods}
    renderers: dict[object, Renderer] = {}
    for case in cases:
        renderer = renderers.get(case.sim)
        if renderer is None:
            renderer = renderers[case.sim] = Renderer(case.sim)
        discs = renderer.discs(case.camera_T_tob, case.world_T_camera)
        truth = renderer.blobs(discs)
        img = renderer.expose(renderer.signal(truth), case.frame_index)
        true_points = transform_points(case.camera_T_tob, renderer.model.source_positions_mm)
        for method, perception in perceptions.items():
            _score(stats[method], perception.measure(img), truth, true_points, case.camera_T_tob)
    for method, s in stats.items():
        pts = np.asarray(s.true_points_mm, dtype=float).reshape(-1, 3)
        sigma = s.centre_rms_px
        if len(pts) and math.isfinite(sigma):
            p = perceptions[method]
            tri = "eq4" if method == "paper" else p.config.triangulation
            sig = np.array([point_sigma_mm(p.params, q, sigma, tri) for q in pts])
            s.bound_mm = np.sqrt(np.mean(sig**2, axis=0))
            # the pose: sigma of X (mm, deg) -> RMS translation and (small) rotation angle
            sig_x = np.array([pose_sigma(p.params, p.model, T, sigma, tri) for T in s.true_poses])
            s.pose_bound = (
                float(np.sqrt(np.mean(np.sum(sig_x[:, :3] ** 2, axis=1)))),
                float(np.sqrt(np.mean(np.sum(sig_x[:, 3:] ** 2, axis=1)))),
            )
    return stats


def _score(s: Stats, result, truth, true_points: np.ndarray, camera_T_tob: np.ndarray) -> None:
    s.images += 1
    m = result.match
    s.full += m.status == FULL
    s.position_only += m.status == POSITION_ONLY
    s.lost += m.status == LOST
    uv = result.blobs.uv_px
    if m.visible == 0:
        return
    # each reported centre -> the nearest true blob (view, label)
    d = np.linalg.norm(uv[m.pairs.ravel()][:, None, :] - truth.centre_px[None], axis=-1)
    nearest = d.argmin(axis=1)
    close = d[np.arange(len(nearest)), nearest] < 1.0
    views = truth.view[nearest].reshape(-1, 2)
    labels = truth.label[nearest].reshape(-1, 2)
    close = close.reshape(-1, 2)
    ok = (
        close.all(axis=1)
        & (views[:, 0] == 0)
        & (views[:, 1] == 1)
        & (labels[:, 0] == labels[:, 1])
        & (labels[:, 0] < 3)
    )
    if m.status == FULL:
        ok &= labels[:, 0] == np.arange(3)
    if not ok.all():
        s.wrong += 1
        return
    s.centre_err_px.extend((uv[m.pairs.ravel()] - truth.centre_px[nearest]).ravel().tolist())
    if m.status == FULL:
        s.point_err_mm.extend((m.camera_p_mm - true_points).tolist())
        s.true_points_mm.extend(true_points.tolist())
        s.translation_err_mm.append(
            float(np.linalg.norm(m.camera_T_tob[:3, 3] - camera_T_tob[:3, 3]))
        )
        s.rotation_err_deg.append(_rotation_angle_deg(m.camera_T_tob, camera_T_tob))
        s.true_poses.append(camera_T_tob)


def format_table(results: dict[str, dict[str, Stats]]) -> str:
    """A text table of ``{set name: {method: Stats}}``."""
    header = ["set", "method", "images", "full", "pos.", "lost", "wrong", "centre RMS px",
              "3D RMS x", "y", "z (mm)", "bound x", "y", "z (mm)", "pose RMS t mm", "r deg", "bound t", "r"]
    rows = []
    for set_name, by_method in results.items():
        for method, s in by_method.items():
            rms = s.point_rms_mm
            bound = s.bound_mm if s.bound_mm is not None else np.full(3, math.nan)
            rows.append([set_name, method, s.images, s.full, s.position_only, s.lost, f"{100 * s.wrong_rate:.1f}%",
                         f"{s.centre_rms_px:.4f}", *(tables.number(v) for v in rms[:2]), tables.number(rms[2], 3),
                         *(tables.number(v) for v in bound[:2]), tables.number(bound[2], 3),
                         tables.number(s.translation_rms_mm, 3), tables.number(s.rotation_rms_deg, 3),
                         tables.number(s.pose_bound[0], 3), tables.number(s.pose_bound[1], 3)])
    return tables.render(header, rows, align="ll" + "r" * (len(header) - 2))


# --------------------------------------------------------------------------- blob checks


def realistic_sim_config(seed: int = 0):
    """The renderer's config of the twin's realistic world (its optics and sensor)."""
    from humanpt.runtime.config import build, to_table
    from humanpt.sim_camera import SimCameraConfig
    from humanpt.twin.worlds import World, merge_overrides

    table = merge_overrides(to_table(SimCameraConfig(seed=seed)), World.realistic().overrides()["sim_camera"])
    return build(SimCameraConfig, table, source="realistic world", section="sim_camera")


def check_rates(
    cases: list[Case],
    fractions=(0.0, 0.1, 0.2, 0.3),
    methods: tuple[str, ...] = ("weighted", "paper"),
    sim=None,
    seed: int = 1,
) -> dict[str, dict[float, tuple[int, int, int]]]:
    """The blob checks (:mod:`humanpt.perception.checks`) on ``cases`` rendered with source
    ``index % 3`` covered by ``fraction`` (the hidden side at a seeded random angle in the
    TOB plane; ``sim`` the renderer's config, default the case's). Returns ``{method:
    {fraction: (checked images, images with the covered source flagged - or, for 0, with any
    flag -, images with another source flagged)}}``."""
    from humanpt.sim_camera.render import Renderer

    perceptions = {m: Perception(PerceptionConfig(method=m)) for m in methods}
    out: dict[str, dict[float, tuple[int, int, int]]] = {m: {} for m in methods}
    for fraction in fractions:
        counts = {m: [0, 0, 0] for m in methods}
        for k, case in enumerate(cases):
            source = k % 3
            angle = float(np.random.default_rng([seed, k]).uniform(0.0, 360.0))
            base = sim or case.sim
            cfg = dataclasses.replace(base, occluded_sources=(source,) if fraction else (),
                                      occlusion_fraction=fraction or 0.5, occlusion_angle_deg=angle)
            r = Renderer(cfg)
            img = r.expose(r.signal(r.blobs(r.discs(case.camera_T_tob, case.world_T_camera))), case.frame_index)
            for m, p in perceptions.items():
                check = p.measure(img).check
                if check is None:
                    continue
                c = counts[m]
                c[0] += 1
                if fraction:
                    c[1] += source in check.degraded
                    c[2] += any(s != source for s in check.degraded)
                else:
                    c[1] += bool(check.degraded)
        for m in methods:
            out[m][fraction] = tuple(counts[m])
    return out


def check_table(seed: int = 1) -> str:
    """The perception README's table of the blob checks: ideal and realistic optics, both
    methods, the scenarios' poses (15 each) and 200 random ones, 0/10/20/30 % covers.
    ``python -c "from humanpt.testing.perception_eval import check_table; print(check_table())"``"""
    from humanpt.sim_camera import SimCameraConfig

    sets = {"scenarios": standard_cases(15, seed=seed), "random": random_cases(200, seed=seed)}
    lines = ["optics     method    poses          n   0% (false)  10%   20%   30%   (wrong source)"]
    for optics, sim in (("ideal", SimCameraConfig(seed=seed)), ("realistic", realistic_sim_config(seed))):
        for set_name, cases in sets.items():
            rates = check_rates(cases, sim=sim, seed=seed)
            for method, by_fraction in rates.items():
                n0, false, _ = by_fraction[0.0]
                cells = [f"{100.0 * hit / max(n, 1):4.0f}%" for f, (n, hit, _) in by_fraction.items() if f]
                wrong = sum(w for f, (_, _, w) in by_fraction.items() if f)
                lines.append(f"{optics:10s} {method:9s} {set_name:10s} {n0:5d} {false:8d}      "
                             + "  ".join(cells) + f"   {wrong}")
    return "\n".join(lines)
