"""humanpt path compare (issue 21.4, 32.2): a path against the seam, its distances and its
coverage along the seam, the seam's start and end included; the robot's reported path read
from real MCAP recordings (flange in metres, the tool in mm).  Every expectation is worked
out by hand in the comments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from humanpt.geometry.transforms import transform_from_x
from humanpt.runtime.recording import Recorder, RecordingError
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, pose
from humanpt.seam import seamfile
from humanpt.seam.compare import compare_points, played_tool_path
from humanpt.seam.fit import FitConfig, Seam, Segment
from tests.conftest import run_cli_here


def seam_of(*segments: Segment) -> Seam:
    return Seam(tuple(segments), (), (), (), 0.0, FitConfig(), 0)


def line(a, b) -> Segment:
    return Segment("line", 0, 0, tuple(map(float, a)), tuple(map(float, b)), (0.0, 15.0, 180.0), (0.0, 15.0, 180.0),
                   0.0, 0.0, 10)


STRAIGHT = seam_of(line((0, 0, 0), (100, 0, 0)))  # 100 mm along x


def along(x0, x1, offset=(0.0, 0.0), step=1.0):
    x = np.arange(x0, x1 + 1e-9, step)
    return np.column_stack([x, np.full(len(x), offset[0]), np.full(len(x), offset[1])])


def test_an_offset_path_that_starts_late():
    # Played 0.3 mm beside the seam (y) from x = 10 to 100 mm: every distance 0.3 mm; it
    # covers [10, 100] of [0, 100]: 90 %, the seam's first 10 mm never played.
    c = compare_points(STRAIGHT, along(10, 100, (0.3, 0.0)), approach_mm=None)
    assert c.n == 91
    assert c.rms_mm == pytest.approx(0.3) and c.max_mm == pytest.approx(0.3) and c.p95_mm == pytest.approx(0.3)
    assert c.covered == pytest.approx(0.9, abs=1e-3)
    assert (c.largest_gap_mm, c.gap_from_mm, c.gap_to_mm) == pytest.approx((10.0, 0.0, 10.0), abs=0.1)
    assert c.length_mm == pytest.approx(100.0)


def test_a_hole_in_the_middle_and_the_gap_that_bridges_it():
    # 0.3 mm across and 0.4 mm up: 0.5 mm from the seam (3-4-5); played 0..40 and 60..100:
    # the 20 mm between them is longer than gap_mm = 10: 80 % covered, the hole 40..60 mm.
    pts = np.vstack([along(0, 40, (0.3, 0.4)), along(60, 100, (0.3, 0.4))])
    c = compare_points(STRAIGHT, pts, approach_mm=None, gap_mm=10.0)
    assert c.rms_mm == pytest.approx(0.5) and c.max_mm == pytest.approx(0.5)
    assert c.covered == pytest.approx(0.8, abs=1e-3)
    assert (c.largest_gap_mm, c.gap_from_mm, c.gap_to_mm) == pytest.approx((20.0, 40.0, 60.0), abs=0.1)
    # With gap_mm = 25 the two points either side of the hole (20 mm apart) cover it: 100 %.
    c = compare_points(STRAIGHT, pts, approach_mm=None, gap_mm=25.0)
    assert c.covered == pytest.approx(1.0) and c.largest_gap_mm == pytest.approx(0.0)


def test_points_beyond_the_cover_radius_leave_their_stretch_uncovered():
    # Every mm from 0 to 100, those at 50..70 mm 2 mm off the seam (beyond cover_mm = 1):
    # pairs of points both within 1 mm cover [0, 49] and [71, 100]: 78 mm, the largest
    # stretch left 49..71 (22 mm).  Distances: 21 points of 2 mm, 80 of 0: RMS
    # sqrt(21 * 4 / 101) = 0.9119 mm, mean 42 / 101 = 0.4158 mm, max 2 mm at the first of
    # them, (50, 2, 0).
    pts = along(0, 100)
    pts[50:71, 1] = 2.0
    c = compare_points(STRAIGHT, pts, cover_mm=1.0, approach_mm=None)
    assert c.rms_mm == pytest.approx(math.sqrt(84 / 101)) and c.max_mm == pytest.approx(2.0)
    assert c.mean_mm == pytest.approx(42 / 101)
    assert c.worst_mm == pytest.approx((50.0, 2.0, 0.0))
    assert c.covered == pytest.approx(0.78, abs=1e-3)
    assert (c.largest_gap_mm, c.gap_from_mm, c.gap_to_mm) == pytest.approx((22.0, 49.0, 71.0), abs=0.1)


def test_an_arc_followed_a_little_outside():
    # A quarter circle of radius 50 mm (length 25 pi = 78.54 mm) and a path on the circle
    # of radius 50.5 mm every degree: 0.5 mm from it everywhere, all of it covered.
    r, c0 = 50.0, np.array([0.0, 0.0, 0.0])
    arc = Segment("arc", 0, 0, (r, 0.0, 0.0), (0.0, r, 0.0), (0, 15, 180), (90, 15, 180), 0.0, 0.0, 10,
                  centre_mm=tuple(c0), normal=(0.0, 0.0, 1.0), radius_mm=r, sweep_deg=90.0)
    a = np.radians(np.arange(0, 91))
    pts = np.column_stack([50.5 * np.cos(a), 50.5 * np.sin(a), np.zeros(len(a))])
    c = compare_points(seam_of(arc), pts, approach_mm=None)
    assert c.length_mm == pytest.approx(25 * math.pi)
    assert c.rms_mm == pytest.approx(0.5) and c.covered == pytest.approx(1.0, abs=2e-3)


def test_the_approach_before_the_seams_start_is_left_out():
    # From (0, -50, 0) straight to the start, then along the seam 0.3 mm off: the approach
    # points (up to 50 mm off) do not count once the path reaches the start within 0.25 mm.
    approach = np.column_stack([np.zeros(50), np.linspace(-50, -1, 50), np.zeros(50)])
    pts = np.vstack([approach, [[0.0, 0.0, 0.0]], along(1, 100, (0.0, 0.3))])
    c = compare_points(STRAIGHT, pts)
    assert c.n == 101 and c.max_mm == pytest.approx(0.3)


def record_run(run, states_x_m, started_ns=None, done_ns=None, tool_x=(0.0, 0.0, 200.0, 0.0, 0.0, 0.0)):
    """A run directory as the cell records one: controller.mcap (its configuration's tool,
    its playback events) and robot_gateway.mcap (robot states, the flange in metres)."""
    run.mkdir(exist_ok=True)
    with Recorder(run / "controller.mcap", {"component": "controller",
                                            "config": {"flange_T_tool_x": list(tool_x)}}) as ctl:
        for code, t in (("playback_started", started_ns), ("playback_done", done_ns)):
            if t is not None:
                ctl.write("out", t, "controller/events", pb.Event(header=header(t), code=code))
    with Recorder(run / "robot_gateway.mcap", {"component": "robot_gateway"}) as gw:
        for k, x in enumerate(states_x_m):
            T = transform_from_x(np.asarray(x, dtype=float))  # (x, y, z) given in metres here
            gw.write("out", k * 28_000_000, "robot_gateway/robot_state",
                     pb.RobotState(header=header(k * 28_000_000, k, "world"), world_T_flange=pose(T), cycle=k))


def test_the_played_path_is_the_flange_in_mm_times_the_tool(tmp_path):
    # Flange at (0.001 k, 1.0, 0.5) m, pointing down (roll 180 deg: its z is the world's -z);
    # the tool 200 mm along the flange's z: the tool at (k, 1000, 300) mm.  The playback
    # window (started at state 10, done at state 20) keeps states 10..20.
    states = [(0.001 * k, 1.0, 0.5, 0.0, 0.0, 180.0) for k in range(31)]
    record_run(tmp_path / "run", states, started_ns=10 * 28_000_000, done_ns=20 * 28_000_000)
    played = played_tool_path(tmp_path / "run")
    assert "done" in played.window and len(played.tool_mm) == 11
    np.testing.assert_allclose(played.tool_mm, [[k, 1000.0, 300.0] for k in range(10, 21)], atol=1e-9)


def test_a_run_without_the_controllers_recording_is_refused(tmp_path):
    with pytest.raises(RecordingError, match="no controller.mcap"):
        played_tool_path(tmp_path)


def test_path_compare_cli_on_a_recorded_run(tmp_path):
    # The seam from (0, 1000.3, 300) to (100, 1000.3, 300) mm: the played tool (k, 1000, 300)
    # for k = 0..80 runs 0.3 mm beside it and stops 20 mm short of its end: RMS 0.300 mm,
    # 80.0 % covered, the last 20 mm (80 to 100 along the seam) never played.  (The units
    # mixed up - metres times mm - put the tool 200 m away: 1189.8 mm RMS in the issue.)
    states = [(0.001 * k, 1.0, 0.5, 0.0, 0.0, 180.0) for k in range(81)]
    record_run(tmp_path / "run", states, started_ns=0, done_ns=80 * 28_000_000)
    seamfile.write(tmp_path / "s.json", seam_of(line((0, 1000.3, 300), (100, 1000.3, 300))))
    out = run_cli_here("path", "compare", str(tmp_path / "s.json"), str(tmp_path / "run"))
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert "81 states" in text and "(100.0 mm)" in text
    row = lambda name: next(ln for ln in text.splitlines() if name in ln)  # noqa: E731
    assert "0.300" in row("RMS distance") and "0.300" in row("max")
    assert "80.0 %" in row("seam covered")
    assert "20.0 (80.0 to 100.0" in row("largest stretch")


def test_path_compare_cli_names_a_missing_run(tmp_path):
    seamfile.write(tmp_path / "s.json", STRAIGHT)
    out = run_cli_here("path", "compare", str(tmp_path / "s.json"), str(tmp_path / "nothing"))
    assert out.returncode == 2 and "no controller.mcap" in out.stderr and "Traceback" not in out.stderr
