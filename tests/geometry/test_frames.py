"""The cell's frame graph and its time-stamped pose buffer (geometry.frames), against hand
calculations and scipy: interpolation (linear translation, scipy's Slerp rotation), each
named policy at, between and beyond the samples, bounded memory, lookups through the tree
equal to the chains written out by hand (bit for bit: recordings depend on it), and the
smooth batch track against a cubic it must reproduce."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from humanpt.geometry import GeometryError, invert_transform, transform_from_x
from humanpt.geometry.frames import (
    NEAREST_HOLD,
    SAMPLE_HOLD_HOLD,
    SAMPLE_HOLD_REFUSE,
    Backwards,
    Between,
    FrameGraph,
    Lookup,
    Outside,
    Repeat,
    TimedPoses,
    segment_reach,
    smooth_poses_at,
)


def _turn_z(angle_deg: float, x: float) -> np.ndarray:
    """A turn about z by ``angle_deg`` at (x, 0, 5), by hand."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    return np.array([[c, -s, 0.0, x], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 5.0], [0.0, 0.0, 0.0, 1.0]])


def _three() -> TimedPoses:
    """Samples at 100, 200, 300: 10, 30, 30 deg about z at x = 0, 20, 20."""
    buf = TimedPoses(8)
    for t, angle, x in ((100, 10.0, 0.0), (200, 30.0, 20.0), (300, 30.0, 20.0)):
        assert buf.add(t, _turn_z(angle, x))
    return buf


def test_interpolation_is_linear_in_translation_and_scipy_slerp_in_rotation():
    a = transform_from_x(np.array([10.0, -20.0, 30.0, 40.0, -25.0, 70.0]))
    b = transform_from_x(np.array([-5.0, 60.0, 0.0, -100.0, 10.0, 150.0]))
    buf = TimedPoses(4)
    buf.add(1_000, a)
    buf.add(5_000, b)
    got = buf.at(2_000, SAMPLE_HOLD_REFUSE)  # a quarter of the way
    want_r = Slerp([0.0, 1.0], Rotation.from_matrix([a[:3, :3], b[:3, :3]]))(0.25).as_matrix()
    np.testing.assert_allclose(got[:3, :3], want_r, atol=1e-12)
    np.testing.assert_allclose(got[:3, 3], 0.75 * a[:3, 3] + 0.25 * b[:3, 3], atol=1e-12)


@pytest.mark.parametrize(
    ("lookup", "stamp", "want"),
    [
        # the truth (sim_camera): held before, refused after, a sample on its stamp
        (SAMPLE_HOLD_REFUSE, 50, (10.0, 0.0)),
        (SAMPLE_HOLD_REFUSE, 150, (20.0, 10.0)),
        (SAMPLE_HOLD_REFUSE, 200, (30.0, 20.0)),
        (SAMPLE_HOLD_REFUSE, 301, None),
        (SAMPLE_HOLD_HOLD, 999, (30.0, 20.0)),
        # the viewer: the nearest sample, the earlier on a tie, held at both ends
        (NEAREST_HOLD, 149, (10.0, 0.0)),
        (NEAREST_HOLD, 150, (10.0, 0.0)),
        (NEAREST_HOLD, 151, (30.0, 20.0)),
        (NEAREST_HOLD, 0, (10.0, 0.0)),
        (NEAREST_HOLD, 400, (30.0, 20.0)),
        # the pose filter: on at the end segment's rates within the reach, None beyond
        (segment_reach(60), 50, (0.0, -10.0)),
        (segment_reach(60), 40, (-2.0, -12.0)),
        (segment_reach(60), 39, None),
        (segment_reach(60), 360, (30.0, 20.0)),
        (segment_reach(60), 361, None),
        (segment_reach(0), 250, (30.0, 20.0)),
        (Lookup(Between.SAMPLE, Outside.REFUSE, Outside.HOLD), 99, None),
    ],
)
def test_each_policy_by_hand(lookup, stamp, want):
    got = _three().at(stamp, lookup)
    if want is None:
        assert got is None
    else:
        np.testing.assert_allclose(got, _turn_z(*want), atol=1e-12)


def test_a_single_sample_and_an_empty_buffer():
    buf = TimedPoses(4)
    assert buf.at(0, NEAREST_HOLD) is None and buf.latest is None and buf.last_ns is None
    buf.add(100, _turn_z(10.0, 1.0))
    for lookup, stamp, held in ((segment_reach(5), 105, True), (segment_reach(5), 94, False),
                                (SAMPLE_HOLD_REFUSE, 100, True), (SAMPLE_HOLD_REFUSE, 101, False),
                                (SAMPLE_HOLD_REFUSE, 0, True)):
        got = buf.at(stamp, lookup)
        assert (got is not None) == held, (lookup, stamp)
        if held:
            np.testing.assert_array_equal(got, _turn_z(10.0, 1.0))


def test_repeats_and_earlier_stamps_follow_their_policies():
    a, b, c = _turn_z(0.0, 0.0), _turn_z(90.0, 1.0), _turn_z(45.0, 2.0)
    refuse = TimedPoses(4)
    assert refuse.add(10, a) and not refuse.add(10, b) and not refuse.add(5, b)
    np.testing.assert_array_equal(refuse.at(10, SAMPLE_HOLD_REFUSE), a)
    replace = TimedPoses(4, repeat=Repeat.REPLACE, backwards=Backwards.RESTART)
    replace.add(10, a)
    assert replace.add(10, b) and len(replace) == 1
    np.testing.assert_array_equal(replace.at(10, SAMPLE_HOLD_REFUSE), b)
    assert replace.add(5, c) and len(replace) == 1 and replace.first_ns == 5  # a restarted source
    keep = TimedPoses(4, repeat=Repeat.KEEP, backwards=Backwards.RESTART)
    keep.add(10, a)
    keep.add(10, b)
    assert len(keep) == 2
    np.testing.assert_array_equal(keep.at(10, NEAREST_HOLD), a)  # the first of the two
    np.testing.assert_array_equal(keep.at(11, segment_reach(5)), b)  # no segment between them


def test_memory_is_bounded_and_forget_before_keeps_what_later_stamps_need():
    buf = TimedPoses(3)
    for t in range(10):
        buf.add(t * 10, _turn_z(t, 0.0))
    assert len(buf) == 3 and buf.first_ns == 70 and buf.last_ns == 90
    buf.forget_before(85)  # 80 is the last at or before 85: kept
    assert len(buf) == 2 and buf.first_ns == 80
    assert buf.covers(90) and not buf.covers(91)
    with pytest.raises(ValueError, match="maxlen"):
        TimedPoses(0)
    with pytest.raises(ValueError, match="reach"):
        segment_reach(-1)


def _cell() -> tuple[FrameGraph, dict[str, np.ndarray]]:
    T = {
        "world_T_base": transform_from_x(np.array([100.0, 0.0, 50.0, 30.0, 0.0, 0.0])),
        "flange_T_camera": transform_from_x(np.array([0.0, 80.0, 40.0, 0.0, 90.0, -90.0])),
        "camera_T_right": transform_from_x(np.array([-30.0, 0.0, 10.0, 5.0, 0.0, 0.0])),
        "camera_T_left": transform_from_x(np.array([30.0, 0.0, 10.0, -5.0, 0.0, 0.0])),
        "tob_T_tip": transform_from_x(np.array([0.0, 0.0, 120.0, 0.0, 0.0, 0.0])),
        "world_T_flange": transform_from_x(np.array([500.0, -200.0, 700.0, 10.0, 170.0, 20.0])),
        "world_T_tob": transform_from_x(np.array([450.0, -150.0, 100.0, 45.0, 5.0, 180.0])),
    }
    g = FrameGraph("world")
    g.add_static("world", "base", T["world_T_base"])
    g.add_timed("world", "flange", TimedPoses(4), SAMPLE_HOLD_REFUSE).add(0, T["world_T_flange"])
    g.add_static("flange", "camera", T["flange_T_camera"])
    g.add_static("camera", "right", T["camera_T_right"])
    g.add_static("camera", "left", T["camera_T_left"])
    g.add_timed("world", "tob", TimedPoses(4), SAMPLE_HOLD_REFUSE).add(0, T["world_T_tob"])
    g.add_static("tob", "tip", T["tob_T_tip"])
    return g, T


def test_lookups_are_the_chains_written_out_by_hand_bit_for_bit():
    g, T = _cell()
    world_T_camera = T["world_T_flange"] @ T["flange_T_camera"]
    cases = {
        ("world", "camera"): world_T_camera,
        ("camera", "tob"): invert_transform(world_T_camera) @ T["world_T_tob"],
        ("base", "flange"): invert_transform(T["world_T_base"]) @ T["world_T_flange"],
        ("flange", "camera"): T["flange_T_camera"],  # a parent-child lookup is the edge
        ("right", "left"): invert_transform(T["camera_T_right"]) @ T["camera_T_left"],
        ("tip", "world"): invert_transform(T["world_T_tob"] @ T["tob_T_tip"]),
        ("world", "world"): np.eye(4),
    }
    for (a, b), want in cases.items():
        np.testing.assert_array_equal(g.lookup(a, b, 0), want, err_msg=f"{a}_T_{b}")
    # and the geometry: the tip seen from the camera, by the inverse chain
    np.testing.assert_allclose(g.lookup("camera", "tip", 0) @ g.lookup("tip", "camera", 0), np.eye(4), atol=1e-12)
    assert g.path("left") == ("world", "flange", "camera", "left")
    assert g.edges[:2] == (("world", "base"), ("world", "flange"))


def test_a_timed_edge_without_a_pose_makes_the_lookup_none_and_bad_use_is_named():
    g, _ = _cell()
    assert g.lookup("camera", "tob", 1) is None  # the truth is never extrapolated
    assert g.lookup("flange", "left", 1) is not None  # no timed edge on the way
    with pytest.raises(GeometryError, match="'hand'"):
        g.lookup("world", "hand", 0)
    with pytest.raises(GeometryError, match="needs a stamp"):
        g.lookup("world", "camera")
    with pytest.raises(GeometryError, match="already hangs from 'flange'"):
        g.add_static("world", "camera", np.eye(4))
    with pytest.raises(GeometryError, match="root"):
        g.add_static("base", "world", np.eye(4))
    with pytest.raises(GeometryError, match=r"\(4, 4\)"):
        g.add_static("base", "tool", np.eye(3))
    g.add_static("flange", "camera", np.eye(4))  # a new value of a fixed edge (a new hand-eye)
    np.testing.assert_array_equal(g.lookup("flange", "camera"), np.eye(4))


def test_the_smooth_track_reproduces_a_cubic_and_a_constant_turn_and_clamps():
    t = np.array([0.0, 0.1, 0.25, 0.3, 0.5, 0.8])
    poses = np.array([_turn_z(100.0 * ti, 0.0) for ti in t])
    poses[:, :3, 3] = np.stack([t**3 - t, 2 * t**2, 1.0 + 0 * t], axis=1)
    q = np.array([-0.2, 0.05, 0.4, 0.79, 1.5])
    got = smooth_poses_at(t, poses, q)
    qc = np.clip(q, 0.0, 0.8)
    np.testing.assert_allclose(got[:, :3, 3], np.stack([qc**3 - qc, 2 * qc**2, 1.0 + 0 * qc], axis=1), atol=1e-12)
    np.testing.assert_allclose(got[:, :3, :3], [_turn_z(100.0 * x, 0.0)[:3, :3] for x in qc], atol=1e-12)
