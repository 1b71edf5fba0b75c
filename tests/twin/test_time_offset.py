"""Issue 32.4 on the twin: the hand-eye stage measures the camera-to-robot time offset from
its own moves (a known 5 ms injected), writes it to the rig with its sigma, and a rig
file from before (no [timing]) still reads."""

from __future__ import annotations

import tomllib

import pytest

from humanpt.calibration.handeye import apply_to_rig
from humanpt.runtime.rigfile import load_rig, rig_to_toml, write_rig
from humanpt.twin.cal_handeye import calibrate_hand_eye_on_twin
from humanpt.twin.system import nominal_rig, operator_config
from humanpt.twin.worlds import World
from tests.conftest import ROOT


def test_the_hand_eye_stage_finds_an_injected_5_ms_offset_and_writes_it_to_the_rig(tmp_path):
    world = World.named("ideal+stamp_offset")  # the images stamped 5 ms late (sim_camera.stamp_offset_ms)
    rig = nominal_rig(operator_config("trapezium", 0))
    res, report, truth = calibrate_hand_eye_on_twin(world, rig, 0, robot="standin")
    off = res.time_offset
    assert off is not None and off.offset_ms == pytest.approx(5.0, abs=0.5)  # measured: 5.04 +- 0.03
    assert 0 < off.sigma_ms < 0.5
    assert any("time offset" in line for line in report)
    checks = {c.stage: c for c in truth.checks}
    assert checks["time offset"].met and checks["hand-eye"].met
    new = apply_to_rig(rig, res, "2026-11-27T00:00:00Z")
    assert new.timing.camera_time_offset_ms == pytest.approx(off.offset_ms, abs=1e-3)
    assert new.timing.calibration.sigma["camera_time_offset_ms"] == pytest.approx(off.sigma_ms, abs=1e-3)
    assert "timing servo-alignment" in new.methods()
    path = write_rig(tmp_path / "rig.toml", new)
    assert tomllib.loads(path.read_text())["timing"]["camera_time_offset_ms"] == pytest.approx(off.offset_ms, abs=1e-3)
    assert load_rig(path).timing == new.timing


def test_a_rig_file_from_before_reads_with_no_offset(tmp_path):
    old = ROOT / "recordings" / "arc" / "rig.toml"  # written before [timing] existed
    assert "[timing]" not in old.read_text()
    rig = load_rig(old)
    assert rig.timing.camera_time_offset_ms == 0.0 and rig.timing.calibration.method == "nominal"
    assert "timing" not in rig.methods()
    assert "[timing]" in rig_to_toml(rig)  # written from now on
