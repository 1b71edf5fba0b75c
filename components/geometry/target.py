"""The target object (TOB) and its frame: Section 4, eq. (7)-(9).

The TOB carries three planar light sources A, B, C on the vertices of an isosceles
triangle (apex A, base BC), and optionally a metal driver whose endpoint P is at its
invisible underside.

TOB frame (eq. (7), (8)): origin G = (A + B + C)/3; ``R_a = GA``, ``R_b = GB``;
``W = R_b x R_a``, ``U = -R_a``, ``V = W x U``; ``u, v, w`` their unit vectors and
``camera_R_tob = [u v w]``. The frame is right-handed (``u x v = w`` by construction).

Which way w points is fixed by the labelling of B and C: :func:`label_sources` names B and
C so that **w points away from the camera**, i.e. from the lit face into the TOB's
underside, where the driver is. The driver tip of eq. (9) is then at ``G + d w`` with
d > 0 (``tob_t_tip = (0, 0, d)``). In the TOB frame the sources lie in the plane w = 0,
A on the negative u axis, B at v > 0, C at v < 0.

Units: mm. Default target (an assumption, the paper gives no dimensions): legs
AB = AC = 40 mm, base BC = 30 mm, 5 mm sources - three dots picked by a mask from a large
5x7 dot-matrix display (apex at the top centre dot, B and C at the bottom corners) - and a
60 mm needle on the w axis.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import GeometryError
from .transforms import compose, invert_transform, make_transform, transform_points

__all__ = [
    "TargetModel",
    "Labelling",
    "tob_frame_from_points",
    "label_sources",
    "estimate_camera_T_tob",
    "tob_T_tip_on_w_axis",
    "tip_pose",
    "isosceles_source_positions_mm",
    "COLLINEAR_SINE_TOL",
]

COLLINEAR_SINE_TOL = 1e-6
"""Smallest |sin| of the angle between GA and GB (and of any triangle corner) accepted as a
triangle; below it the points are called collinear."""


def tob_frame_from_points(a_p_a_mm, a_p_b_mm, a_p_c_mm) -> np.ndarray:
    """Eq. (7), (8): ``a_T_tob`` (..., 4, 4) from the labelled source centres A, B, C
    (..., 3) given in any frame ``a`` (normally the camera frame), mm.

    G is the mean of A, B, C; ``W = GB x GA``, ``U = -GA``, ``V = W x U``, normalised.
    Raises :class:`GeometryError` for coincident or collinear points.
    """
    a = np.asarray(a_p_a_mm, dtype=float)
    b = np.asarray(a_p_b_mm, dtype=float)
    c = np.asarray(a_p_c_mm, dtype=float)
    if a.shape == (3,) and b.shape == (3,) and c.shape == (3,):
        frame = _tob_frame_single(a.tolist(), b.tolist(), c.tolist())
        if frame is not None:
            return frame
    if a.shape[-1:] != (3,) or b.shape[-1:] != (3,) or c.shape[-1:] != (3,):
        raise ValueError("source points must have shape (..., 3)")
    g = (a + b + c) / 3.0
    r_a = a - g
    r_b = b - g
    w = np.cross(r_b, r_a)
    u = -r_a
    v = np.cross(w, u)
    n_a = np.linalg.norm(r_a, axis=-1)
    n_b = np.linalg.norm(r_b, axis=-1)
    n_w = np.linalg.norm(w, axis=-1)
    scale = np.maximum(n_a * n_b, 1e-300)
    if np.any(~np.isfinite(n_w)) or np.any(n_a < 1e-9) or np.any(n_b < 1e-9):
        raise GeometryError("light sources coincide (or are not finite): no TOB frame")
    sine = n_w / scale
    if np.any(sine < COLLINEAR_SINE_TOL):
        raise GeometryError(
            f"light sources are collinear (|sin(GA, GB)| = {np.min(sine):.3g}): no TOB frame"
        )
    rot = np.stack(
        [
            u / np.linalg.norm(u, axis=-1, keepdims=True),
            v / np.linalg.norm(v, axis=-1, keepdims=True),
            w / n_w[..., None],
        ],
        axis=-1,
    )
    return make_transform(rot, g)


def _norm3(x: float, y: float, z: float) -> float:
    """``np.linalg.norm`` of a 3-vector, the same number (squares summed in order)."""
    return math.sqrt(x * x + y * y + z * z)


def _tob_frame_single(a: list, b: list, c: list) -> np.ndarray | None:
    """:func:`tob_frame_from_points` for one triangle in plain float arithmetic: the same
    operations in the same order as the array code (so the same numbers), without numpy's
    per-call overhead on 3-vectors. None when the array code has to decide (non-finite
    input, coincident or collinear points: it raises with the message)."""
    ax, ay, az = a
    bx, by, bz = b
    cx, cy, cz = c
    gx, gy, gz = (ax + bx + cx) / 3.0, (ay + by + cy) / 3.0, (az + bz + cz) / 3.0
    rax, ray, raz = ax - gx, ay - gy, az - gz
    rbx, rby, rbz = bx - gx, by - gy, bz - gz
    # w = r_b x r_a, u = -r_a, v = w x u (np.cross's operation order)
    wx, wy, wz = rby * raz - rbz * ray, rbz * rax - rbx * raz, rbx * ray - rby * rax
    ux, uy, uz = -rax, -ray, -raz
    vx, vy, vz = wy * uz - wz * uy, wz * ux - wx * uz, wx * uy - wy * ux
    n_a = _norm3(rax, ray, raz)
    n_b = _norm3(rbx, rby, rbz)
    n_w = _norm3(wx, wy, wz)
    if not (math.isfinite(n_w) and n_a >= 1e-9 and n_b >= 1e-9):
        return None
    if not n_w / (n_a * n_b) >= COLLINEAR_SINE_TOL:
        return None
    n_u = _norm3(ux, uy, uz)
    n_v = _norm3(vx, vy, vz)
    return np.array(
        [
            [ux / n_u, vx / n_v, wx / n_w, gx],
            [uy / n_u, vy / n_v, wy / n_w, gy],
            [uz / n_u, vz / n_v, wz / n_w, gz],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def tob_T_tip_on_w_axis(distance_mm: float) -> np.ndarray:
    """Eq. (9) default: ``tob_T_tip`` with ``R = I`` and ``t = (0, 0, d)`` - the driver tip
    on the w axis at distance d (mm) from G, on the underside for d > 0."""
    return make_transform(np.eye(3), np.array([0.0, 0.0, float(distance_mm)]))


def tip_pose(a_T_tob: np.ndarray, tob_T_tip: np.ndarray) -> np.ndarray:
    """Eq. (9) chained: ``a_T_tip = a_T_tob @ tob_T_tip`` (e.g. ``a`` = world for the path
    point P). Stacks broadcast; mm."""
    return compose(a_T_tob, tob_T_tip)


def isosceles_source_positions_mm(leg_mm: float, base_mm: float) -> np.ndarray:
    """Source centres (3, 3) = A, B, C in the TOB frame of an isosceles triangle with legs
    AB = AC = ``leg_mm`` and base BC = ``base_mm``: A = (-2h/3, 0, 0),
    B = (h/3, base/2, 0), C = (h/3, -base/2, 0), h = sqrt(leg^2 - base^2/4)."""
    if not (leg_mm > 0 and base_mm > 0 and 2 * leg_mm > base_mm):
        raise ValueError(
            f"no isosceles triangle with legs {leg_mm} mm and base {base_mm} mm "
            "(need 2 * leg > base > 0)"
        )
    h = math.sqrt(leg_mm**2 - base_mm**2 / 4.0)
    return np.array(
        [[-2.0 * h / 3.0, 0.0, 0.0], [h / 3.0, base_mm / 2.0, 0.0], [h / 3.0, -base_mm / 2.0, 0.0]]
    )


def _sides(p: np.ndarray) -> np.ndarray:
    """(|AB|, |BC|, |CA|) of points (..., 3, 3)."""
    return np.stack(
        [
            np.linalg.norm(p[..., 0, :] - p[..., 1, :], axis=-1),
            np.linalg.norm(p[..., 1, :] - p[..., 2, :], axis=-1),
            np.linalg.norm(p[..., 2, :] - p[..., 0, :], axis=-1),
        ],
        axis=-1,
    )


_DEFAULT_LEG_MM = 40.0
_DEFAULT_BASE_MM = 30.0
_DEFAULT_DRIVER_MM = 60.0
_DEFAULT_POSITIONS = isosceles_source_positions_mm(_DEFAULT_LEG_MM, _DEFAULT_BASE_MM)


def _vec3(name: str, value) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=float).ravel()
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ValueError(f"TargetModel.{name} must be 3 finite numbers (mm), got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True)
class TargetModel:
    """Known geometry of the TOB, in its own frame (mm).

    ``tob_p_a_mm, tob_p_b_mm, tob_p_c_mm``: the source centres, which must already be in
    their own eq. (7) frame (G at the origin, A on -u, B at v > 0, w = 0); build from any
    measured positions with :meth:`from_source_positions`, or use :meth:`isosceles`.
    ``source_diameter_mm``: diameter of the planar sources. ``tob_t_tip_mm``: the driver
    tip P in the TOB frame (eq. (9), ``tob_R_tip = I``), or None when no driver is fitted;
    default (0, 0, 60) - on the w axis, underside. ``side_tolerance_mm``: how far a measured
    side may differ from the model's before :func:`label_sources` rejects the triangle.

    Default: legs 40 mm, base 30 mm, 5 mm sources, 60 mm driver, 3 mm tolerance.
    """

    tob_p_a_mm: tuple[float, float, float] = tuple(_DEFAULT_POSITIONS[0])
    tob_p_b_mm: tuple[float, float, float] = tuple(_DEFAULT_POSITIONS[1])
    tob_p_c_mm: tuple[float, float, float] = tuple(_DEFAULT_POSITIONS[2])
    source_diameter_mm: float = 5.0
    tob_t_tip_mm: tuple[float, float, float] | None = (0.0, 0.0, _DEFAULT_DRIVER_MM)
    side_tolerance_mm: float = 3.0

    def __post_init__(self) -> None:
        for name in ("tob_p_a_mm", "tob_p_b_mm", "tob_p_c_mm"):
            object.__setattr__(self, name, _vec3(name, getattr(self, name)))
        if self.tob_t_tip_mm is not None:
            object.__setattr__(self, "tob_t_tip_mm", _vec3("tob_t_tip_mm", self.tob_t_tip_mm))
        for name in ("source_diameter_mm", "side_tolerance_mm"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"TargetModel.{name} must be finite and > 0, got {value}")
            object.__setattr__(self, name, value)
        pts = self.source_positions_mm
        sides = _sides(pts)
        object.__setattr__(self, "_sides_mm", tuple(sides.tolist()))  # for label_sources
        if np.min(sides) <= self.source_diameter_mm:
            raise ValueError(
                f"TargetModel: sides {np.round(sides, 3).tolist()} mm must exceed the source "
                f"diameter {self.source_diameter_mm} mm (the sources would overlap)"
            )
        try:
            frame = tob_frame_from_points(pts[0], pts[1], pts[2])
        except GeometryError as exc:
            raise ValueError(f"TargetModel: the sources do not form a triangle: {exc}") from None
        if np.max(np.abs(frame - np.eye(4))) > 1e-9 * max(1.0, float(np.max(sides))):
            raise ValueError(
                "TargetModel: source positions are not in their own eq. (7) frame "
                "(G at the origin, A on -u, B at v > 0, in the plane w = 0); use "
                "TargetModel.from_source_positions(...)"
            )
        # The labelling must be unique: every other cyclic naming (same orientation) must
        # miss the model's sides by more than twice the tolerance.
        for shift in (1, 2):
            other = _sides(np.roll(pts, shift, axis=0))
            miss = float(np.max(np.abs(other - sides)))
            if miss <= 2.0 * self.side_tolerance_mm:
                raise ValueError(
                    f"TargetModel: sides {np.round(sides, 3).tolist()} mm cannot be labelled "
                    f"with tolerance {self.side_tolerance_mm} mm (a relabelling differs by "
                    f"only {miss:.3f} mm; an equilateral triangle is never labellable): make "
                    "the base differ from the legs by more than 2x the tolerance"
                )

    @classmethod
    def isosceles(
        cls,
        leg_mm: float = _DEFAULT_LEG_MM,
        base_mm: float = _DEFAULT_BASE_MM,
        source_diameter_mm: float = 5.0,
        driver_length_mm: float | None = _DEFAULT_DRIVER_MM,
        side_tolerance_mm: float = 3.0,
    ) -> TargetModel:
        """Isosceles TOB: legs AB = AC, base BC, driver tip on the w axis at
        ``driver_length_mm`` from G (None: no driver)."""
        pts = isosceles_source_positions_mm(leg_mm, base_mm)
        tip = None if driver_length_mm is None else (0.0, 0.0, float(driver_length_mm))
        return cls(
            tuple(pts[0]), tuple(pts[1]), tuple(pts[2]), source_diameter_mm, tip, side_tolerance_mm
        )

    @classmethod
    def from_source_positions(
        cls, p_a_mm, p_b_mm, p_c_mm, world_p_tip_mm=None, **kwargs
    ) -> TargetModel:
        """Build a model from labelled source centres measured in any frame (mm), e.g. on a
        measuring machine; they are re-expressed in their own eq. (7) frame. An optional
        tip position in the same frame becomes ``tob_t_tip_mm``."""
        tob_T_frame = invert_transform(tob_frame_from_points(p_a_mm, p_b_mm, p_c_mm))
        pts = transform_points(tob_T_frame, np.array([p_a_mm, p_b_mm, p_c_mm], dtype=float))
        # Exact zeros where eq. (7) puts them (rounding leaves ~1e-15).
        pts[0, 1:] = 0.0
        pts[1:, 2] = 0.0
        if world_p_tip_mm is not None:
            kwargs["tob_t_tip_mm"] = tuple(transform_points(tob_T_frame, world_p_tip_mm))
        return cls(tuple(pts[0]), tuple(pts[1]), tuple(pts[2]), **kwargs)

    @property
    def source_positions_mm(self) -> np.ndarray:
        """(3, 3) array, rows A, B, C in the TOB frame (mm)."""
        return np.array([self.tob_p_a_mm, self.tob_p_b_mm, self.tob_p_c_mm])

    @property
    def sides_mm(self) -> np.ndarray:
        """(|AB|, |BC|, |CA|) in mm."""
        return _sides(self.source_positions_mm)

    @property
    def has_driver(self) -> bool:
        return self.tob_t_tip_mm is not None

    @property
    def tob_T_tip(self) -> np.ndarray:
        """Eq. (9): ``tob_T_tip`` (4, 4), identity rotation (the tip frame is parallel to the
        TOB frame by definition). Raises :class:`GeometryError` without a driver."""
        if self.tob_t_tip_mm is None:
            raise GeometryError("this TargetModel has no driver (tob_t_tip_mm is None)")
        return make_transform(np.eye(3), np.array(self.tob_t_tip_mm))

    def with_tip(self, tob_t_tip_mm) -> TargetModel:
        """A copy with another driver tip (e.g. from a calibration)."""
        return replace(self, tob_t_tip_mm=None if tob_t_tip_mm is None else tuple(tob_t_tip_mm))


@dataclass(frozen=True)
class Labelling:
    """Result of :func:`label_sources`.

    ``order``: indices into the input rows giving A, B, C; ``camera_p_abc_mm``: (3, 3) the
    points as A, B, C; ``sides_mm``: their (|AB|, |BC|, |CA|); ``side_error_mm``: the largest
    |measured - model| side difference.
    """

    order: tuple[int, int, int]
    camera_p_abc_mm: np.ndarray
    sides_mm: np.ndarray
    side_error_mm: float


def label_sources(
    model: TargetModel,
    camera_p_mm: np.ndarray,
    viewpoint_mm=(0.0, 0.0, 0.0),
    side_tolerance_mm: float | None = None,
) -> Labelling:
    """Name three measured source centres (3, 3), in any order, as A, B, C.

    Section 4: the apex A (and the base) follow from the side lengths, B and C from the
    orientation - B is the one that makes ``w = GB x GA`` point away from ``viewpoint_mm``
    (the camera's optical centre, the origin of the camera frame by default), i.e. into the
    TOB's underside. Of the three namings with that orientation the one whose sides best
    match the model's is chosen.

    Raises :class:`GeometryError` when the points coincide or are collinear, when the
    triangle is seen edge-on, when the best naming's sides differ from the model's by more
    than the tolerance (``model.side_tolerance_mm`` unless given), and when two namings fit
    (ambiguous).
    """
    p = np.asarray(camera_p_mm, dtype=float)
    if p.shape != (3, 3):
        raise ValueError(f"label_sources needs exactly three points (3, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise GeometryError("source points are not finite")
    tol = model.side_tolerance_mm if side_tolerance_mm is None else float(side_tolerance_mm)
    lab = _label_single(model, p, viewpoint_mm, tol)
    if lab is not None:
        return lab
    sides = _sides(p)
    if np.min(sides) < 1e-9:
        raise GeometryError(f"two light sources coincide (sides {sides.tolist()} mm)")
    g = p.mean(axis=0)
    normal = np.cross(p[1] - p[0], p[2] - p[0])
    sine = np.linalg.norm(normal) / (sides[0] * sides[2])
    if sine < COLLINEAR_SINE_TOL:
        raise GeometryError(
            f"light sources are collinear (sides {np.round(sides, 4).tolist()} mm): "
            "not a target triangle"
        )
    line_of_sight = g - np.asarray(viewpoint_mm, dtype=float)
    facing = float(np.dot(normal, line_of_sight)) / (
        np.linalg.norm(normal) * np.linalg.norm(line_of_sight)
    )
    if abs(facing) < 1e-6:
        raise GeometryError("the target triangle is seen edge-on: B and C cannot be told apart")
    model_sides = model.sides_mm
    candidates = []
    for order in itertools.permutations(range(3)):
        q = p[list(order)]
        w = np.cross(q[1] - g, q[0] - g)
        if np.dot(w, line_of_sight) <= 0:
            continue
        s = _sides(q)
        candidates.append((float(np.max(np.abs(s - model_sides))), order, q, s))
    candidates.sort(key=lambda c: c[0])
    best_err, order, q, s = candidates[0]
    if best_err > tol:
        raise GeometryError(
            f"measured triangle does not match the target: sides "
            f"{np.round(np.sort(sides), 3).tolist()} mm vs model "
            f"{np.round(np.sort(model_sides), 3).tolist()} mm (best naming off by "
            f"{best_err:.3f} mm > tolerance {tol} mm)"
        )
    if len(candidates) > 1 and candidates[1][0] <= tol:
        raise GeometryError(
            f"ambiguous labelling: two namings of the sources fit the model within {tol} mm "
            f"(errors {best_err:.3f} and {candidates[1][0]:.3f} mm)"
        )
    return Labelling(tuple(int(i) for i in order), q, s, best_err)


_PERMUTATIONS = tuple(itertools.permutations(range(3)))


def _label_single(model: TargetModel, p: np.ndarray, viewpoint_mm, tol: float):
    """:func:`label_sources` in plain float arithmetic (the array code's operations in the
    same order, so the same numbers): the Labelling, or None when the array code has to
    decide (it raises with the message)."""
    pts = p.tolist()
    vx, vy, vz = np.asarray(viewpoint_mm, dtype=float).reshape(3).tolist()
    # side k joins point k and point k + 1; |p_i - p_j| == |p_j - p_i| exactly
    d01 = _norm3(pts[0][0] - pts[1][0], pts[0][1] - pts[1][1], pts[0][2] - pts[1][2])
    d12 = _norm3(pts[1][0] - pts[2][0], pts[1][1] - pts[2][1], pts[1][2] - pts[2][2])
    d20 = _norm3(pts[2][0] - pts[0][0], pts[2][1] - pts[0][1], pts[2][2] - pts[0][2])
    if not min(d01, d12, d20) >= 1e-9:
        return None
    dist = ((0.0, d01, d20), (d01, 0.0, d12), (d20, d12, 0.0))
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = pts
    gx, gy, gz = (ax + bx + cx) / 3.0, (ay + by + cy) / 3.0, (az + bz + cz) / 3.0
    ux, uy, uz = bx - ax, by - ay, bz - az
    wx, wy, wz = cx - ax, cy - ay, cz - az
    nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    n_norm = _norm3(nx, ny, nz)
    if not n_norm / (d01 * d20) >= COLLINEAR_SINE_TOL:
        return None
    lx, ly, lz = gx - vx, gy - vy, gz - vz
    facing = (nx * lx + ny * ly + nz * lz) / (n_norm * _norm3(lx, ly, lz))
    if not abs(facing) >= 1e-6:
        return None
    m0, m1, m2 = model._sides_mm
    candidates = []
    for order in _PERMUTATIONS:
        i, j, k = order
        qi, qj = pts[i], pts[j]
        rx, ry, rz = qj[0] - gx, qj[1] - gy, qj[2] - gz  # q1 - g
        sx, sy, sz = qi[0] - gx, qi[1] - gy, qi[2] - gz  # q0 - g
        w0, w1, w2 = ry * sz - rz * sy, rz * sx - rx * sz, rx * sy - ry * sx
        if w0 * lx + w1 * ly + w2 * lz <= 0:
            continue
        s = (dist[i][j], dist[j][k], dist[k][i])
        err = max(abs(s[0] - m0), abs(s[1] - m1), abs(s[2] - m2))
        candidates.append((err, order, s))
    if not candidates:
        return None
    candidates.sort(key=lambda c: c[0])
    best_err, order, s = candidates[0]
    if not best_err <= tol or (len(candidates) > 1 and candidates[1][0] <= tol):
        return None
    return Labelling(order, p[list(order)], np.array(s), best_err)


def estimate_camera_T_tob(
    model: TargetModel, camera_p_mm: np.ndarray, viewpoint_mm=(0.0, 0.0, 0.0)
) -> tuple[np.ndarray, Labelling]:
    """Section 4 steps 6-7: label three measured source centres (3, 3, any order, camera
    frame, mm) and build ``camera_T_tob`` by eq. (7), (8). Returns (camera_T_tob (4, 4),
    :class:`Labelling`)."""
    lab = label_sources(model, camera_p_mm, viewpoint_mm)
    q = lab.camera_p_abc_mm
    return tob_frame_from_points(q[0], q[1], q[2]), lab
