"""Issue 18's acceptance on the lock-step twin (world ideal): every hard scenario at 20 and
60 mm/s with no filter restart, no hole in the recorded path longer than two camera frames
(beyond the recording interval), and G within 0.5 mm and 0.5 deg of the truth; the source
hidden for 2 s leaves position points with the orientation flagged held; the field of view
keeps a margin. The limits are the issue's words; the truth is the twin's."""

from __future__ import annotations

import pytest

from humanpt.twin.hard import HARD_SCENARIOS, HARD_SPEEDS_MM_S, run_case

pytestmark = [pytest.mark.timeout(300), pytest.mark.twin]


@pytest.mark.parametrize("speed", HARD_SPEEDS_MM_S)
@pytest.mark.parametrize("scenario", HARD_SCENARIOS)
def test_a_hard_case_is_followed_recorded_and_accurate(scenario, speed):
    c = run_case(scenario, speed)
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
