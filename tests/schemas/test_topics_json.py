"""schemas/topics.json, the topic table as data for clients in any language: fresh, shipped
as package data, and every type it names is defined by the shipped .proto files."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import resources

from google.protobuf import descriptor_pb2

from humanpt.schemas import topics
from tests.conftest import ROOT

SCHEMAS = ROOT / "schemas"


def test_committed_table_is_fresh():
    committed = (SCHEMAS / "topics.json").read_text()
    assert committed == topics.table_json(), (
        "schemas/topics.json is stale: run  python -m humanpt.schemas.topics --write")


def test_shipped_as_package_data():
    data = json.loads(resources.files("humanpt.schemas").joinpath("topics.json").read_text())
    assert {r["short"] for r in data["topics"]} == set(topics.TOPICS)
    pyproject = (ROOT / "pyproject.toml").read_text()
    for pattern in ('"topics.json"', '"foxglove/*.proto"'):
        assert pattern in pyproject, f"{pattern} is not package data"


def test_types_resolve_from_the_proto_files_alone(tmp_path):
    """What a non-Python client does: compile the .proto each row names, look the type up."""
    data = json.loads((SCHEMAS / "topics.json").read_text())
    rows = data["topics"] + data["local_topics"]
    protos = sorted({r["proto"] for r in rows})
    out = tmp_path / "set.pb"
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", f"-I{SCHEMAS}", f"--descriptor_set_out={out}",
                    *protos], check=True, cwd=SCHEMAS)
    fds = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes())
    defined = {(f.name, f"{f.package}.{m.name}") for f in fds.file for m in f.message_type}
    for r in rows:
        assert (r["proto"], r["type"]) in defined, r
    for r in data["topics"]:
        cell_key = r["key"].format(cell="cellA")
        assert topics.short_from_key(cell_key) == ("cellA", r["short"])
        assert not r["local"]
    assert all(r["local"] and "/" not in r["short"] for r in data["local_topics"])
    # every event publisher's events topic is a row
    assert {f"{c}/events" for c in data["event_publishers"]} <= {r["short"] for r in data["topics"]}
