"""humanpt path retime (issue 21.2): constant feed, bounded acceleration and jerk, a stop
at each corner, the torch's angular limit, samples on the controller's cycle.  The
samples are checked by finite differences here, against the limits given."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.seam.fit import Corner, Dwell, FitConfig, Seam, Segment
from humanpt.seam.retime import RetimeConfig, RetimeError, retime
from tests.conftest import run_cli_here


def line(a, b, ypr0=(0, 15, 180), ypr1=(0, 15, 180)) -> Segment:
    return Segment("line", 0, 0, tuple(map(float, a)), tuple(map(float, b)), tuple(map(float, ypr0)),
                   tuple(map(float, ypr1)), 0.0, 0.0, 10)


def seam_of(segments, corners=(), dwells=()) -> Seam:
    return Seam(tuple(segments), tuple(corners), tuple(dwells), (), 0.0, FitConfig(), 0)


def diffs(timed):
    dt = np.diff(timed.t_s)
    v = np.diff(timed.x[:, :3], axis=0) / dt[:, None]
    a = np.diff(v, axis=0) / dt[1:, None]
    j = np.diff(a, axis=0) / dt[2:, None]
    return dt, np.linalg.norm(v, axis=1), np.linalg.norm(a, axis=1), np.linalg.norm(j, axis=1)


L_CORNER = seam_of([line((0, 0, 0), (100, 0, 0)), line((100, 0, 0), (100, 80, 0))],
                   corners=[Corner((100.0, 0.0, 0.0), 90.0, 0, 1)])


def test_feed_limits_and_the_stop_at_the_corner():
    cfg = RetimeConfig(speed_mm_s=50, accel_mm_s2=300, jerk_mm_s3=3000, cycle_ms=28)
    tm = retime(L_CORNER, cfg)
    dt, v, a, j = diffs(tm)
    np.testing.assert_allclose(dt, 0.028, atol=1e-12)  # every controller cycle
    assert v.max() <= 50 * (1 + 1e-9) and v.max() > 49.9  # the feed is reached on both 80+ mm runs
    assert a.max() <= 300 and j.max() <= 3000 * 1.05  # (finite differences of a smooth ramp)
    np.testing.assert_allclose(tm.x[0, :3], [0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(tm.x[-1, :3], [100, 80, 0], atol=1e-9)
    at_corner = np.flatnonzero(np.linalg.norm(tm.x[:, :3] - [100, 0, 0], axis=1) < 1e-6)
    assert len(at_corner) >= 1 and tm.speed_mm_s[at_corner].max() == 0.0  # it stops there
    # the path between samples is the seam: every sample on one of the two lines
    off = np.minimum(np.abs(tm.x[:, 1]) + np.abs(tm.x[:, 2]), np.abs(tm.x[:, 0] - 100) + np.abs(tm.x[:, 2]))
    assert off.max() < 1e-9


def test_the_torch_turn_lowers_the_feed_to_the_angular_limit():
    turn = seam_of([line((0, 0, 0), (30, 0, 0), (0, 15, 180), (90, 15, 180))])
    tm = retime(turn, RetimeConfig(speed_mm_s=100, accel_mm_s2=5000, jerk_mm_s3=1e6, max_angular_deg_s=60))
    r = Rotation.from_euler("ZYX", tm.x[:, 3:], degrees=True)
    w = np.degrees((r[:-1].inv() * r[1:]).magnitude()) / np.diff(tm.t_s)
    assert w.max() <= 60 * (1 + 1e-6)
    assert tm.feeds_mm_s[0] <= 60 * 30 / 90 + 1e-9  # 90 deg over 30 mm at 60 deg/s: 20 mm/s at most
    np.testing.assert_allclose(tm.x[-1, 3:], [90, 15, 180], atol=1e-6)


def test_a_corner_with_a_new_torch_angle_turns_on_the_spot_within_limits():
    s = seam_of([line((0, 0, 0), (50, 0, 0)), line((50, 0, 0), (50, 50, 0), (20, 15, 180), (20, 15, 180))],
                corners=[Corner((50.0, 0.0, 0.0), 90.0, 0, 1)])
    tm = retime(s, RetimeConfig(max_angular_deg_s=30))
    r = Rotation.from_euler("ZYX", tm.x[:, 3:], degrees=True)
    w = np.degrees((r[:-1].inv() * r[1:]).magnitude()) / np.diff(tm.t_s)
    turning = w > 1e-6
    assert turning.any() and w.max() <= 30 * (1 + 1e-6)
    moving = np.linalg.norm(np.diff(tm.x[:, :3], axis=0), axis=1) > 1e-9
    assert not (turning & moving).any()  # it turns standing still at the corner


def test_a_dwell_is_held():
    s = seam_of([line((0, 0, 0), (40, 0, 0))], dwells=[Dwell((40.0, 0.0, 0.0), 0, 0, 1.5)])
    tm = retime(s)
    still = np.all(np.abs(tm.x[:, :3] - [40, 0, 0]) < 1e-9, axis=1)
    assert tm.t_s[still][-1] - tm.t_s[still][0] >= 1.5
    assert retime(s, RetimeConfig(dwells=False)).duration_s < tm.duration_s - 1.4


def test_a_short_run_never_reaches_the_feed_but_keeps_the_limits():
    tm = retime(seam_of([line((0, 0, 0), (5, 0, 0))]), RetimeConfig(speed_mm_s=100, accel_mm_s2=200))
    _, v, a, _ = diffs(tm)
    assert tm.feeds_mm_s[0] < 100 and a.max() <= 200
    np.testing.assert_allclose(tm.x[-1, :3], [5, 0, 0], atol=1e-9)


@pytest.mark.parametrize("kw, says", [({"speed_mm_s": 150}, "above max_speed"), ({"accel_mm_s2": 0}, "accel"),
                                      ({"cycle_ms": math.nan}, "cycle_ms")])
def test_bad_parameters_are_refused(kw, says):
    with pytest.raises(RetimeError, match=says):
        RetimeConfig(**kw)


def test_cli_refuses_a_speed_above_the_limit_and_writes_nothing(tmp_path):
    from humanpt.seam import seamfile

    f = seamfile.write(tmp_path / "s.json", L_CORNER)
    r = run_cli_here("path", "retime", str(f), "--speed", "150")
    assert r.returncode == 2 and "above max_speed" in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json"]
    ok = run_cli_here("path", "retime", str(f), "--speed", "40")
    assert ok.returncode == 0, ok.stderr
    rows = (tmp_path / "s.timed.csv").read_text().splitlines()
    assert rows[0].startswith("index,t_s,x_mm") and len(rows) > 100


def test_export_takes_the_retimed_samples_and_feed(tmp_path):
    # humanpt path retime -> path export --timed: the JSON program carries every cycle's
    # time and pose, the feed is the retime's; a CSV that is not retime's is refused.
    from humanpt.seam import seamfile

    f = seamfile.write(tmp_path / "s.json", L_CORNER)
    assert run_cli_here("path", "retime", str(f), "--speed", "35", "-o", str(tmp_path / "t.csv")).returncode == 0
    r = run_cli_here("path", "export", str(f), "--format", "json", "--timed", str(tmp_path / "t.csv"), "-o",
                str(tmp_path / "p.json"))
    assert r.returncode == 0, r.stderr
    import json

    prog = json.loads((tmp_path / "p.json").read_text())
    rows = (tmp_path / "t.csv").read_text().splitlines()[1:]
    assert prog["speed_mm_s"] == 35.0 and len(prog["samples"]) == len(rows)
    last = [float(v) for v in rows[-1].split(",")]
    assert prog["samples"][-1]["t_s"] == round(last[1], 6) and prog["samples"][-1]["x_mm"] == [100.0, 80.0, 0.0]
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    r = run_cli_here("path", "export", str(f), "--format", "json", "--timed", str(tmp_path / "bad.csv"), "-o",
                str(tmp_path / "q.json"))
    assert r.returncode == 2 and "not a timed path" in r.stderr and not (tmp_path / "q.json").exists()


TOOL_X = (0.0, 0.0, 200.0, 0.0, 0.0, 0.0)  # the controller's default torch: 200 mm along the flange's z


def flange_speeds(tm, tool_x=TOOL_X):
    """The flange's speed (mm/s) between samples, by finite differences of the flange
    positions worked out with scipy: the tool's pose times the tool's offset inverted."""
    R = Rotation.from_euler("ZYX", tm.x[:, 3:], degrees=True)
    R_ft = Rotation.from_euler("ZYX", tool_x[3:], degrees=True)
    tool_p_flange = -R_ft.inv().apply(tool_x[:3])  # the flange's origin in the tool's frame
    flange = tm.x[:, :3] + R.apply(tool_p_flange)
    return np.linalg.norm(np.diff(flange, axis=0), axis=1) / np.diff(tm.t_s)


def test_a_turn_on_the_spot_swings_the_flange_no_faster_than_its_share_of_the_limit():
    # At the corner the torch pitches from 15 to -45 deg about a horizontal axis through its
    # tip: the flange, 200 mm up the torch, swings at 200 mm per radian, 209 mm/s at 60 deg/s.
    s = seam_of([line((0, 0, 0), (50, 0, 0)), line((50, 0, 0), (50, 50, 0), (0, -45, 180), (0, -45, 180))],
                corners=[Corner((50.0, 0.0, 0.0), 90.0, 0, 1)])
    bare = retime(s, RetimeConfig())
    assert flange_speeds(bare).max() > 150  # planned for the tip alone: beyond the robot's 100 mm/s
    tm = retime(s, RetimeConfig(flange_T_tool_x=TOOL_X, limit_share=0.9))
    v = flange_speeds(tm)
    assert 85.0 < v.max() <= 90.0 * (1 + 1e-3)  # within 90 % of 100 mm/s, and using it
    assert tm.duration_s > bare.duration_s + 1.0  # the corner was given the time it needs
    np.testing.assert_allclose(tm.x[-1], [50, 50, 0, 0, -45, 180], atol=1e-6)


def test_an_arc_whose_torch_swings_the_flange_is_fed_slower():
    # A 60 mm arc at 60 mm/s with the torch pitched 45 deg and following the arc: the flange
    # moves at the tip's 60 mm/s plus the swing 1 rad/s x 141 mm: over 100 mm/s at that feed.
    r, sweep = 60.0, 90.0
    a = Segment("arc", 0, 0, (r, 0.0, 0.0), (0.0, r, 0.0), (90.0, 45.0, 180.0), (180.0, 45.0, 180.0), 0.0, 0.0, 10,
                centre_mm=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), radius_mm=r, sweep_deg=sweep)
    bare = retime(seam_of([a]), RetimeConfig(speed_mm_s=60))
    assert flange_speeds(bare).max() > 100
    tm = retime(seam_of([a]), RetimeConfig(speed_mm_s=60, flange_T_tool_x=TOOL_X, limit_share=0.9))
    assert flange_speeds(tm).max() <= 90.0 * (1 + 1e-3)
    assert tm.feeds_mm_s[0] < 60 and np.linalg.norm(np.diff(tm.x[:, :3], axis=0), axis=1).max() / 0.028 < 60


@pytest.mark.parametrize("kw, says", [({"limit_share": 0.0}, "limit_share"),
                                      ({"flange_T_tool_x": (0, 0, math.inf, 0, 0, 0)}, "flange_T_tool_x"),
                                      ({"flange_T_tool_x": (0, 0, 5000, 0, 0, 0)}, "2000")])
def test_bad_tool_parameters_are_refused(kw, says):
    with pytest.raises(RetimeError, match=says):
        RetimeConfig(**kw)
