"""The rig file (issue 16.1): one place for what the pipeline believes, refused field by field
when wrong, recorded with every run, replayed with the recorded rig, served live."""

from __future__ import annotations

import dataclasses
import json
import re
import tomllib
import typing

import numpy as np
import pytest

from humanpt.geometry.config import PsvsConfig
from humanpt.geometry.rig import Calibration, HandEye, Rig, TargetGeometry, Tip
from humanpt.runtime.config import ConfigError
from humanpt.runtime.registry import config_types
from humanpt.runtime.rigfile import (
    load_rig,
    rig_from_json,
    rig_from_table,
    rig_to_json,
    rig_to_toml,
    write_rig,
)
from tests.conftest import procs as procs
from tests.conftest import router as router  # noqa: F401
from tests.conftest import run_cli, run_cli_here, wait_for, write_config  # noqa: F401 - fixtures

# A rig that is not the nominal one in every part.
CALIBRATED = Rig(
    name="cell 7",
    psvs=PsvsConfig(a_u=1003.5, a_v=1002.5, u0=321.0, baseline_mm=90.4, dist_coeffs=(-0.01, 0.0, 0.0, 0.0, 0.0),
                    rotvec_left_deg=(0.0, 0.1, 0.0)),
    psvs_calibration=Calibration(method="zhang", date="2026-11-23T10:00:00Z", sigma={"a_u": 0.4, "baseline_mm": 0.05}),
    hand_eye=HandEye((0.5, 60.2, 99.8, 0.0, 0.1, -0.05), Calibration(method="ax=yb", sigma={"flange_T_camera_x": 0.1})),
    target=TargetGeometry(leg_mm=40.1, base_mm=29.9),
    tip=Tip((0.1, -0.2, 60.3), Calibration(method="pivot", note="60 samples")),
)


def test_a_rig_survives_toml_and_json():
    text = rig_to_toml(CALIBRATED)
    assert rig_from_table(tomllib.loads(text)) == CALIBRATED  # the TOML is plain TOML (the stdlib reads it)
    assert rig_from_json(rig_to_json(CALIBRATED)) == CALIBRATED


def test_write_rig_keeps_an_existing_file_unless_told(tmp_path):
    p = tmp_path / "rig.toml"
    write_rig(p, Rig())
    with pytest.raises(FileExistsError):
        write_rig(p, CALIBRATED)
    assert load_rig(p) == Rig()
    write_rig(p, CALIBRATED, overwrite=True)
    assert load_rig(p) == CALIBRATED and load_rig(tmp_path / "rig.toml.bak") == Rig()


def _nominal_table() -> dict:
    return tomllib.loads(rig_to_toml(Rig()))


def _with(path: str, value) -> dict:
    t = _nominal_table()
    *parents, key = path.split(".")
    node = t
    for k in parents:
        node = node.setdefault(k, {})
    if value is _DELETE:
        del node[key]
    else:
        node[key] = value
    return t


_DELETE = object()
NOT_A_ROTATION = [[1.0, 0.1, 0.0, 0.0], [0.0, 1.0, 0.0, 60.0], [0.0, 0.0, 1.0, 100.0], [0, 0, 0, 1]]
MIRRORED = [[-1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 60.0], [0.0, 0.0, 1.0, 100.0], [0, 0, 0, 1]]


@pytest.mark.parametrize("path, value, named", [
    ("psvs.a_u", 0.0, "a_u"),  # focal <= 0
    ("psvs.a_v", -1000.0, "a_v"),
    ("psvs.baseline_mm", 0.0, "baseline_mm"),  # baseline <= 0
    ("psvs.dist_coeffs", [0.0, 0.0], "dist_coeffs"),
    ("psvs.rotvec_left_deg", [0.0, 400.0, 0.0], "rotvec_left_deg"),
    ("psvs.focal", 1000.0, "focal"),  # unknown key
    ("hand_eye.flange_T_camera_x", [0.0, 60.0, "a", 0.0, 0.0, 0.0], "flange_T_camera_x"),
    ("hand_eye.flange_T_camera", NOT_A_ROTATION, "flange_T_camera"),  # not orthonormal
    ("hand_eye.flange_T_camera", MIRRORED, "flange_T_camera"),  # det -1: a reflection
    ("target.leg_mm", 10.0, "target"),  # 2 x 10 < 30: no triangle
    ("tip.tob_t_tip_mm", [0.0, 0.0, float("nan")], "tob_t_tip_mm"),
    ("tip.calibration.sigma", {"tip_length": 0.1}, "tip_length"),  # sigma of no field
    ("psvs.calibration.sigma", {"a_u": -1.0}, "sigma"),
    ("version", 2, "version"),
    ("version", _DELETE, "version"),
    ("magic", 1, "magic"),
])
def test_a_bad_rig_is_refused_naming_the_field(path, value, named):
    with pytest.raises(ConfigError) as e:
        rig_from_table(_with(path, value), "rig.toml")
    assert named in str(e.value) and "rig.toml" in str(e.value), str(e.value)


def test_a_hand_eye_matrix_is_read_as_its_pose():
    T = [[0.0, -1.0, 0.0, 5.0], [1.0, 0.0, 0.0, 60.0], [0.0, 0.0, 1.0, 100.0], [0, 0, 0, 1]]  # yaw 90 deg
    t = _with("hand_eye.flange_T_camera", T)
    del t["hand_eye"]["flange_T_camera_x"]
    np.testing.assert_allclose(rig_from_table(t).hand_eye.flange_T_camera_mm(), T, atol=1e-12)


def test_missing_and_unreadable_rig_files_are_named(tmp_path):
    with pytest.raises(ConfigError, match="no such rig file"):
        load_rig(tmp_path / "absent.toml")
    (tmp_path / "bad.toml").write_text("version = 1\n[psvs\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_rig(tmp_path / "bad.toml")


def test_config_check_fails_on_a_bad_rig_naming_the_field(tmp_path):
    write_rig(tmp_path / "rig.toml", Rig())
    cfg = tmp_path / "humanpt.toml"
    cfg.write_text('[runtime]\nrig = "rig.toml"\n')  # relative to the config file
    r = run_cli_here("config", "--check", "--config", str(cfg), cwd="/")
    assert r.returncode == 0 and "rig" in r.stdout, r.stdout + r.stderr
    (tmp_path / "rig.toml").write_text((tmp_path / "rig.toml").read_text().replace("baseline_mm = 90.0",
                                                                                   "baseline_mm = -90.0"))
    r = run_cli_here("config", "--check", "--config", str(cfg))
    assert r.returncode == 2 and "baseline_mm" in r.stderr and "rig.toml" in r.stderr, r.stdout + r.stderr
    cfg.write_text('[runtime]\nrig = "nowhere.toml"\n')
    r = run_cli_here("config", "--check", "--config", str(cfg))
    assert r.returncode == 2 and "no such rig file" in r.stderr, r.stderr


def test_rig_cli_init_check_diff(tmp_path):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    assert run_cli_here("rig", "init", str(a)).returncode == 0
    r = run_cli_here("rig", "init", str(a))
    assert r.returncode == 2 and "exists" in r.stderr
    write_rig(b, CALIBRATED)
    r = run_cli_here("rig", "check", str(b))
    assert r.returncode == 0 and "1003.5" in r.stdout and "ax=yb" in r.stdout, r.stdout
    r = run_cli_here("rig", "diff", str(a), str(b))
    assert r.returncode == 1 and "psvs.a_u: 1000.0 -> 1003.5" in r.stdout, r.stdout
    assert run_cli_here("rig", "diff", str(a), str(a)).returncode == 0


# -- one place ------------------------------------------------------------------------------
# What the pipeline believes about the hardware; the twin's components hold the world.
HARDWARE_NAMES = ("flange_T_camera", "psvs", "a_u", "a_v", "u0", "v0", "baseline_mm", "m_mm", "l_mm",
                  "dist_coeffs", "target_leg_mm", "target_base_mm", "source_diameter_mm", "side_tolerance_mm",
                  "tob_t_tip", "tob_T_tip")
TWIN = ("sim_camera", "sim_robot", "operator", "standin_robot", "pinger", "ponger")


def _fields(cls, prefix=""):
    for f in dataclasses.fields(cls):
        yield prefix + f.name, f
        tp = typing.get_type_hints(cls)[f.name]
        for t in (tp, *typing.get_args(tp)):
            if dataclasses.is_dataclass(t):
                yield from _fields(t, f"{prefix}{f.name}.")


def test_only_the_rig_holds_intrinsics_psvs_hand_eye_target_and_tip():
    checked = []
    for name, cls in config_types().items():
        if name in TWIN:
            continue
        checked.append(name)
        for path, f in _fields(cls):
            hints = typing.get_type_hints(cls) if "." not in path else {}
            assert not any(re.search(rf"(^|_){h}($|_)", f.name) for h in HARDWARE_NAMES), \
                f"[{name}] {path} belongs in the rig"
            assert hints.get(f.name) is not PsvsConfig, f"[{name}] {path} is a PSVS: it belongs in the rig"
    assert {"perception", "pose_filter", "controller", "viz"} <= set(checked)
    # ... and the rig does hold them
    assert {"psvs", "hand_eye", "target", "tip"} <= {f.name for f in dataclasses.fields(Rig)}


# -- recorded, replayed, served ---------------------------------------------------------------
def test_a_run_records_its_rig_and_replays_with_it(tmp_path):
    from humanpt.perception.core import PerceptionCore
    from humanpt.runtime.recording import read
    from humanpt.runtime.replay import build_core, replay
    from humanpt.sim_camera import SimCameraConfig
    from humanpt.twin.system import build_system

    # The world's camera is the calibrated rig's (an exact calibration), not the nominal one.
    cam = SimCameraConfig(psvs=CALIBRATED.psvs, flange_T_camera_mm_deg=CALIBRATED.hand_eye.flange_T_camera_x)
    w = build_system("static", sim_camera=cam, rig=CALIBRATED, run_dir=tmp_path, robot="standin")
    w.run_for(1.5)
    w.close()
    rec = read(tmp_path / "perception.mcap")
    assert rig_from_json(rec.metadata["rig"]) == CALIBRATED
    assert build_core(rec).rig == CALIBRATED
    res = replay(tmp_path / "perception.mcap")
    assert res.divergence is None and res.compared > 10
    # The same inputs through the nominal rig give other outputs: the recorded rig matters.
    nominal = PerceptionCore(build_core(rec).config, Rig())
    outs = [nominal.step(e.t_ns, e.topic, e.decode()) for e in rec.inputs]
    recorded = [e for e in rec.outputs if e.topic == "perception/tob"]
    got = [m for o in outs for t, m in o if t == "perception/tob"]
    assert len(got) == len(recorded) > 10
    assert any(g.SerializeToString() != r.data for g, r in zip(got, recorded, strict=True))


def test_a_recording_without_a_rig_is_refused_with_a_reason(tmp_path):
    from humanpt.perception.config import PerceptionConfig
    from humanpt.perception.core import PerceptionCore
    from humanpt.runtime.recording import Recorder, RecordingError, read
    from humanpt.runtime.replay import build_core

    meta = PerceptionCore(PerceptionConfig()).recording_metadata("test")
    del meta["rig"]
    Recorder(tmp_path / "old.mcap", meta).close()
    with pytest.raises(RecordingError, match="without a rig"):
        build_core(read(tmp_path / "old.mcap"))


def test_live_components_serve_their_rig_and_rig_show_finds_a_mismatch(router, procs, tmp_path):  # noqa: F811
    port, _ = router
    write_rig(tmp_path / "rig.toml", CALIBRATED)
    write_rig(tmp_path / "other.toml", Rig())
    a = write_config(tmp_path / "a.toml", port, 'rig = "rig.toml"\n')
    b = write_config(tmp_path / "b.toml", port, 'rig = "other.toml"\n')
    procs.start("perception", "--config", str(a), "--run-dir", str(tmp_path / "run"))
    r = None

    def served():
        nonlocal r
        r = run_cli_here("rig", "show", "--config", str(a), "--json")
        return r.returncode == 0

    wait_for(served, 30, "perception serving its rig")
    assert "1003.5" in r.stdout and "perception" in r.stdout
    body = json.loads(r.stdout[r.stdout.index("{"):])
    assert rig_from_table(body["perception"]) == CALIBRATED
    procs.start("pose_filter", "--config", str(b), "--run-dir", str(tmp_path / "run"))

    def mismatch():
        nonlocal r
        r = run_cli_here("rig", "show", "--config", str(a))
        return "ANOTHER rig" in r.stdout

    wait_for(mismatch, 30, "rig show seeing two rigs")
    assert r.returncode == 1 and "psvs.a_u" in r.stdout, r.stdout
