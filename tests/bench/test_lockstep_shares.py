"""The lock-step bench's shares (issue 37.4): where the closed loop's CPU goes, each core,
the codecs, the recorders and the scheduler, against the cores-alone baseline."""

from __future__ import annotations

import pytest

from humanpt.bench.summary import lockstep_speed

pytestmark = pytest.mark.twin


def test_the_recorded_loops_shares_name_every_part_and_add_up():
    ls = lockstep_speed(1.0, record=True)
    names = {k for k, _ in ls.share_rows()}
    assert {"sim_camera", "perception", "pose_filter", "controller", "robot_gateway", "sim_robot", "operator",
            "scene", "decode", "encode", "record", "schedule", "other threads"} <= names
    shares = [float(v.split("%")[0]) for _, v in ls.share_rows()]
    assert sum(shares) == pytest.approx(100.0, abs=0.1 * len(shares))  # each rounded to 0.1
    assert shares == sorted(shares, reverse=True)
    # the loop's one thread spends at most its wall time in the cores (closing adds to the
    # wall time only): the loop can never run faster than its cores alone
    assert ls.cores_alone >= ls.speed > 0.0
    assert ls.twin_s == 1.0
