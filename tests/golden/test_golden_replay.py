"""Golden replay of the reference runs in recordings/.

Every component of every reference run (found on disk, so a new run is picked up by
itself) is replayed on its recorded inputs and must reproduce its recorded outputs:
discrete fields exactly, floats and images within golden.TOLERANCES / IMAGE_TOLERANCE.
No reference runs at all is a failure, not a pass.  A deliberately perturbed core (made
here, in the test) is caught with the run, component, topic, message and field deltas
named, when beyond tolerance, and passes within it; a recording of another schema version
is refused, naming the version.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.records import Channel, Metadata, Schema
from mcap.records import Message as McapMessage
from mcap.writer import Writer

from humanpt.runtime.recording import (
    RUN_METADATA,
    RecordingError,
    iter_records,
    read,
    read_metadata,
)
from humanpt.schemas import topics
from humanpt.testing import golden
from humanpt.twin.rerecord import SPEC_FILE, load_specs
from tests.conftest import ROOT
from tests.golden.perturb import fresh_copy, perturbed_factory

RECORDINGS = ROOT / "recordings"
# What a live demo run records: every component of the closed loop on the twin.
LIVE_COMPONENTS = {
    "operator",
    "sim_robot",
    "robot_gateway",
    "sim_camera",
    "perception",
    "pose_filter",
    "controller",
}
REQUIRED_RUNS = {"static", "arc", "trapezium"}
SIZE_BUDGET_BYTES = 8_000_000  # all reference runs together: keep the repository light


def _reference_params():
    try:
        return [pytest.param(f, id=f.id) for f in golden.reference_files(RECORDINGS)]
    except golden.GoldenError as e:
        # Nothing to replay must fail, not pass silently with zero tests.
        return [pytest.param(e, id="no-reference-runs")]


@pytest.mark.parametrize("ref", _reference_params())
def test_golden_replay(ref):
    if isinstance(ref, golden.GoldenError):
        pytest.fail(str(ref), pytrace=False)
    result = golden.check_component(ref)
    if not result.ok:
        pytest.fail(result.message, pytrace=False)
    print(result.message)  # the largest difference per field (pytest -rP shows it)


def test_reference_runs_are_complete_live_and_small():
    specs = {s.name: s for s in load_specs(RECORDINGS / SPEC_FILE)}
    assert REQUIRED_RUNS <= set(specs)
    readme = (RECORDINGS / "README.md").read_text()
    total = 0
    for name, spec in specs.items():
        run = RECORDINGS / name
        assert run.is_dir(), (
            f"{run}: reference run {name!r} of {SPEC_FILE} is not recorded; "
            f"humanpt runs rerecord --only {name}"
        )
        assert {p.stem for p in run.glob("*.mcap")} >= LIVE_COMPONENTS
        info = json.loads((run / "reference.json").read_text())
        assert (
            info["live"]
            and info["seed"] == spec.seed
            and info["command"].startswith("humanpt demo ")
        )
        assert info["overrides"] == list(spec.overrides), (
            f"{name}: {SPEC_FILE} changed since it was recorded"
        )
        assert (run / "humanpt.toml").is_file()
        for f in run.glob("*.mcap"):
            meta, complete = read_metadata(f)
            assert complete, f"{f}: not closed properly"
            assert meta["shell"] == "live", f"{f}: recorded by the {meta['shell']} shell, not live"
        assert f"| `{name}` |" in readme, f"recordings/README.md has no line for {name}"
        total += sum(p.stat().st_size for p in run.rglob("*") if p.is_file())
    assert total < SIZE_BUDGET_BYTES, f"reference runs weigh {total / 1e6:.1f} MB"


def test_no_reference_runs_is_a_failure(tmp_path):
    with pytest.raises(golden.GoldenError, match="no reference runs"):
        golden.reference_files(tmp_path)
    with pytest.raises(golden.GoldenError, match="no such directory"):
        golden.reference_files(tmp_path / "missing")


def _static(tmp_path: Path, component: str) -> Path:
    """The static run's recording of ``component``, re-recorded offline with this build
    (so these tests of the machinery do not depend on the build matching the reference)."""
    path = RECORDINGS / "static" / f"{component}.mcap"
    if not path.exists():
        pytest.fail(
            f"{path}: the static reference run is missing (humanpt runs rerecord --only static)"
        )
    return fresh_copy(path, tmp_path / "static" / f"{component}.mcap")


def test_perturbed_core_fails_with_the_divergence_named(tmp_path):
    path = _static(tmp_path, "pose_filter")
    result = golden.check_component(
        path,
        perturbed_factory(
            "pose_filter/tob_state", after=10, field="world_T_tob.translation.x", delta=1e-6
        ),
    )
    assert not result.ok
    msg = result.message
    assert "reference run 'static', component 'pose_filter'" in msg
    assert "first differing message: topic pose_filter/tob_state, message #10 on that topic" in msg
    assert "world_T_tob.translation.x:" in msg and "(by +1e-06)" in msg
    # The summary of the whole replay: every later state differs by the same nudge.
    n = sum(1 for e in read(path).outputs if e.topic == "pose_filter/tob_state")
    assert (
        f"pose_filter/tob_state: {n} -> {n} messages, 0 added, 0 removed, {n - 10} differ (first at #10)"
        in msg
    )
    assert "world_T_tob.translation.x: max |d| 1e-06" in msg
    assert "humanpt runs rerecord" in msg
    # The product's core, unperturbed, passes on the same file.
    assert golden.check_component(path).ok


def test_dropped_message_is_named_as_removed(tmp_path):
    path = _static(tmp_path, "perception")
    result = golden.check_component(path, perturbed_factory("perception/tob", after=5, drop=True))
    assert not result.ok
    assert "component 'perception'" in result.message
    assert "topic perception/tob, message #5 on that topic" in result.message
    assert "0 added, 1 removed" in result.message


@pytest.mark.parametrize(
    "component, topic, field, within, beyond",
    [
        # metres: tolerance 1e-9 m
        ("pose_filter", "pose_filter/tob_state", "world_T_tob.translation.x", 1e-12, 1e-8),
        # quaternion components: 1e-9
        ("operator", "operator/truth", "world_T_tob.rotation.y", 1e-12, 1e-8),
        # radians: 1e-9 rad
        ("controller", "controller/command", "d_rotation_rad.z", 1e-12, 1e-8),
    ],
)
def test_float_within_tolerance_passes_and_beyond_fails(tmp_path, component, topic, field,
                                                        within, beyond):
    path = _static(tmp_path, component)
    ok = golden.check_component(path, perturbed_factory(topic, after=3, field=field, delta=within))
    assert ok.ok, ok.message
    assert f"{field}: max |d| " in ok.message and "within tolerance" in ok.message
    assert _largest(ok, topic, field) == pytest.approx(within, rel=1e-3)  # the nudge, reported
    bad = golden.check_component(path, perturbed_factory(topic, after=3, field=field, delta=beyond))
    assert not bad.ok
    assert f"topic {topic}, message #3 on that topic" in bad.message
    assert f"{field}: max |d| " in bad.message and "BEYOND it in" in bad.message
    assert _largest(bad, topic, field) == pytest.approx(beyond, rel=1e-3)
    # Run == replay stays exact within one build: the exact mode refuses even the tiny nudge.
    exact = golden.check_component(
        path, perturbed_factory(topic, after=3, field=field, delta=within), exact=True
    )
    assert not exact.ok and "byte for byte" in exact.message
    assert golden.check_component(path, exact=True).ok


def _largest(result, topic: str, field: str) -> float:
    (td,) = [t for t in result.diff.topics if t.topic == topic]
    (fd,) = [f for f in td.fields if f.field == field]
    return fd.max_abs


def test_discrete_fields_are_exact(tmp_path):
    path = _static(tmp_path, "pose_filter")
    result = golden.check_component(
        path, perturbed_factory("pose_filter/tob_state", after=5, field="header.seq", delta=1)
    )
    assert not result.ok
    assert "header.seq: max |d| 1 " in result.message and "BEYOND" in result.message


def test_float_field_without_a_unit_rule_fails(tmp_path):
    assert golden.tolerance_of("world_T_tob.translation.x") is golden.TOLERANCES["m"]
    assert golden.tolerance_of("centers_px[3].u") is golden.TOLERANCES["px"]
    assert golden.tolerance_of("linear_velocity_m_s.x") is golden.TOLERANCES["m/s"]
    assert golden.tolerance_of("mystery") is None
    # Every float field of every message on a topic has a rule (else it could never pass).
    types = {t.short: t.type for t in golden.topics.TOPICS.values()} | golden.topics.LOCAL_TOPICS
    for short, msg_type in types.items():
        for name, value in golden.flatten(_filled(msg_type())).items():
            if isinstance(value, float):
                assert golden.tolerance_of(name) is not None, f"{short}: {name}"


def _filled(msg):
    """``msg`` with one item in every repeated message field (so their fields are named)."""
    for fd in msg.DESCRIPTOR.fields:
        if fd.type == fd.TYPE_MESSAGE:
            if fd.is_repeated:
                _filled(getattr(msg, fd.name).add())
            else:
                _filled(getattr(msg, fd.name))
        elif fd.is_repeated and fd.type in (fd.TYPE_DOUBLE, fd.TYPE_FLOAT):
            getattr(msg, fd.name).append(0.0)
    return msg


@pytest.mark.parametrize(
    "pixels, dn, ok",
    [
        (1, 1, True),  # one draw of the shot noise moved by 1 DN
        (1, 20, False),  # beyond IMAGE_TOLERANCE.max_dn
        (1000, 1, False),  # too many pixels, and all one way (a brighter image)
    ],
)
def test_changed_image_pixels_within_and_beyond_tolerance(tmp_path, pixels, dn, ok):
    path = _static(tmp_path, "sim_camera")
    result = golden.check_component(
        path, perturbed_factory("camera/image", after=3, pixel=1000, pixels=pixels, dn=dn)
    )
    assert result.ok == ok, result.message
    assert f"data: max |d| (bytes as uint8) {dn} " in result.message
    if not ok:
        assert "topic camera/image, message #3 on that topic" in result.message


def rewrite_metadata(src: Path, dst: Path, **changes: str) -> None:
    """Copy an MCAP recording, changing keys of its humanpt.run metadata."""
    with open(dst, "wb") as out:
        w = Writer(out)
        w.start(profile="humanpt", library="test")
        schemas, channels = {}, {}
        for r in iter_records(src):
            if isinstance(r, Schema):
                schemas[r.id] = w.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel):
                channels[r.id] = w.register_channel(
                    r.topic, r.message_encoding, schemas.get(r.schema_id, 0), r.metadata
                )
            elif isinstance(r, Metadata):
                w.add_metadata(
                    r.name, {**r.metadata, **changes} if r.name == RUN_METADATA else r.metadata
                )
            elif isinstance(r, McapMessage):
                w.add_message(
                    channels[r.channel_id], r.log_time, r.data, r.publish_time, r.sequence
                )
        w.finish()


@pytest.mark.parametrize(
    "version", [str(topics.SCHEMA_VERSION - 1), str(topics.SCHEMA_VERSION + 1)]
)
def test_recording_of_another_schema_version_is_refused_naming_it(tmp_path, version):
    src = _static(tmp_path / "fresh", "perception")
    run = tmp_path / "static"
    run.mkdir()
    dst = run / "perception.mcap"
    rewrite_metadata(src, dst, schema_version=version)
    assert read_metadata(dst)[0]["schema_version"] == version
    with pytest.raises(
        RecordingError,
        match=f"written with schema version {version}; this humanpt reads "
        f"schema version {topics.SCHEMA_VERSION}",
    ):
        read(dst)
    result = golden.check_component(dst)
    assert not result.ok
    assert "reference run 'static', component 'perception'" in result.message
    assert f"written with schema version {version}" in result.message
    assert "humanpt runs rerecord" in result.message
    # The same copy with the current version replays: only the version made the difference.
    rewrite_metadata(src, tmp_path / "same.mcap", schema_version=str(topics.SCHEMA_VERSION))
    assert golden.check_component(tmp_path / "same.mcap").ok
