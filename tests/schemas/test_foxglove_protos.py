"""The shipped Foxglove .proto files (schemas/foxglove/, from @foxglove/schemas): a plain
protoc compiles them with humanpt.proto, and each message has the fields (name, number,
type, label) of the foxglove-schemas-protobuf classes humanpt publishes."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest
from google.protobuf import descriptor_pb2

from humanpt.schemas import topics
from tests.conftest import ROOT

SCHEMAS = ROOT / "schemas"
# What issue 20 publishes or records as Foxglove types (and their parts): must be shipped.
NEEDED = ["RawImage", "FrameTransform", "FrameTransforms", "PosesInFrame", "PoseInFrame", "Pose", "Vector3",
          "Quaternion", "ImageAnnotations", "CircleAnnotation", "PointsAnnotation", "TextAnnotation",
          "CameraCalibration", "Log", "SceneUpdate", "SceneEntity", "SceneEntityDeletion", "Color", "Point2",
          "Point3", "KeyValuePair", "TriangleListPrimitive", "LinePrimitive"]


@pytest.fixture(scope="module")
def compiled(tmp_path_factory) -> dict[str, descriptor_pb2.DescriptorProto]:
    """foxglove.<Name> -> its DescriptorProto, from protoc over humanpt.proto + foxglove/*.proto."""
    out = tmp_path_factory.mktemp("fg") / "set.pb"
    protos = sorted(str(p.relative_to(SCHEMAS)) for p in (SCHEMAS / "foxglove").glob("*.proto"))
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", f"-I{SCHEMAS}", f"--descriptor_set_out={out}",
                    "humanpt.proto", *protos], check=True, cwd=SCHEMAS)
    fds = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes())
    return {f"{f.package}.{m.name}": m for f in fds.file for m in f.message_type}


def _fields(m: descriptor_pb2.DescriptorProto) -> dict[str, tuple]:
    return {f.name: (f.number, f.type, f.label, f.type_name.lstrip(".")) for f in m.field}


def test_needed_messages_are_shipped(compiled):
    missing = [n for n in NEEDED if f"foxglove.{n}" not in compiled]
    assert not missing, f"schemas/foxglove/ lacks {missing}"
    assert "humanpt.Tick" in compiled  # humanpt.proto compiled in the same run


@pytest.mark.parametrize("name", NEEDED)
def test_fields_match_the_python_classes(compiled, name):
    """Same wire format as the class humanpt encodes with (foxglove-schemas-protobuf)."""
    mod = importlib.import_module(f"foxglove_schemas_protobuf.{name}_pb2")
    theirs = descriptor_pb2.DescriptorProto()
    getattr(mod, name).DESCRIPTOR.CopyToProto(theirs)
    ours, want = _fields(compiled[f"foxglove.{name}"]), _fields(theirs)
    # A field the newer .proto adds is fine (old readers skip it); every field the Python
    # class writes must be there, with the same number and type.
    assert {k: ours.get(k) for k in want} == want


def test_every_foxglove_topic_type_is_shipped(compiled):
    for cls in topics.all_types():
        if cls.DESCRIPTOR.full_name.startswith("foxglove."):
            assert cls.DESCRIPTOR.full_name in compiled
