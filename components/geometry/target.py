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
    "triangle_sides_mm",
    "COLLINEAR_SINE_TOL",
]

COLLINEAR_SINE_TOL = 1e-6
"""Smallest |sin| of the angle between GA and GB (and of any triangle corner) accepted as a
triangle; below it the points are called collinear."""


def tob_frame_from_points(a_p_a_mm, a_p_b_mm, a_p_c_mm) -> np.ndarray:
    """Eq. (7), (8): ``a_T_tob`` (..., 4, 4) from the labelled source centres A, B, C
    (..., 3) given in any frame ``a`` (normally the camera frame), mm.

    G is the mean of A, B, C; ``W = GB x GA``, ``U = -GA``, ``V = W x U``, normalised.
    Raises :class:`GeometryError` for coincident or collinear points. One triangle is
    computed on plain floats (perception builds one frame per image); a stack, triangle
    by triangle.
    """
    a = np.asarray(a_p_a_mm, dtype=float)
    b = np.asarray(a_p_b_mm, dtype=float)
    c = np.asarray(a_p_c_mm, dtype=float)
    if a.shape[-1:] != (3,) or b.shape[-1:] != (3,) or c.shape[-1:] != (3,):
        raise ValueError("source points must have shape (..., 3)")
    if a.shape == b.shape == c.shape == (3,):
        return np.array(_tob_frame(a.tolist(), b.tolist(), c.tolist()))
    batch = np.broadcast_shapes(a.shape[:-1], b.shape[:-1], c.shape[:-1])
    a, b, c = (np.broadcast_to(x, batch + (3,)).reshape(-1, 3).tolist() for x in (a, b, c))
    frames = [_tob_frame(pa, pb, pc) for pa, pb, pc in zip(a, b, c, strict=True)]
    return np.array(frames).reshape(batch + (4, 4))


def _sub(p, q) -> tuple[float, float, float]:
    return p[0] - q[0], p[1] - q[1], p[2] - q[2]


def _cross(p, q) -> tuple[float, float, float]:
    return p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]


def _dot(p, q) -> float:
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _norm(p) -> float:
    return math.sqrt(_dot(p, p))


def _tob_frame(a: list, b: list, c: list) -> list[list[float]]:
    """Eq. (7), (8) for one triangle (three (x, y, z) lists): the rows of a_T_tob."""
    g = ((a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0)
    r_a, r_b = _sub(a, g), _sub(b, g)
    w = _cross(r_b, r_a)
    u = (-r_a[0], -r_a[1], -r_a[2])
    v = _cross(w, u)
    n_a, n_b, n_w = _norm(r_a), _norm(r_b), _norm(w)
    if not (math.isfinite(n_w) and n_a >= 1e-9 and n_b >= 1e-9):
        raise GeometryError("light sources coincide (or are not finite): no TOB frame")
    sine = n_w / (n_a * n_b)
    if not sine >= COLLINEAR_SINE_TOL:
        raise GeometryError(f"light sources are collinear (|sin(GA, GB)| = {sine:.3g}): no TOB frame")
    n_u, n_v = _norm(u), _norm(v)
    return [
        [u[0] / n_u, v[0] / n_v, w[0] / n_w, g[0]],
        [u[1] / n_u, v[1] / n_v, w[1] / n_w, g[1]],
        [u[2] / n_u, v[2] / n_v, w[2] / n_w, g[2]],
        [0.0, 0.0, 0.0, 1.0],
    ]


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


def triangle_sides_mm(p_mm: np.ndarray) -> np.ndarray:
    """Side lengths (|AB|, |BC|, |CA|) (..., 3) of triangles A, B, C (..., 3, 3), mm."""
    p = np.asarray(p_mm, dtype=float)
    d = p - p[..., [1, 2, 0], :]
    return np.sqrt(np.einsum("...ij,...ij->...i", d, d))


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
        sides = triangle_sides_mm(pts)
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
            other = triangle_sides_mm(np.roll(pts, shift, axis=0))
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
        return np.array(self._sides_mm)

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
    (ambiguous). Three points: plain float arithmetic (perception labels once per image).
    """
    p = np.asarray(camera_p_mm, dtype=float)
    if p.shape != (3, 3):
        raise ValueError(f"label_sources needs exactly three points (3, 3), got {p.shape}")
    pts = p.tolist()
    if not math.isfinite(sum(pts[0] + pts[1] + pts[2])):  # a NaN or an inf spreads to the sum
        raise GeometryError("source points are not finite")
    tol = model.side_tolerance_mm if side_tolerance_mm is None else float(side_tolerance_mm)
    d01 = _norm(_sub(pts[0], pts[1]))
    d12 = _norm(_sub(pts[1], pts[2]))
    d20 = _norm(_sub(pts[2], pts[0]))
    sides = [d01, d12, d20]
    if min(sides) < 1e-9:
        raise GeometryError(f"two light sources coincide (sides {sides} mm)")
    normal = _cross(_sub(pts[1], pts[0]), _sub(pts[2], pts[0]))
    n_norm = _norm(normal)
    if n_norm / (d01 * d20) < COLLINEAR_SINE_TOL:
        raise GeometryError(
            f"light sources are collinear (sides {[round(d, 4) for d in sides]} mm): "
            "not a target triangle"
        )
    g = [(pts[0][k] + pts[1][k] + pts[2][k]) / 3.0 for k in range(3)]
    line_of_sight = _sub(g, np.asarray(viewpoint_mm, dtype=float).reshape(3).tolist())
    facing = _dot(normal, line_of_sight) / (n_norm * _norm(line_of_sight))
    if abs(facing) < 1e-6:
        raise GeometryError("the target triangle is seen edge-on: B and C cannot be told apart")
    # For points named in input order (or any cyclic renaming of it) GB x GA = -normal/3,
    # for the other three namings +normal/3: w points away from the viewpoint for these.
    orders = _CYCLIC if facing < 0 else _ANTICYCLIC
    dist = ((0.0, d01, d20), (d01, 0.0, d12), (d20, d12, 0.0))
    model_sides = model._sides_mm
    m0, m1, m2 = model_sides
    candidates = []
    for i, j, k in orders:
        s = (dist[i][j], dist[j][k], dist[k][i])
        candidates.append((max(abs(s[0] - m0), abs(s[1] - m1), abs(s[2] - m2)), (i, j, k), s))
    candidates.sort(key=lambda c: c[0])
    best_err, order, s = candidates[0]
    if best_err > tol:
        raise GeometryError(
            f"measured triangle does not match the target: sides "
            f"{[round(d, 3) for d in sorted(sides)]} mm vs model "
            f"{[round(m, 3) for m in sorted(model_sides)]} mm (best naming off by "
            f"{best_err:.3f} mm > tolerance {tol} mm)"
        )
    if candidates[1][0] <= tol:
        raise GeometryError(
            f"ambiguous labelling: two namings of the sources fit the model within {tol} mm "
            f"(errors {best_err:.3f} and {candidates[1][0]:.3f} mm)"
        )
    return Labelling(order, p[list(order)], np.array(s), best_err)


_CYCLIC = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
_ANTICYCLIC = ((0, 2, 1), (1, 0, 2), (2, 1, 0))


def estimate_camera_T_tob(
    model: TargetModel, camera_p_mm: np.ndarray, viewpoint_mm=(0.0, 0.0, 0.0)
) -> tuple[np.ndarray, Labelling]:
    """Section 4 steps 6-7: label three measured source centres (3, 3, any order, camera
    frame, mm) and build ``camera_T_tob`` by eq. (7), (8). Returns (camera_T_tob (4, 4),
    :class:`Labelling`)."""
    lab = label_sources(model, camera_p_mm, viewpoint_mm)
    q = lab.camera_p_abc_mm
    return tob_frame_from_points(q[0], q[1], q[2]), lab
