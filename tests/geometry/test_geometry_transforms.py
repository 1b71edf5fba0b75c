"""Transforms, chains, Z-Y-X angles and the six-vector X."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from scipy.spatial.transform import Rotation

from humanpt.geometry import (
    GeometryError,
    chain_world_T_tob,
    check_rigid,
    compose,
    invert_transform,
    make_transform,
    position_quaternion_from_transform,
    rotation_from_ypr_deg,
    transform_from_position_quaternion,
    transform_from_x,
    transform_points,
    x_from_transform,
    ypr_deg_from_rotation,
)

from .geometry_strategies import finite, rigid_transforms


def test_ypr_is_rz_ry_rx():
    psi, theta, phi = 30.0, -20.0, 75.0
    rz = Rotation.from_rotvec([0, 0, np.radians(psi)]).as_matrix()
    ry = Rotation.from_rotvec([0, np.radians(theta), 0]).as_matrix()
    rx = Rotation.from_rotvec([np.radians(phi), 0, 0]).as_matrix()
    np.testing.assert_allclose(rotation_from_ypr_deg([psi, theta, phi]), rz @ ry @ rx, atol=1e-15)
    np.testing.assert_allclose(ypr_deg_from_rotation(rz @ ry @ rx), [psi, theta, phi], atol=1e-12)


@settings(deadline=None, max_examples=100)
@given(
    x=finite(-2000, 2000),
    y=finite(-2000, 2000),
    z=finite(-2000, 2000),
    psi=finite(-179.9, 179.9),
    theta=finite(-89.0, 89.0),
    phi=finite(-179.9, 179.9),
)
def test_x_round_trip(x, y, z, psi, theta, phi):
    vec = np.array([x, y, z, psi, theta, phi])
    t = transform_from_x(vec)
    check_rigid(t, tol=1e-12)
    np.testing.assert_allclose(x_from_transform(t), vec, rtol=0, atol=1e-9)


@settings(deadline=None, max_examples=60)
@given(a=rigid_transforms(), b=rigid_transforms(), c=rigid_transforms())
def test_chain_inverse_and_points(a, b, c):
    chain = chain_world_T_tob(a, b, c)
    np.testing.assert_allclose(chain, a @ b @ c, atol=1e-9)
    np.testing.assert_allclose(compose(chain, invert_transform(chain)), np.eye(4), atol=1e-9)
    np.testing.assert_allclose(invert_transform(a), np.linalg.inv(a), atol=1e-9)
    p = np.array([12.0, -7.0, 300.0])
    np.testing.assert_allclose(
        transform_points(chain, p),
        transform_points(a, transform_points(b, transform_points(c, p))),
        atol=1e-9,
    )


@settings(deadline=None, max_examples=60)
@given(t=rigid_transforms())
def test_position_quaternion_round_trip_metres(t):
    pos_m, q = position_quaternion_from_transform(t)
    np.testing.assert_allclose(pos_m * 1000.0, t[:3, 3], atol=1e-12)
    assert q[3] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
    np.testing.assert_allclose(transform_from_position_quaternion(pos_m, q), t, atol=1e-12)


def test_quaternion_boundary_checks():
    with pytest.raises(GeometryError, match="zero"):
        transform_from_position_quaternion([0, 0, 0], [0, 0, 0, 0])
    t = transform_from_position_quaternion([0.1, 0.2, 0.3], [0, 0, 0, 2.0])  # normalised
    np.testing.assert_allclose(t, make_transform(np.eye(3), [100.0, 200.0, 300.0]))


def test_stacks_broadcast():
    rng = np.random.default_rng(1)
    xs = np.column_stack([rng.uniform(-500, 500, (10, 3)), rng.uniform(-80, 80, (10, 3))])
    ts = transform_from_x(xs)
    assert ts.shape == (10, 4, 4)
    np.testing.assert_allclose(x_from_transform(ts), xs, atol=1e-9)
    np.testing.assert_allclose(
        compose(ts, invert_transform(ts)), np.broadcast_to(np.eye(4), ts.shape), atol=1e-9
    )


def test_check_rigid_rejects_bad_matrices():
    t = np.eye(4)
    t[:3, :3] *= 1.01
    with pytest.raises(GeometryError, match="orthonormal"):
        check_rigid(t)
    refl = np.diag([1.0, 1.0, -1.0, 1.0])
    with pytest.raises(GeometryError, match="reflection"):
        check_rigid(refl)
    bottom = np.eye(4)
    bottom[3, 0] = 1.0
    with pytest.raises(GeometryError, match="last row"):
        check_rigid(bottom)
    with pytest.raises(GeometryError, match="non-finite"):
        check_rigid(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        invert_transform(np.eye(3))
