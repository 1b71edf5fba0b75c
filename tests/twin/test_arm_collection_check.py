"""The arm stage warns when its collection ended early (issue 32.4: on arc seed 4 the
robot faulted at pose 8 of 28, the wrist at its limit, and the arm fitted from 8 poses
came out 4-7 sigma off the truth with no warning of its own). The check needs no truth:
the collector's notes and the counts; no twin is run."""

from __future__ import annotations

from humanpt.twin.cal_arm import collection_checks

FAULT = ("pose 8: collection ended, the robot faulted (the controller reports FAULT at cycle 1565; "
         "holding)")


def test_a_collection_that_ended_early_is_a_warning():
    (check,) = collection_checks(["planned pose 6: the move flips a joint (a singularity on the way): skipped",
                                  FAULT], planned=28, collected=8)
    assert not check.met and check.value == 20 and check.limit == 0
    assert check.stage == "arm" and "robot faulted" in check.what
    assert check.line().startswith("WARN arm: poses not collected")


def test_poses_skipped_one_by_one_are_the_plans_margin():
    notes = ["planned pose 6: the move flips a joint (a singularity on the way): skipped",
             "pose 3: skipped, not reached in 20 s (unreachable or clamped by the gateway)"]
    assert collection_checks(notes, planned=28, collected=27) == []
    assert collection_checks([], planned=28, collected=28) == []
