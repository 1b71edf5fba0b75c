"""``humanpt runs rerecord`` and the stream comparison behind its summary."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.cli.demo import parse_overrides
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.testing import golden
from humanpt.twin import rerecord as rr
from tests.conftest import ROOT, run_cli_here
from tests.golden.perturb import fresh_run, perturbed_factory

RECORDINGS = ROOT / "recordings"


# -- compare_streams ---------------------------------------------------------------------------
def _state(t_ns: int, x: float, seq: int = 0, status=pb.TOB_STATUS_FULL) -> tuple[int, str, bytes]:
    m = pb.TobState(status=status)
    m.header.stamp_ns, m.header.seq = t_ns, seq
    m.world_T_tob.translation.x = x
    return (t_ns, "pose_filter/tob_state", m.SerializeToString())


def _image(t_ns: int, pixels: bytes) -> tuple[int, str, bytes]:
    m = RawImage(width=len(pixels), height=1, encoding="mono8", step=len(pixels), data=pixels)
    m.timestamp.FromNanoseconds(t_ns)
    return (t_ns, "camera/image", m.SerializeToString())


def test_identical_streams():
    s = [_state(10, 0.1), _state(20, 0.2), _image(20, b"\x01\x02")]
    d = golden.compare_streams(s, list(s))
    assert d.identical
    assert [t.topic for t in d.topics] == ["pose_filter/tob_state", "camera/image"]
    assert "pose_filter/tob_state: 2 -> 2 messages, identical" in d.describe()


def test_field_difference_added_and_removed_by_step():
    old = [_state(10, 0.1), _state(20, 0.2), _state(30, 0.3)]
    new = [_state(10, 0.1), _state(20, 0.2005), _state(25, 0.25), _state(40, 0.4)]
    t = golden.compare_streams(old, new, pairing="step").topics[0]
    assert (t.old_count, t.new_count, t.added, t.removed, t.differing, t.first) == (
        3,
        4,
        2,
        1,
        1,
        1,
    )
    (f,) = t.fields
    assert f.field == "world_T_tob.translation.x" and f.kind == "number"
    assert f.max_abs == pytest.approx(5e-4) and f.signed == pytest.approx(5e-4) and f.at == 1
    text = "\n".join(t.describe())
    assert "3 -> 4 messages, 2 added, 1 removed, 1 differ (first at #1)" in text
    assert (
        "world_T_tob.translation.x: max |d| 0.0005 (new - old = +0.0005 at #1; differs in 1; "
        "tolerance 1e-09 m; BEYOND it in 1, first at #1)" in text
    )


def test_largest_difference_per_field_and_text_fields():
    old = [_state(10, 0.1), _state(20, 0.2), _state(30, 0.3, status=pb.TOB_STATUS_FULL)]
    new = [_state(10, 0.0), _state(20, 0.5), _state(30, 0.3, status=pb.TOB_STATUS_LOST)]
    t = golden.compare_streams(old, new).topics[0]
    by = {f.field: f for f in t.fields}
    assert by["world_T_tob.translation.x"].max_abs == pytest.approx(0.3)
    assert (
        by["world_T_tob.translation.x"].at == 1 and by["world_T_tob.translation.x"].differing == 2
    )
    assert (
        by["status"].kind == "text"
        and "'TOB_STATUS_FULL' -> 'TOB_STATUS_LOST'" in by["status"].describe()
    )


def test_images_compare_pixel_by_pixel():
    old = [_image(10, bytes([10, 20, 30]))]
    new = [_image(10, bytes([10, 27, 30]))]
    (t,) = golden.compare_streams(old, new).topics
    (f,) = t.fields
    assert (f.field, f.kind, f.max_abs, f.signed) == ("data", "bytes", 7.0, 7.0)
    assert "data: max |d| (bytes as uint8) 7" in f.describe()


def test_live_runs_pair_in_order_with_stamps_relative_to_their_start():
    # The same run started 5 s later, one message shorter: only the count differs.
    old = [_state(1_000 + i * 10, 0.1 * i, seq=i) for i in range(4)]
    new = [_state(5_000_001_000 + i * 10, 0.1 * i, seq=i) for i in range(3)]
    (t,) = golden.compare_streams(old, new, pairing="order", relative_stamps=True).topics
    assert (t.added, t.removed, t.differing) == (0, 1, 0)
    # Without relative stamps, the start shows in the stamp and the log time.
    (t,) = golden.compare_streams(old, new, pairing="order").topics
    assert {f.field for f in t.fields} == {"header.stamp_ns", "(log time ns)"}


def test_flatten_names_every_field():
    m = pb.TobMeasurement(visible=2, status=pb.TOB_STATUS_POSITION_ONLY)
    m.centers_px.add(u=1.5, v=2.5)
    flat = golden.flatten(m)
    assert flat["centers_px[#]"] == 1 and flat["centers_px[0].u"] == 1.5
    assert flat["status"] == "TOB_STATUS_POSITION_ONLY" and flat["visible"] == 2
    assert flat["camera_T_tob.translation.z"] == 0.0  # unset fields count too


# -- reference run list and demo overrides ---------------------------------------------------------
def test_runs_toml_lists_the_reference_runs():
    specs = rr.load_specs(RECORDINGS / rr.SPEC_FILE)
    assert {"static", "arc", "trapezium"} <= {s.name for s in specs}
    for s in specs:
        assert s.command().startswith(f"humanpt demo --scenario {s.scenario} --duration ")
        over = parse_overrides(s.overrides)
        assert over["sim_camera"]["fps"] == 15


def test_bad_runs_toml_is_named(tmp_path):
    p = tmp_path / "runs.toml"
    p.write_text('[runs.x]\nscenario = "static"\nduration_s = 500\n')
    with pytest.raises(golden.GoldenError, match="duration_s must be in"):
        rr.load_specs(p)
    p.write_text('[runs.x]\nscenario = "static"\nduration = 5\n')
    with pytest.raises(golden.GoldenError, match=r"\[runs.x\] unknown key 'duration'"):
        rr.load_specs(p)


def test_parse_overrides():
    assert parse_overrides(
        [
            "sim_camera.fps=15",
            "sim_camera.psvs.a_u=500.5",
            "perception.method=paper",
            'operator.scenario="arc"',
        ]
    ) == {
        "sim_camera": {"fps": 15, "psvs": {"a_u": 500.5}},
        "perception": {"method": "paper"},
        "operator": {"scenario": "arc"},
    }
    with pytest.raises(SystemExit, match="expected SECTION.KEY=VALUE"):
        parse_overrides(["fps=15"])


# -- the verb, offline (a recorder that copies the reference run) ------------------------------
def _args(root: Path, **kw) -> dict:
    """rerecord()'s arguments (typed: the API, not the command line)."""
    base = {
        "root": root,
        "only": ["static"],
        "dry_run": False,
        "out": root.parent / "new-runs",  # never a stray temporary directory
        "fields": 6,
        "timeout_s": 60.0,
    }
    return {**base, **kw}


@pytest.fixture(scope="module")
def fresh(tmp_path_factory) -> Path:
    """The static reference run re-recorded offline with this build (tmp/fresh/static): the
    rerecord machinery is tested apart from whether this build matches recordings/. Once
    per module: every test reads it only (``scratch`` is each test's copy)."""
    return fresh_run(RECORDINGS / "static", tmp_path_factory.mktemp("fresh") / "static").parent


@pytest.fixture
def scratch(tmp_path, fresh) -> Path:
    """A recordings/ with only the static run (the others' tables stay in runs.toml)."""
    root = tmp_path / "recordings"
    root.mkdir()
    shutil.copy(RECORDINGS / rr.SPEC_FILE, root)
    shutil.copy(RECORDINGS / "README.md", root)
    shutil.copytree(fresh / "static", root / "static")
    return root


def copying_recorder(src_root: Path):
    """A recorder that 'records' a run by copying it from ``src_root`` (a live rerun
    with no change and perfectly repeatable timing)."""

    def record(spec, run_dir, timeout_s):
        shutil.copytree(src_root / spec.name, run_dir)
        (run_dir / "reference.json").unlink(missing_ok=True)
        return True, ""

    return record


def _digest(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def test_dry_run_summarises_and_leaves_recordings_alone(scratch, fresh, tmp_path, capsys):
    before = _digest(scratch)
    assert (
        rr.rerecord(**_args(scratch, dry_run=True, out=tmp_path / "new"), recorder=copying_recorder(fresh))
        == 0
    )
    out = capsys.readouterr().out
    assert "this build on the old run's inputs (identical, within tolerance or CHANGED" in out
    for c in (
        "robot_gateway",
        "controller",
        "operator",
        "perception",
        "pose_filter",
        "sim_camera",
        "sim_robot",
    ):
        assert f"    {c}: identical (" in out
    assert "sim_camera/truth: " in out and ", identical" in out
    assert "accuracy against ground truth" in out
    assert "this build changes component outputs in: none" in out and "dry run:" in out
    assert _digest(scratch) == before
    assert (tmp_path / "new" / "static" / "perception.mcap").is_file()


def test_accepting_replaces_the_run_and_rewrites_the_readme(scratch, fresh, capsys):
    readme_before = (scratch / "README.md").read_text()
    assert rr.rerecord(**_args(scratch), recorder=copying_recorder(fresh)) == 0
    info = json.loads((scratch / "static" / "reference.json").read_text())
    assert info["command"].startswith("humanpt demo --scenario static") and info["live"]
    assert info["version"]["schema_version"] == str(golden.topics.SCHEMA_VERSION)
    readme = (scratch / "README.md").read_text()
    assert readme.split(rr.README_BEGIN)[0] == readme_before.split(rr.README_BEGIN)[0]  # prose kept
    assert "| `static` | `humanpt demo --scenario static" in readme and "| total |" in readme
    assert not list(scratch.glob(".static.*"))
    assert all(golden.check_component(f).ok for f in golden.reference_files(scratch))


def test_failed_recording_replaces_nothing(scratch, fresh, capsys):
    before = _digest(scratch)
    assert rr.rerecord(**_args(scratch), recorder=lambda spec, d, t: (False, "router did not start")) == 1
    assert "recording FAILED: router did not start" in capsys.readouterr().out
    assert _digest(scratch) == before


def test_new_run_that_does_not_replay_is_refused(scratch, fresh, capsys):
    def recorder(spec, run_dir, timeout_s):
        copying_recorder(fresh)(spec, run_dir, timeout_s)
        data = (run_dir / "controller.mcap").read_bytes()
        (run_dir / "controller.mcap").write_bytes(data[: len(data) // 2])  # a crash mid-run
        return True, ""

    before = _digest(scratch)
    assert rr.rerecord(**_args(scratch), recorder=recorder) == 1
    out = capsys.readouterr().out
    assert "the NEW recording does not replay exactly" in out and "controller" in out
    assert _digest(scratch) == before


def test_summary_shows_what_a_changed_component_does(scratch, fresh, tmp_path):
    new = tmp_path / "new"
    copying_recorder(fresh)(rr.ReferenceRun("static", "static", 3.5), new, 0)
    factory = perturbed_factory(
        "controller/command", after=4, field="d_translation_m.y", delta=-2e-5
    )
    rep = rr.compare_run(
        rr.ReferenceRun("static", "static", 3.5), scratch / "static", new, 6, factory
    )
    text = "\n".join(rep.lines)
    assert rep.ok and rep.changed
    assert "controller: CHANGED (recorded -> this build):" in text
    assert (
        "controller/command: " in text and "0 added, 0 removed" in text and "(first at #4)" in text
    )
    assert re.search(
        r"d_translation_m.y: max \|d\| 2e-05 \(new - old = -2e-05 at #\d+; differs in \d+; "
        r"tolerance 1e-09 m; BEYOND it in \d+, first at #4\)",
        text,
    )


def test_unknown_run_is_named(scratch, fresh, capsys):
    assert rr.rerecord(**_args(scratch, only=["spiral"]), recorder=copying_recorder(fresh)) == 2
    assert "no reference run 'spiral'" in capsys.readouterr().err


# -- the verb, live (one short run, not replacing anything) -----------------------------------------
@pytest.mark.live  # (the verb runs in this process and starts the live run's processes)
@pytest.mark.timeout(400)
def test_rerecord_static_live_dry_run(scratch, fresh, tmp_path):
    # A live run of 1.5 s (the reference's 3.5 s: its length is not what is checked here; the
    # verdict on this build comes from replaying the old run's inputs, whatever the new run's
    # length). The verb in this process: it starts the live run's processes itself.
    spec = scratch / rr.SPEC_FILE
    text = spec.read_text()
    assert "[runs.static]\n" in text and "duration_s = 3.5\n" in text
    spec.write_text(text.replace("duration_s = 3.5\n", "duration_s = 1.5\n", 1))
    assert {s.name: s.duration_s for s in rr.load_specs(spec)}["static"] == 1.5
    r = run_cli_here(
        "runs",
        "rerecord",
        "--only",
        "static",
        "--dry-run",
        "--dir",
        str(scratch),
        "--out",
        str(tmp_path / "new"),
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "this build changes component outputs in: none" in r.stdout
    assert "the new live run against the old" in r.stdout
    new = tmp_path / "new" / "static"
    assert {p.stem for p in new.glob("*.mcap")} >= {
        "sim_camera",
        "perception",
        "pose_filter",
        "controller",
        "robot_gateway",
        "sim_robot",
        "operator",
    }
    assert all(
        golden.check_component(golden.ReferenceFile("static", p.stem, p)).ok
        for p in new.glob("*.mcap")
    )


def _pose(t_ns: int, q: tuple[float, float, float, float]) -> tuple[int, str, bytes]:
    m = pb.TobState()
    m.header.stamp_ns = t_ns
    r = m.world_T_tob.rotation
    r.x, r.y, r.z, r.w = q
    return (t_ns, "pose_filter/tob_state", m.SerializeToString())


def test_quaternion_sign_is_not_a_rotation_change():
    # q and -q: the same rotation; the summary says the encodings differ, not by ~2.
    (t,) = golden.compare_streams(
        [_pose(10, (0.99, 0.1, 0.0, 0.01))], [_pose(10, (-0.99, -0.1, 0.0, -0.01))]
    ).topics
    assert t.differing == 1 and [f.field for f in t.fields] == ["(bytes)"]
    (t,) = golden.compare_streams(
        [_pose(10, (0.99, 0.1, 0.0, 0.01))], [_pose(10, (-0.99, -0.1, 0.0, 0.01))]
    ).topics
    # Another rotation: compared with the sign that brings it nearest (only w differs).
    assert {f.field for f in t.fields} == {"world_T_tob.rotation.w"}
