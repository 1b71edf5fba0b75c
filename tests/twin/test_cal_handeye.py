"""Hand-eye calibration on the twin (humanpt.twin.cal_handeye) and its CLI: the robot moves
itself around the fixed target through the normal command path, and AX = YB finds the
world's true hand-eye (the world's truth is the expected value; the tool never reads it
to estimate). Bad input: a robot that faults, too few poses: a clear message, exit 2,
the rig untouched."""

from __future__ import annotations

import json

import numpy as np
import pytest

from humanpt.calibration.handeye import HandEyeError, pose_difference
from humanpt.geometry.rig import Rig
from humanpt.geometry.transforms import invert_transform, transform_from_x
from humanpt.runtime.rigfile import load_rig, write_rig
from humanpt.twin.cal_handeye import DEFAULT_POSES, calibrate_hand_eye_on_twin
from humanpt.twin.worlds import World

# The camera 0.5 mm along flange x and 0.1 deg in pitch off the rig's nominal: both of the
# world's hand-eye error sources at once (World.only("hand_eye_mm", "hand_eye_deg") would
# apply only the last, as each sets the whole transform).
TRUE_X = [0.5, 60.0, 100.0, 0.0, 0.1, 0.0]
HAND_EYE_WORLD = World("hand-eye", (), {"sim_camera": {"flange_T_camera_mm_deg": TRUE_X}})

FAULTING_ROBOT = """name = "a robot that faults on its first move"
[sim_robot]
max_joint_speed_deg_s = 1.0
"""


@pytest.fixture(scope="module")
def calibrated():
    done = []
    result, report, truth = calibrate_hand_eye_on_twin(HAND_EYE_WORLD, Rig(), 0, progress=lambda d, n: done.append(d))
    return result, report, truth, done


def test_the_hand_eye_is_found_within_the_acceptance(calibrated):
    result, report, truth, done = calibrated
    dt, da = pose_difference(result.flange_T_camera_mm, transform_from_x(np.array(TRUE_X)))
    assert dt < 0.2 and da < 0.05, (dt, da)
    # better than the nominal rig it started from (0.5 mm, 0.1 deg off)
    assert result.n_poses >= 10 and done[-1] == DEFAULT_POSES
    # the report: per-pose measurements and residuals, the estimate with its sigma, the truth
    assert any("spread: translation RMS" in s for s in report)
    assert any("flange_T_camera (X)" in s and "+-" in s for s in report)
    assert "estimate off by" in truth[1]
    # a stereo measurement at 600 mm and an ideal robot: residuals of hundredths of a mm
    assert np.sqrt(np.mean(result.residual_mm**2)) < 0.1


def test_the_planned_poses_tilt_the_camera_about_two_axes(calibrated):
    result = calibrated[0]
    # Y, the target in the world, is where the poses' measurements put it: its
    # consistency shows that the poses really turned (rotation residuals are small
    # against tilts of 10-20 deg)
    assert np.max(result.residual_deg) < 0.2
    assert pose_difference(result.world_T_target_mm,
                           transform_from_x([236.132, 1248.772, 85.284, -2.598, -0.883, -4.535]))[0] < 1.0


def test_a_faulting_robot_is_a_clear_error_and_nothing_is_written(tmp_path, capsys, cli_main):
    world = tmp_path / "faulting.toml"
    world.write_text(FAULTING_ROBOT)
    with pytest.raises(HandEyeError, match="the robot faulted"):
        calibrate_hand_eye_on_twin(World.named(str(world)), Rig(), 0)
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    before = rig.read_bytes()
    assert cli_main(["calibrate", "hand-eye", "--twin", "--world", str(world), "--rig", str(rig)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("humanpt calibrate hand-eye: the robot faulted") and "nothing written" in err
    assert rig.read_bytes() == before and not (tmp_path / "rig.toml.bak").exists()


def _pairs_file(path, n=8, degenerate=False):
    """Pairs a live cell would have collected, made from a known X and Y."""
    X = transform_from_x(np.array(TRUE_X))
    Y = transform_from_x([236.1, 1248.8, 85.3, -2.6, -0.9, -4.5])
    F0 = Y @ invert_transform(transform_from_x([0, 0, 600, 0, 0, 0])) @ invert_transform(X)
    out = []
    for k in range(n):
        rv = [0.0, 0.0, 0.2 * k] if degenerate else [0.15 * np.cos(k), 0.15 * np.sin(k), 0.1 * (k % 3)]
        A = F0 @ transform_from_x([10.0 * k, 0, 0, *np.degrees(rv)])
        out.append({"world_T_flange": A.tolist(), "camera_T_target": (invert_transform(X) @ invert_transform(A) @ Y).tolist()})
    path.write_text(json.dumps(out))
    return path


def test_the_cli_writes_the_rig_from_pairs(tmp_path, capsys, cli_main):
    rig = tmp_path / "rig.toml"
    pairs = _pairs_file(tmp_path / "pairs.json")
    assert cli_main(["calibrate", "hand-eye", "--pairs", str(pairs), "--rig", str(rig), "--dry-run"]) == 0
    assert not rig.exists()
    assert cli_main(["calibrate", "hand-eye", "--pairs", str(pairs), "--rig", str(rig)]) == 0
    out = capsys.readouterr().out
    assert "hand-eye AX = YB from 8 poses" in out and f"wrote [hand_eye] to {rig}" in out
    he = load_rig(rig).hand_eye
    assert he.calibration.method == "ax=yb" and he.calibration.date.endswith("Z")
    assert np.allclose(he.flange_T_camera_x, TRUE_X, atol=1e-6)
    assert cli_main(["calibrate", "hand-eye", "--pairs", str(pairs), "--rig", str(rig)]) == 0
    assert (tmp_path / "rig.toml.bak").exists()


@pytest.mark.parametrize("args, message", [
    (["--twin", "--poses", "2"], "--poses 2: too few"),
    (["--pairs", "DEGENERATE"], "degenerate motion: every relative rotation is about one axis"),
    (["--pairs", "FEW"], "too few poses: 2"),
    (["--pairs", "missing.json"], "no such pairs file"),
    ([], "give one of --twin"),
    (["--twin", "--live"], "give one of --twin"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, cli_main, args, message):
    rig = tmp_path / "rig.toml"
    write_rig(rig, Rig())
    before = rig.read_bytes()
    if "DEGENERATE" in args:
        args = ["--pairs", str(_pairs_file(tmp_path / "d.json", degenerate=True))]
    if "FEW" in args:
        args = ["--pairs", str(_pairs_file(tmp_path / "f.json", n=2))]
    if "missing.json" in args:
        args = ["--pairs", str(tmp_path / "missing.json")]
    assert cli_main(["calibrate", "hand-eye", *args, "--rig", str(rig)]) == 2
    err = [s for s in capsys.readouterr().err.splitlines() if s.strip()]
    assert len(err) == 1 and message in err[0], err
    assert rig.read_bytes() == before and not (tmp_path / "rig.toml.bak").exists()


def test_the_puma_check_drops_moves_through_the_wrist_singularity():
    from humanpt.calibration.handeye import plan_poses, puma_move_check
    from humanpt.twin.run import SystemConfig
    from humanpt.twin.system import puma_cores
    from humanpt.twin.world import start_flange_for

    cfg = SystemConfig.for_scenario("static")
    start = start_flange_for(cfg.operator, 600.0, cfg.sim_camera.flange_T_camera)
    _, gateway = puma_cores(start)
    check = puma_move_check(gateway.world_T_base_mm_deg)
    unchecked, _ = plan_poses(start, Rig().hand_eye.flange_T_camera_mm(), 600.0, n_poses=12, seed=0)
    refused = [check(start, p) for p in unchecked[1:]]
    # tilts of 10-20 deg from the Puma's start (q5 = 25 deg) cross the wrist singularity
    assert any(r and "singularity" in r for r in refused)
    checked, notes = plan_poses(start, Rig().hand_eye.flange_T_camera_mm(), 600.0, n_poses=12, seed=0, check=check)
    assert len(checked) == 12 and any("singularity" in n for n in notes)
    assert all(check(a, b) is None for a, b in zip(checked[:-1], checked[1:], strict=True))
