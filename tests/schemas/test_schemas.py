"""Schemas: generated code is fresh, the topic table is consistent, converters round-trip."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from google.protobuf import descriptor_pb2
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from humanpt.schemas import convert, topics
from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import ROOT


def test_generated_code_is_fresh(tmp_path):
    """Regenerate from schemas/humanpt.proto; the committed module must describe the same file."""
    out = tmp_path / "set.pb"
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", f"-I{ROOT / 'schemas'}", f"--descriptor_set_out={out}",
                    str(ROOT / "schemas" / "humanpt.proto")], check=True)
    fresh = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()).file[0]
    committed = descriptor_pb2.FileDescriptorProto()
    pb.DESCRIPTOR.CopyToProto(committed)
    for fdp in (fresh, committed):  # json_name is derived, and CopyToProto leaves it out
        for m in fdp.message_type:
            for f in m.field:
                f.ClearField("json_name")
    assert committed.SerializeToString(deterministic=True) == fresh.SerializeToString(deterministic=True), ("schemas/humanpt_pb2.py is stale: run  python -m grpc_tools.protoc -Ischemas "
                                "--python_out=schemas --pyi_out=schemas schemas/humanpt.proto")


def test_every_message_has_a_header():
    for cls in topics.all_types():
        if cls.DESCRIPTOR.full_name == "foxglove.RawImage":
            assert "timestamp" in cls.DESCRIPTOR.fields_by_name and "frame_id" in cls.DESCRIPTOR.fields_by_name
            continue
        if cls.DESCRIPTOR.full_name.startswith("foxglove."):  # humanpt.scene: stamped as Foxglove orders
            stamped = [cls.DESCRIPTOR] + [f.message_type for f in cls.DESCRIPTOR.fields if f.message_type]
            assert any(d.fields_by_name.get("timestamp") and d.fields_by_name["timestamp"].message_type.full_name
                       == "google.protobuf.Timestamp" for d in stamped), cls
            continue
        assert cls.DESCRIPTOR.fields_by_name["header"].message_type.full_name == "humanpt.Header", cls


def test_topic_table_is_consistent():
    assert len({t.short for t in topics.TOPICS.values()}) == len(topics.TOPICS)
    for t in topics.TOPICS.values():
        comp, _, name = t.short.partition("/")
        assert comp == t.publisher and name and "/" not in name
        cell, short = topics.short_from_key(t.key("cellA"))
        assert (cell, short) == ("cellA", t.short)
        assert topics.message_type(short) is t.type
    assert topics.message_type("tick") is pb.Tick
    with pytest.raises(topics.UnknownTopicError, match="unknown topic"):
        topics.message_type("nobody/nothing")
    with pytest.raises(topics.UnknownTopicError, match="not a humanpt key"):
        topics.short_from_key("other/cell/x/y")


@settings(max_examples=60, deadline=None)
@given(rotvec=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
       t=st.lists(st.floats(-5.0, 5.0), min_size=3, max_size=3))
def test_pose_round_trip(rotvec, t):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    back = convert.from_pose(pb.Pose.FromString(convert.pose(T).SerializeToString()))
    np.testing.assert_allclose(back, T, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(q=st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 1e-3))
def test_pose_quaternions_agree_with_scipy(q):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(q).as_matrix()
    r = convert.pose(T).rotation
    mine, ref = np.array([r.x, r.y, r.z, r.w]), Rotation.from_matrix(T[:3, :3]).as_quat()
    assert mine[3] >= 0.0
    # q and -q are the same rotation (scipy breaks the w = 0 tie differently).
    assert min(np.abs(mine - ref).max(), np.abs(mine + ref).max()) < 1e-12
    x, y, z, w = q  # not normalised: from_pose normalises
    back = convert.from_pose(pb.Pose(rotation=pb.Quaternion(x=x, y=y, z=z, w=w)))
    np.testing.assert_allclose(back[:3, :3], T[:3, :3], atol=1e-12)


def test_pose_rejects_non_rotation_and_nan():
    T = np.eye(4)
    T[0, 0] = -1.0  # a reflection
    with pytest.raises(convert.MessageError, match="not a proper rotation"):
        convert.pose(T)
    with pytest.raises(convert.MessageError, match="4x4"):
        convert.pose(np.eye(3))
    bad = pb.Pose(translation=pb.Vector3(x=float("nan")))
    with pytest.raises(convert.MessageError, match="non-finite"):
        convert.from_pose(bad)
    np.testing.assert_array_equal(convert.from_pose(pb.Pose()), np.eye(4))  # unset = identity
    # Squares that underflow or overflow: the rotation is still the quaternion's direction.
    for scale in (1e-200, 1e200):
        q = pb.Pose(rotation=pb.Quaternion(x=scale, y=scale))
        np.testing.assert_allclose(convert.from_pose(q)[:3, :3],
                                   Rotation.from_quat([1.0, 1.0, 0.0, 0.0]).as_matrix(), atol=1e-12)


@pytest.mark.parametrize("shape,dtype,enc", [((48, 64), np.uint8, "mono8"), ((48, 64, 3), np.uint8, "rgb8"),
                                             ((48, 64), np.uint16, "mono16")])
def test_image_round_trip(shape, dtype, enc):
    rng = np.random.default_rng(7)
    a = rng.integers(0, np.iinfo(dtype).max, size=shape, dtype=dtype)
    msg = convert.image(a, 123_456_789_012)
    assert msg.encoding == enc and convert.image_stamp_ns(msg) == 123_456_789_012
    msg2 = type(msg).FromString(msg.SerializeToString())
    np.testing.assert_array_equal(convert.from_image(msg2), a)


def test_bad_images_raise_clear_errors():
    good = convert.image(np.zeros((4, 5), np.uint8), 0)
    short = type(good)()
    short.CopyFrom(good)
    short.data = good.data[:-1]
    with pytest.raises(convert.MessageError, match="needs 20"):
        convert.from_image(short)
    odd = type(good)()
    odd.CopyFrom(good)
    odd.encoding = "yuv422"
    with pytest.raises(convert.MessageError, match="unsupported image encoding"):
        convert.from_image(odd)
    with pytest.raises(convert.MessageError, match="empty"):
        convert.from_image(type(good)(encoding="mono8"))
    with pytest.raises(convert.MessageError, match="no image encoding"):
        convert.image(np.zeros((4, 5), np.float32), 0)


def test_vectors_and_covariance_round_trip():
    v = np.array([1.5, -2.0, 3.25])
    np.testing.assert_array_equal(convert.from_vector3(convert.vector3(v)), v)
    P = np.random.default_rng(1).normal(size=(12, 12))
    vals, n = convert.covariance(P)
    np.testing.assert_array_equal(convert.from_covariance(vals, n), P)
    with pytest.raises(convert.MessageError, match="expected 6x6"):
        convert.from_covariance(vals, 6)


def test_pose_from_mm_is_pose_in_metres():
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 1.1]).as_matrix()
    T[:3, 3] = [1200.0, -35.5, 480.25]
    m = T.copy()
    m[:3, 3] /= 1000.0
    assert convert.pose_from_mm(T) == convert.pose(m)
    assert T[0, 3] == 1200.0  # the input is left alone
