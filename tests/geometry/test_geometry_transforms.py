"""Transforms, chains, Z-Y-X angles and the six-vector X."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from scipy.spatial.transform import Rotation, Slerp

from humanpt.geometry import (
    GeometryError,
    apply_step,
    chain_world_T_tob,
    check_rigid,
    compose,
    interpolate_transform,
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    rotation_angle_rad,
    rotation_from_ypr_deg,
    rotvec_from_matrix,
    slerp,
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


def _rz(angle_rad: float) -> np.ndarray:
    """Rotation about z by hand (the oracle of the rotation-vector tests)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_rotation_vectors_by_hand():
    # exp: a rotation vector along z of length a is Rz(a); log the way back; its angle a.
    for a in (0.0, 1e-9, 0.3, 2.0, np.pi - 1e-9):
        np.testing.assert_allclose(matrix_from_rotvec([0.0, 0.0, a]), _rz(a), atol=1e-15)
        np.testing.assert_allclose(rotvec_from_matrix(_rz(a)), [0.0, 0.0, a], atol=1e-12)
        assert rotation_angle_rad(_rz(a)) == pytest.approx(a, abs=1e-12)
        assert rotation_angle_rad(_rz(-a), assume_valid=True) == pytest.approx(a, abs=1e-12)
    # any axis: R = Rz(a) in a frame whose z is that axis
    rng = np.random.default_rng(2)
    for _ in range(50):
        q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        q *= np.sign(np.linalg.det(q))
        a = rng.uniform(0.0, 3.0)
        expected = q @ _rz(a) @ q.T
        np.testing.assert_allclose(matrix_from_rotvec(q[:, 2] * a), expected, atol=1e-12)
        np.testing.assert_allclose(rotvec_from_matrix(expected), q[:, 2] * a, atol=1e-9)


def test_slerp_and_interpolation_by_hand():
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        q *= np.sign(np.linalg.det(q))
        r0 = q @ _rz(rng.uniform(-3, 3)) @ q.T @ matrix_from_rotvec(rng.normal(size=3))
        a = rng.uniform(-3.0, 3.0)
        r1 = r0 @ q @ _rz(a) @ q.T  # a turn of a about q's z, in r0's frame
        for s in (0.0, 0.25, 1.0, -0.5, 1.7):
            np.testing.assert_allclose(slerp(r0, r1, s), r0 @ q @ _rz(s * a) @ q.T, atol=1e-12)
        s = rng.uniform(0.0, 1.0)
        scipy_slerp = Slerp([0.0, 1.0], Rotation.from_matrix([r0, r1]))(s).as_matrix()
        np.testing.assert_allclose(slerp(r0, r1, s, assume_valid=True), scipy_slerp, atol=1e-12)
        t0 = make_transform(r0, rng.normal(size=3) * 100)
        t1 = make_transform(r1, rng.normal(size=3) * 100)
        mid = interpolate_transform(t0, t1, s)
        np.testing.assert_allclose(mid[:3, 3], (1 - s) * t0[:3, 3] + s * t1[:3, 3], atol=1e-12)
        np.testing.assert_allclose(mid[:3, :3], scipy_slerp, atol=1e-12)
        np.testing.assert_array_equal(mid[3], [0.0, 0.0, 0.0, 1.0])


def test_apply_step_turns_about_the_origin_in_the_outer_frame():
    t = make_transform(_rz(0.5), [10.0, 0.0, 0.0])
    moved = apply_step(t, np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, 0.25]))
    np.testing.assert_allclose(moved, make_transform(_rz(0.75), [11.0, 2.0, 3.0]), atol=1e-15)
    np.testing.assert_array_equal(t, make_transform(_rz(0.5), [10.0, 0.0, 0.0]))  # not in place


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


@pytest.mark.parametrize("a_deg", [0.0, 180.0, 37.0])
def test_val_oat_is_exact_and_quiet_at_the_gimbal_lock(a_deg, recwarn):
    """VAL II's O, A, T (Z-Y-Z): at A = 0 or 180 only O + T (O - T) is defined and scipy
    warns of a gimbal lock; the angles still give the same rotation (checked against scipy's
    own matrices), so a path written as a VAL II program at a flat torch warns no one."""
    from scipy.spatial.transform import Rotation

    from humanpt.controller.pathfile import to_val2
    from humanpt.geometry.transforms import oat_deg_from_rotation

    r = Rotation.from_euler("ZYZ", [30.0, a_deg, 50.0], degrees=True)
    o, a, t = oat_deg_from_rotation(r)
    assert np.allclose(Rotation.from_euler("ZYZ", [o, a, t], degrees=True).as_matrix(), r.as_matrix(), atol=1e-12)
    assert a == pytest.approx(a_deg, abs=1e-9)
    ypr = r.as_euler("ZYX", degrees=True)
    program = to_val2(np.array([[400.0, 1200.0, 0.0, *ypr]]), "flat")
    assert "TRANS(400.00, 1200.00, 0.00" in program
    assert not [w for w in recwarn if "Gimbal" in str(w.message)], [str(w.message) for w in recwarn]
