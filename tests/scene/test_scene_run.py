"""The scene component in a lock-step run, merged with ``humanpt runs merge``: its channels
carry Foxglove's own schemas (checked against Foxglove's .proto files, schemas/foxglove) and
their content agrees with the humanpt messages they come from and with the rig."""

from __future__ import annotations

import math
import tomllib
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pb2
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from scipy.spatial.transform import Rotation

from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli_here

pytestmark = pytest.mark.timeout(120)

DATA = Path(__file__).parents[2] / "schemas"  # schemas/foxglove: Foxglove's own .proto files (their README)
CELL = "humanpt/cell0/"
# scene topic -> Foxglove schema name (issue 20 item 1)
FOXGLOVE = {
    "scene/transforms": "foxglove.FrameTransforms",
    "scene/path": "foxglove.PosesInFrame",
    "scene/path_points": "foxglove.PointCloud",
    "scene/annotations": "foxglove.ImageAnnotations",
    "scene/calibration": "foxglove.CameraCalibration",
    "scene/log": "foxglove.Log",
    "scene/entities": "foxglove.SceneUpdate",
}


class Run:
    """A merged lock-step run, decoded: short topic -> [(log_time_ns, message)], schemas."""

    def __init__(self, run_dir: Path, merged: Path):
        self.run_dir = run_dir
        self.messages: dict[str, list] = defaultdict(list)
        self.schemas: dict[str, tuple[str, bytes]] = {}  # short topic -> (schema name, data)
        with open(merged, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for schema, channel, message, decoded in reader.iter_decoded_messages():
                short = channel.topic.removeprefix(CELL)
                self.schemas[short] = (schema.name, schema.data)
                self.messages[short].append((message.log_time, decoded))

    def of(self, short: str) -> list:
        return [m for _, m in self.messages[short]]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Run:
    d = tmp_path_factory.mktemp("scene")
    run_dir, merged = d / "run", d / "merged.mcap"
    r = run_cli_here("demo", "--lockstep", "--scenario", "arc", "--duration", "4", "--run-dir", str(run_dir))
    assert r.returncode == 0, r.stderr
    r = run_cli_here("runs", "merge", str(run_dir), str(merged))
    assert r.returncode == 0, r.stderr
    return Run(run_dir, merged)


def _foxglove_descriptors(tmp_path: Path) -> dict[str, descriptor_pb2.DescriptorProto]:
    """Foxglove's .proto files compiled by protoc: full name -> message descriptor."""
    import grpc_tools
    from grpc_tools import protoc

    out = tmp_path / "foxglove.pb"
    include = Path(grpc_tools.__file__).parent / "_proto"
    protos = sorted(str(p.relative_to(DATA)) for p in (DATA / "foxglove").glob("*.proto"))
    rc = protoc.main(["protoc", f"-I{DATA}", f"-I{include}", "--include_imports",
                      f"--descriptor_set_out={out}", *protos])
    assert rc == 0, "protoc could not compile schemas/foxglove"
    return _messages(descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()))


def _messages(fds: descriptor_pb2.FileDescriptorSet) -> dict[str, descriptor_pb2.DescriptorProto]:
    found = {}
    for f in fds.file:
        for m in f.message_type:
            found[f"{f.package}.{m.name}"] = m
    return found


def _fields(m: descriptor_pb2.DescriptorProto) -> set[tuple]:
    # name, number, type, label and the referenced type; not json_name/proto3_optional
    # bookkeeping (both are proto3 singular fields either way).
    fields = {(f.name, f.number, f.type, f.label, f.type_name) for f in m.field}
    enums = {(e.name, v.name, v.number) for e in m.enum_type for v in e.value}
    return fields | enums


def test_channels_have_foxglove_schema_names(run):
    for topic, name in FOXGLOVE.items():
        assert topic in run.schemas, f"no {topic} channel in the merged run"
        assert run.schemas[topic][0] == name
        assert run.messages[topic], topic


def test_schemas_are_foxglove_field_by_field(run, tmp_path):
    reference = _foxglove_descriptors(tmp_path)
    for topic, name in FOXGLOVE.items():
        recorded = _messages(descriptor_pb2.FileDescriptorSet.FromString(run.schemas[topic][1]))
        # The message and every foxglove type it uses, recursively.
        todo, seen = [name], set()
        while todo:
            n = todo.pop()
            if n in seen:
                continue
            seen.add(n)
            assert n in reference, f"{topic}: {n} is not one of Foxglove's messages"
            assert _fields(recorded[n]) == _fields(reference[n]), f"{topic}: {n} differs from Foxglove's .proto"
            todo += [f.type_name.lstrip(".") for f in recorded[n].field
                     if f.type == f.TYPE_MESSAGE and f.type_name.startswith(".foxglove.")]


def _ns(ts) -> int:
    return ts.seconds * 1_000_000_000 + ts.nanos


def _transforms(run, parent: str, child: str) -> list:
    return [t for m in run.of("scene/transforms") for t in m.transforms
            if t.parent_frame_id == parent and t.child_frame_id == child]


def _due(msgs: list) -> list:
    """The messages whose frames go out: each at least 1/60 s (transforms_max_hz's
    default) after the last one sent."""
    due, last = [], None
    for m in msgs:
        if last is None or m.header.stamp_ns - last >= 1e9 / 60:
            due.append(m)
            last = m.header.stamp_ns
    return due


def test_world_tob_is_the_filters_estimate(run):
    states = [s for s in run.of("pose_filter/tob_state") if s.HasField("world_T_tob")]
    tob = _transforms(run, "world", "tob")
    due = _due(states)
    assert len(tob) == len(due) > 50
    for s, t in zip(due, tob, strict=True):
        assert _ns(t.timestamp) == s.header.stamp_ns
        p, q = s.world_T_tob.translation, s.world_T_tob.rotation
        assert (t.translation.x, t.translation.y, t.translation.z) == (p.x, p.y, p.z)
        assert (t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w) == (q.x, q.y, q.z, q.w)


def _matrix(t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w]).as_matrix()
    T[:3, 3] = [t.translation.x, t.translation.y, t.translation.z]
    return T


def test_robot_chain_and_rig_frames(run):
    states = run.of("robot_gateway/robot_state")
    world_base, base_flange = _transforms(run, "world", "base"), _transforms(run, "base", "flange")
    assert len(base_flange) == len(world_base) == len(states) > 50
    for s, wb, bf in zip(states, world_base, base_flange, strict=True):
        assert _ns(bf.timestamp) == s.header.stamp_ns
        p, q = s.world_T_flange.translation, s.world_T_flange.rotation
        expected = np.eye(4)
        expected[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        expected[:3, 3] = [p.x, p.y, p.z]
        np.testing.assert_allclose(_matrix(wb) @ _matrix(bf), expected, atol=1e-9)
    # The rig's fixed frames, by hand from the nominal rig: the camera at (0, 60, 100) mm on
    # the flange, axes parallel; eq. (3): O1 = (b/2, 0, -b/2), O2 = (-b/2 - m, 0, -b/2 + l)
    # with b = 90 mm, m = 0.329, l = 0.378 (a 1 mm 45 deg n = 1.5 splitter); D 600 mm ahead.
    rig = tomllib.loads((run.run_dir / "rig.toml").read_text())
    m_mm, l_mm = rig["psvs"]["m_mm"], rig["psvs"]["l_mm"]
    assert abs(m_mm - 0.329) < 1e-3 and abs(l_mm - 0.378) < 1e-3
    for parent, child, xyz_mm in (("flange", "camera", (0, 60, 100)), ("camera", "camera_right", (45, 0, -45)),
                                  ("camera", "camera_left", (-45 - m_mm, 0, -45 + l_mm)),
                                  ("camera", "desired", (0, 0, 600))):
        (t, *_) = _transforms(run, parent, child)
        np.testing.assert_allclose(_matrix(t), np.r_[np.c_[np.eye(3), np.array(xyz_mm) * 1e-3], [[0, 0, 0, 1]]],
                                   atol=1e-12, err_msg=f"{parent} -> {child}")
    (tip, *_) = _transforms(run, "tob", "tip")
    tip_mm = rig["tip"]["tob_t_tip_mm"]
    assert [tip.translation.x * 1e3, tip.translation.y * 1e3, tip.translation.z * 1e3] == pytest.approx(tip_mm)
    desired = run.of("controller/status")
    assert len(_transforms(run, "world", "flange_desired")) == len(_due([s for s in desired
                                                                      if s.HasField("world_T_desired")]))


def test_annotations_are_perceptions_centres_on_the_images(run):
    images = {_ns(i.timestamp) for i in run.of("camera/image")}
    measurements = run.of("perception/tob")
    annotations = run.of("scene/annotations")
    assert len(annotations) == len(measurements) > 50
    full = 0
    for m, a in zip(measurements, annotations, strict=True):
        assert _ns(a.timestamp) == m.header.stamp_ns and m.header.stamp_ns in images
        assert [(c.position.x, c.position.y) for c in a.circles] == [(c.u, c.v) for c in m.centers_px]
        assert [[(p.x, p.y) for p in line.points] for line in a.points] == [
            [(m.centers_px[p.right].u, m.centers_px[p.right].v), (m.centers_px[p.left].u, m.centers_px[p.left].v)]
            for p in m.pairs]
        if m.status == 1:  # TOB_STATUS_FULL: labelled A, B, C, each in the right and left view
            full += 1
            assert [t.text for t in a.texts] == ["A R", "A L", "B R", "B L", "C R", "C L"]
    assert full > 50


def test_calibration_is_the_rigs_camera(run):
    rig = tomllib.loads((run.run_dir / "rig.toml").read_text())["psvs"]
    image = run.of("camera/image")[0]
    cals = run.of("scene/calibration")
    assert len(cals) >= 3  # at start and every 30 measurements (3 s of 30 Hz after the start)
    c = cals[0]
    assert (c.frame_id, c.width, c.height) == (image.frame_id, image.width, image.height)
    assert c.distortion_model == "plumb_bob" and list(c.D) == pytest.approx(rig.get("dist_coeffs", [0.0] * 5))
    a_u, a_v, u0, v0 = (rig.get(k, d) for k, d in (("a_u", 1000.0), ("a_v", 1000.0), ("u0", 320.0), ("v0", 240.0)))
    assert list(c.K) == pytest.approx([a_u, 0, u0, 0, a_v, v0, 0, 0, 1])
    assert list(c.P) == pytest.approx([a_u, 0, u0, 0, 0, a_v, v0, 0, 0, 0, 1, 0])


def test_log_has_every_event(run):
    events = [(_stamp, e) for t, ms in run.messages.items() if t.endswith("/events") and not t.startswith("scene/")
              for _stamp, e in ms]
    logs = run.of("scene/log")
    assert len(logs) == len(events) > 3
    assert Counter(lg.name for lg in logs) == Counter(e.source for _, e in events)
    levels = {1: 1, 2: 2, 3: 3, 4: 4, 5: 5}  # humanpt Severity -> foxglove Log.Level (same names)
    assert Counter((lg.level, lg.message) for lg in logs) == Counter(
        (levels[e.severity], f"{e.code}: {e.text}") for _, e in events)


def test_path_is_the_recorded_path(run):
    points = run.of("controller/path")
    paths = run.of("scene/path")
    assert points and paths
    last = paths[-1]
    assert last.frame_id == "world" and len(last.poses) == len(points)
    recorded = []
    for pose, pt in zip(last.poses, points, strict=True):
        src = pt.world_T_tip if pt.has_tip else pt.world_T_tob
        recorded.append((src.translation.x, src.translation.y, src.translation.z))
        assert (pose.position.x, pose.position.y, pose.position.z) == recorded[-1]
    # The same points as a PointCloud: x, y, z float32 (PackedElementField type 7) at 0, 4, 8.
    cloud = run.of("scene/path_points")[-1]
    assert cloud.frame_id == "world" and cloud.point_stride == 12
    assert [(f.name, f.offset, f.type) for f in cloud.fields] == [("x", 0, 7), ("y", 4, 7), ("z", 8, 7)]
    xyz = np.frombuffer(cloud.data, dtype="<f4").reshape(-1, 3)
    np.testing.assert_allclose(xyz, np.array(recorded), rtol=0, atol=1e-6)  # float32 at ~1 m: < 0.1 um


def test_entities_target_triangle_and_seams(run):
    updates = run.of("scene/entities")
    entities = [e for u in updates for e in u.entities]
    target = next(e for e in entities if e.id == "target")
    assert target.frame_id == "tob" and target.frame_locked
    centres = [np.array([s.pose.position.x, s.pose.position.y, s.pose.position.z]) for s in target.spheres]
    sides_mm = sorted(np.linalg.norm(a - b) * 1e3 for a, b in ((centres[0], centres[1]), (centres[1], centres[2]),
                                                                (centres[2], centres[0])))
    rig = tomllib.loads((run.run_dir / "rig.toml").read_text()).get("target", {})
    leg, base = rig.get("leg_mm", 40.0), rig.get("base_mm", 30.0)
    assert sides_mm == pytest.approx([base, leg, leg])  # isosceles: AB = AC = leg, BC = base
    assert [s.size.x * 1e3 for s in target.spheres] == pytest.approx([rig.get("source_diameter_mm", 5.0)] * 3)
    seam = [e for e in entities if e.id.startswith("path1/seam/")]
    assert seam, "no recorded seam"
    drawn = seam[-1].lines[0].points
    points = run.of("controller/path")
    assert len(drawn) == len(points)  # < seam_strip_points: one strip
    truth = [e for e in entities if e.id.startswith("truth/seam/")]
    assert truth and all(e.frame_id == "world" for e in truth)
    # The true seam's points are operator truths (the tip, or G), at least truth_step_mm apart.
    true_points = [(p.x, p.y, p.z) for p in truth[-1].lines[0].points]
    tips = {(t.world_T_tip if t.has_tip else t.world_T_tob).translation.SerializeToString()
            for t in run.of("operator/truth")}
    assert all(pb.Vector3(x=x, y=y, z=z).SerializeToString() in tips for x, y, z in true_points)
    assert all(math.dist(a, b) >= 2e-3 for a, b in zip(true_points, true_points[1:], strict=False))
