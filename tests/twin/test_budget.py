"""twin.budget and ``humanpt experiment budget``: the error budget of the twin's world
(issue 16), on the static scenario with the stand-in robot (a few seconds in all)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from humanpt.controller.config import ControllerConfig
from humanpt.geometry.psvs import virtual_rotation_from_mirror_tilt_deg
from humanpt.geometry.rig import Rig
from humanpt.twin.budget import CSV_COLUMNS, format_table, plan, run_budget, run_world
from humanpt.twin.worlds import ERROR_SOURCES, World
from tests.conftest import in_process_cli

pytestmark = pytest.mark.twin  # runs the lock-step twin for seconds

ONLY = ("focal", "mirror_tilt", "kinematics")


@pytest.fixture(scope="module")
def budget_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("budget")
    with in_process_cli() as main:  # the switch interval and logging left as they were
        rc = main(["experiment", "budget", "--scenario", "static", "--robot", "standin", "--only", ",".join(ONLY),
                   "--out", str(out)])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def rows(budget_dir):
    with (budget_dir / "budget.csv").open() as f:
        return {r["source"]: r for r in csv.DictReader(f)}


def _depth_mm() -> float:
    # The servo holds the target's G on the camera's axis dz in front of it (ControllerConfig).
    return ControllerConfig().dz_mm


def test_csv_and_png_have_one_row_per_source(budget_dir, rows):
    with (budget_dir / "budget.csv").open() as f:
        reader = csv.reader(f)
        assert tuple(next(reader)) == CSV_COLUMNS
        sources = [r[0] for r in reader]
    # Baseline, each source in ERROR_SOURCES order (kinematics needs the Puma: a row that
    # says it was skipped), then the ones that ran together.
    assert sources == ["ideal", "focal", "mirror_tilt", "kinematics", "all"]
    assert rows["kinematics"]["status"] == "skipped: needs robot puma"
    assert rows["all"]["status"] == "ok"
    png = (budget_dir / "budget.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    assert (budget_dir / "budget.txt").read_text().count("focal") >= 2


def test_ideal_world_records_the_target_to_a_few_hundredths_of_a_mm(rows):
    assert rows["ideal"]["status"] == "ok" and int(rows["ideal"]["n"]) >= 3
    bias = math.dist([float(rows["ideal"][f"me_{c}"]) for c in "xyz"], [0, 0, 0])
    assert bias < 0.05, bias


def test_focal_length_0_3_percent_long_biases_depth_by_z_times_0_003(rows):
    # Triangulation z = a_u b / disparity: the true a_u 0.3 % longer than the rig's makes
    # the pipeline see the target 0.3 % of its depth too close (x = u z / a_u keeps).
    hand_mm = _depth_mm() * 0.003  # 1.8 mm at 600 mm
    ours = abs(float(rows["focal"]["me_z"]))
    assert hand_mm / 1.5 <= ours <= hand_mm * 1.5, (ours, hand_mm)
    assert rows["focal"]["within_1_5x"] == "yes"  # and within 1.5x of issue 16's 1.9 mm


def test_mirror_tilt_biases_depth_as_the_disparity_error_predicts(rows):
    # The left virtual camera pans 0.1 deg (twice the mirror's 0.05 deg): its u shifts by
    # a_u tan(0.1 deg) = 1.75 px, a disparity error; dz = z^2 du / (b a_u) = 7.0 mm at 600 mm.
    psvs = Rig().psvs
    pan_deg = float(np.linalg.norm(virtual_rotation_from_mirror_tilt_deg(0.05)))
    du_px = psvs.a_u * math.tan(math.radians(pan_deg))
    hand_mm = _depth_mm() ** 2 * du_px / (psvs.baseline_mm * psvs.a_u)
    assert 6.5 < hand_mm < 7.5
    ours = abs(float(rows["mirror_tilt"]["me_z"]))
    assert hand_mm / 1.5 <= ours <= hand_mm * 1.5, (ours, hand_mm)


def test_a_world_where_the_target_is_never_found_is_a_row_not_an_error():
    # Issue 16: a virtual camera tilted 0.06 deg out of plane (about x): the left view's
    # sources leave their epipolar rows and no pair is made; the run says so.
    rot = [float(v) for v in virtual_rotation_from_mirror_tilt_deg(0.06, axis=(1.0, 0.0, 0.0))]
    row = run_world(World("out of plane", extra={"sim_camera": {"psvs": {"rotvec_left_deg": rot}}}),
                    "static", 0, "standin", duration_s=2.0)
    assert row.status == "target never found" and row.n == 0 and row.full_fraction == 0.0
    assert np.isnan(row.me).all()


def test_plan_keeps_the_sources_order_skips_other_robots_and_names_unknown_ones():
    names = [s.name for s, _ in plan("puma")]
    assert names == [s.name for s in ERROR_SOURCES]
    assert all(not skip for _, skip in plan("puma"))
    skipped = [s.name for s, skip in plan("standin") if skip]
    assert skipped == [s.name for s in ERROR_SOURCES if s.robot == "puma"] and skipped
    assert [s.name for s, _ in plan("puma", ["tremor", "focal"])] == ["focal", "tremor"]
    with pytest.raises(ValueError, match="nosuch"):
        plan("puma", ["focal", "nosuch"])


def test_cli_refuses_an_unknown_source_before_running(tmp_path, capsys, cli_main):
    out = tmp_path / "b"
    assert cli_main(["experiment", "budget", "--only", "nosuch", "--out", str(out)]) != 0
    assert "nosuch" in capsys.readouterr().err
    assert not out.exists()


def test_the_budget_of_a_stereo_pair_meets_the_same_hand_figures():
    # Issue 35: the error budget of an ordinary stereo pair. The pair is the world's PSVS's
    # two virtual cameras rendered apart, so a focal length 0.3 % long biases the depth by
    # z x 0.003 and a mirror tilted 0.05 deg pans one camera 0.1 deg: the same disparity error
    # as above, the same hand figures (1.8 mm, 7.0 mm at 600 mm).
    focal = run_world(World.only("focal"), "static", 0, "standin", source="focal", rig_kind="stereo")
    tilt = run_world(World.only("mirror_tilt"), "static", 0, "standin", source="mirror_tilt", rig_kind="stereo")
    assert focal.status == tilt.status == "ok" and focal.n >= 3 and tilt.n >= 3
    hand_focal = _depth_mm() * 0.003
    assert hand_focal / 1.5 <= abs(focal.me[2]) <= hand_focal * 1.5, (focal.me, hand_focal)
    psvs = Rig().psvs
    du_px = psvs.a_u * math.tan(math.radians(float(np.linalg.norm(virtual_rotation_from_mirror_tilt_deg(0.05)))))
    hand_tilt = _depth_mm() ** 2 * du_px / (psvs.baseline_mm * psvs.a_u)
    assert hand_tilt / 1.5 <= abs(tilt.me[2]) <= hand_tilt * 1.5, (tilt.me, hand_tilt)
    text = format_table([focal, tilt], "static", 0, "standin", "stereo")
    assert "an ordinary stereo pair" in text


def test_a_rig_kind_is_checked_before_anything_runs(tmp_path, capsys, cli_main):
    with pytest.raises(ValueError, match="rig kind 'mono'"):
        run_budget("static", 0, "standin", only=["focal"], rig_kind="mono")
    # the flag is the budget's: another experiment refuses it by name, nothing written
    out = tmp_path / "s"
    with pytest.raises(SystemExit, match="--rig-kind applies to experiment budget"):
        cli_main(["experiment", "static", "--rig-kind", "stereo", "--out", str(out)])
    assert not out.exists()
