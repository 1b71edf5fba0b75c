"""The twin's worlds (issue 16.2, 16.3): the truth differs from the rig only where a world
says so; the ideal world's arc has no twin-made spikes; a realistic world runs."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from humanpt.geometry.rig import Rig
from humanpt.runtime.config import ConfigError
from humanpt.twin import evaluate
from humanpt.twin.run import SystemConfig, run
from humanpt.twin.worlds import ERROR_SOURCES, World, load_world


def test_the_ideal_world_is_the_nominal_rig():
    cfg = SystemConfig.for_scenario("arc", world=World.ideal())
    assert cfg.sim_camera.psvs == cfg.rig.psvs == Rig().psvs
    assert cfg.sim_camera.flange_T_camera_mm_deg == cfg.rig.hand_eye.flange_T_camera_x
    assert cfg.robot_overrides == {}


def test_each_error_source_changes_the_world_and_never_the_rig():
    ideal = SystemConfig.for_scenario("arc")
    for src in ERROR_SOURCES:
        cfg = SystemConfig.for_scenario("arc", world=World.only(src.name))
        assert cfg.rig == ideal.rig, src.name
        changed = (cfg.sim_camera != ideal.sim_camera or cfg.operator != ideal.operator
                   or cfg.robot_overrides != ideal.robot_overrides)
        assert changed, f"{src.name} changes nothing"
    real = SystemConfig.for_scenario("arc", world=World.realistic())
    assert real.sim_camera.psvs.a_u == 1003.0 and real.operator.tremor_mm == 0.2
    assert real.robot_overrides["sim_robot"]["lag_time_constant_ms"] == 20.0


def test_set_goes_over_the_world():
    cfg = SystemConfig.for_scenario("arc", 0, {"sim_camera": {"psvs": {"a_u": 1001.0}}}, world=World.only("focal"))
    assert cfg.sim_camera.psvs.a_u == 1001.0 and cfg.sim_camera.psvs.a_v == 1003.0


def test_bad_worlds_are_named(tmp_path):
    with pytest.raises(ConfigError, match="no error source 'wobble'"):
        World.only("wobble")
    with pytest.raises(ConfigError, match="not 'ideal', 'realistic'"):
        World.named("perfect")
    f = tmp_path / "w.toml"
    f.write_text('sources = ["focal"]\n[perception]\nthreshold = 10\n')
    with pytest.raises(ConfigError, match=r"\[perception\] is not a twin section"):
        load_world(f)
    f.write_text('sources = ["focal"]\n[sim_camera]\nno_such_key = 1\n')
    with pytest.raises(ConfigError, match="no_such_key"):
        SystemConfig.for_scenario("arc", world=load_world(f))
    f.write_text('sources = ["kinematics"]\n[sim_robot]\nlag_time_constant_ms = -1\n')
    with pytest.raises(ConfigError, match="lag_time_constant_ms"):
        SystemConfig.for_scenario("arc", world=load_world(f))


def test_a_world_file_reads_sources_and_sections(tmp_path):
    f = tmp_path / "cell.toml"
    f.write_text('name = "cell 7"\nsources = ["stamp_offset"]\n[sim_camera.psvs]\na_u = 1002.0\n'
                 '[sim_robot]\nlag_time_constant_ms = 15.0\n')
    w = load_world(f)
    assert w.name == "cell 7" and w.sources == ("stamp_offset",)
    cfg = SystemConfig.for_scenario("arc", world=w)
    assert cfg.sim_camera.psvs.a_u == 1002.0 and cfg.sim_camera.stamp_offset_ms == 5.0
    assert cfg.robot_config("sim_robot").lag_time_constant_ms == 15.0


def _path_error_mm(cfg, robot="puma", duration_s=None):
    res = run(cfg, robot=robot, duration_s=duration_s, record_from_s=cfg.operator.start_delay_s, digest=False)
    start = evaluate.scenario_start_ns(res.world)
    _, err, _ = evaluate.path_truth_errors(res.world, after_ns=start)
    return err


def test_the_ideal_arc_has_no_spike_when_the_robot_accelerates():
    # Issue 16's acceptance: no path error above 0.3 mm on the arc in the ideal world (the
    # twin once added 1.8-6.9 mm to the camera's truth, and the filter 0.3 mm by
    # extrapolating robot states, whenever the robot accelerated).
    cfg = SystemConfig.for_scenario("arc", 0)
    err = _path_error_mm(cfg, duration_s=cfg.operator.start_delay_s + 8.0)
    assert len(err) > 20
    assert np.linalg.norm(err[:, :3], axis=1).max() < 0.3, np.abs(err[:, :3]).max(axis=0)


def test_a_known_world_error_shows_in_the_path_as_its_size_says():
    # A camera 0.5 mm off its nominal place along flange x (the rig does not know): the
    # recorded target is 0.5 mm off along the world axis the flange's x points to.
    cfg = SystemConfig.for_scenario("static", 0, world=World.only("hand_eye_mm"))
    err = _path_error_mm(cfg, robot="standin", duration_s=cfg.operator.start_delay_s + 2.0)
    ideal = _path_error_mm(SystemConfig.for_scenario("static", 0), robot="standin",
                           duration_s=cfg.operator.start_delay_s + 2.0)
    shift = np.linalg.norm(err[:, :3].mean(axis=0) - ideal[:, :3].mean(axis=0))
    assert abs(shift - 0.5) < 0.05, shift


def _cli(main, *args) -> int:
    """``humanpt ARGS``'s exit code, by ``main`` in this process; a SystemExit's message goes
    to stderr, as the interpreter would print it."""
    try:
        return main(list(args))
    except SystemExit as e:
        if e.code is None or isinstance(e.code, int):
            return e.code or 0
        print(e.code, file=sys.stderr)
        return 1


@pytest.mark.twin  # (main runs the lock-step twin: the conftest cannot see it by name)
def test_demo_runs_a_realistic_world_and_keeps_rig_and_world(tmp_path, capsys, cli_main):
    # (the CLI in this process: the process boundary is not what is tested)
    assert _cli(cli_main, "demo", "--lockstep", "--world", "realistic", "--duration", "6", "--run-dir",
                str(tmp_path)) == 0
    out = capsys.readouterr().out
    assert f"world realistic ({len(World.realistic().sources)} error sources" in out and "recorded path of G" in out, out
    assert load_world(tmp_path / "world.toml") == World.realistic()
    from humanpt.runtime.rigfile import load_rig

    assert load_rig(tmp_path / "rig.toml") == Rig()
    assert _cli(cli_main, "demo", "--lockstep", "--world", "perfect", "--run-dir", str(tmp_path / "x")) != 0
    said = capsys.readouterr()
    assert "not 'ideal', 'realistic'" in (said.out + said.err)
