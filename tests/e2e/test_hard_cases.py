"""Issue 18's acceptance on the lock-step twin (world ideal): every hard scenario at 20 and
60 mm/s with no filter restart, no hole in the recorded path longer than two camera frames
(beyond the recording interval), and G within 0.5 mm and 0.5 deg of the truth; the source
hidden for 2 s leaves position points with the orientation flagged held; the field of view
keeps a margin. The limits are the issue's words; the truth is the twin's.

The pose filter on the same runs (issue 18, item 1): the closed loop (the Puma over its
ALTER line) through ``scurve`` (opposite arcs, sharp corners, a dwell) and ``abrupt``
(instant starts, stops, a reversal, torch turns) at 20 and 60 mm/s. A real change of motion
is never gated, so the filter never restarts and takes every image; its pose at each
image's stamp is within 0.5 mm and 0.5 deg of where the operator really held the target
(the twin's truth). One lock-step run per scenario and speed serves both checks."""

from __future__ import annotations

import pytest

from humanpt.bench.pose_filter import filter_errors
from humanpt.twin.hard import HARD_SCENARIOS, HARD_SPEEDS_MM_S, run_case_world

pytestmark = [pytest.mark.timeout(300), pytest.mark.twin]
FRAME_MS = 1000 / 30  # sim_camera's 30 images/s


@pytest.fixture(scope="module")
def judged():
    """(HardCase, the pose filter's FilterErrors) of one run per (scenario, speed), run on
    first use (the world itself is not kept: its images would take ~200 MB a run)."""
    done = {}

    def get(scenario: str, speed: float):
        if (scenario, speed) not in done:
            case, world = run_case_world(scenario, speed)
            done[scenario, speed] = case, filter_errors(world)
        return done[scenario, speed]

    return get


@pytest.mark.parametrize("speed", HARD_SPEEDS_MM_S)
@pytest.mark.parametrize("scenario", HARD_SCENARIOS)
def test_a_hard_case_is_followed_recorded_and_accurate(judged, scenario, speed):
    c, _ = judged(scenario, speed)
    assert c.filter_resets == 0, c
    assert c.max_gap_frames <= 2.0, c
    assert c.g_maxe_mm <= 0.5 and c.g_maxe_deg <= 0.5, c
    # The target stayed in view with room to spare (a source image never nearer the border
    # than 50 px of the 640 x 480 image).
    assert c.fov_margin_min_px > 50.0, c
    if scenario == "occluded":
        # B hidden 2 s: the points recorded while it is hidden each have the orientation
        # held. The recording takes a point every 280 ms at least and whenever the target
        # moved recording_spacing_mm (4 mm: every 200 ms at 20 mm/s, 67 ms at 60 mm/s), so
        # 2 s gives between 2000/280 and 2000/(1000 x 4/speed) points, +-1 at each edge.
        every_ms = min(280.0, 1000.0 * 4.0 / speed)
        assert 2000 / 280 - 2 <= c.held_points <= 2000 / every_ms + 2, c
    else:
        assert c.held_points == 0, c


@pytest.mark.parametrize("scenario, speed_mm_s", [("scurve", 60.0), ("abrupt", 60.0), ("scurve", 20.0),
                                                  ("abrupt", 20.0)])
def test_abrupt_motion_is_followed_without_a_gate_or_restart(judged, scenario, speed_mm_s):
    _, fe = judged(scenario, speed_mm_s)
    assert len(fe.stamps_ns) > 60 and fe.full.all()  # the target stayed in view, every source seen
    assert fe.resets == 0 and fe.outliers == 0, (fe.resets, fe.outliers)
    assert fe.max_gap_ms < 1.5 * FRAME_MS, fe.max_gap_ms  # every image taken
    assert fe.manoeuvres >= 1  # the manoeuvring model did the work (the calm one gates these)
    assert fe.pos_mm.max() < 0.5 and fe.rot_deg.max() < 0.5, fe.row()
