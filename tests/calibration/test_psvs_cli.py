"""`humanpt calibrate psvs|mirrors`: a twin run writes the rig (old one kept as .bak),
--dry-run writes nothing, the mirrors check exits 1 on a misaligned mirror and 0 after the
calibration, and each kind of bad input is one line, exit 2, the rig untouched."""

from __future__ import annotations

import pytest

from humanpt.runtime.rigfile import load_rig


def _world(tmp_path, body="sources = [\"mirror_tilt\"]\n"):
    f = tmp_path / "world.toml"
    f.write_text(body)
    return str(f)


def test_psvs_writes_the_rig_and_mirrors_then_pass(tmp_path, capsys, cli_main):
    main = cli_main
    rig = tmp_path / "rig.toml"
    world = _world(tmp_path)
    args = ["--twin", "--world", world, "--rig", str(rig), "--poses", "16", "--frames", "2"]
    assert main(["calibrate", "mirrors", *args]) == 1  # the nominal rig: the pan fails
    out = capsys.readouterr().out
    assert "pan about y" in out and "FAIL" in out and not rig.exists()
    assert main(["calibrate", "psvs", "--dry-run", *args]) == 0
    assert not rig.exists()
    assert main(["calibrate", "psvs", *args]) == 0
    written = load_rig(rig)
    assert written.psvs.rotvec_left_deg[1] == pytest.approx(0.1, abs=0.005)
    assert written.psvs_calibration.method == "psvs-ba" and "rotvec_left_deg" in written.psvs_calibration.sigma
    assert main(["calibrate", "psvs", *args]) == 0
    assert (tmp_path / "rig.toml.bak").exists()
    capsys.readouterr()
    assert main(["calibrate", "mirrors", *args]) == 0
    assert "mirrors PASS" in capsys.readouterr().out


@pytest.mark.parametrize("case", ["one_view", "few_poses", "no_recording", "bad_rig", "bad_world"])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, case, cli_main):
    main = cli_main
    rig = tmp_path / "rig.toml"
    rig.write_text("version = 1\n")
    before = rig.read_text()
    args = ["calibrate", "psvs", "--rig", str(rig)]
    if case == "one_view":  # the target seen by the right view only
        args += ["--twin", "--poses", "6", "--world", _world(tmp_path, "[sim_camera]\nview_gain_left = 0.0\n")]
    elif case == "few_poses":
        args += ["--twin", "--poses", "2"]
    elif case == "no_recording":
        args += ["--recording", str(tmp_path / "none.mcap")]
    elif case == "bad_rig":
        rig.write_text("version = 1\n[psvs]\nbaseline_mm = -3.0\n")
        before = rig.read_text()
        args += ["--twin"]
    else:
        args += ["--twin", "--world", str(tmp_path / "nowhere.toml")]
    capsys.readouterr()
    assert main(args) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("humanpt calibrate psvs:")
           and "the twin, world" not in line]
    assert len(err) == 1, err
    assert rig.read_text() == before and not (tmp_path / "rig.toml.bak").exists()


def test_a_recording_of_perception_is_checked_and_one_depth_refused(tmp_path, capsys, cli_main):
    # A real cell's input: perception's recording. The static scenario holds the target at
    # one depth: the mirrors check reads the tilt (x), the PSVS calibration refuses.
    from humanpt.twin.run import SystemConfig, run
    from humanpt.twin.worlds import World

    world = World("tilt x", (), {"sim_camera": {"psvs": {"rotvec_left_deg": [0.05, 0.0, 0.0]}}})
    run(SystemConfig.for_scenario("static", 0, world=world), robot="standin", duration_s=1.0, run_dir=tmp_path / "rec")
    rec = str(tmp_path / "rec" / "perception.mcap")
    rig = tmp_path / "rig.toml"
    assert cli_main(["calibrate", "mirrors", "--recording", rec, "--rig", str(rig)]) == 1
    out = capsys.readouterr().out
    assert "left view tilt about x: +0.050" in out and "turn the left outer mirror about its horizontal axis" in out
    assert cli_main(["calibrate", "psvs", "--recording", rec, "--rig", str(rig)]) == 2
    assert "one depth only" in capsys.readouterr().err and not rig.exists()
