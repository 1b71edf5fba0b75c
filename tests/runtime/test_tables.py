"""Tables line up whatever their labels (issue 20, item 4: misaligned columns)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from humanpt.runtime.tables import number, render
from humanpt.twin.evaluate import COORDS, Stats, format_stats
from humanpt.twin.hard import HardCase, format_cases


def right_edges(line: str) -> list[int]:
    """End positions (exclusive) of the whitespace-separated words of a line."""
    edges, inside = [], False
    for i, ch in enumerate(line + " "):
        if ch != " " and not inside:
            inside = True
        elif ch == " " and inside:
            inside = False
            edges.append(i)
    return edges


def test_numbers_end_in_one_column_under_their_header_whatever_the_label():
    labels = ["ME", "MaxE  twin, paper's perception, against the mean", "SD  short"]
    rows = [[lab, "0.0866", "-10.1194"] for lab in labels]
    lines = render(["", "x", "y"], rows).splitlines()
    header, rule, body = lines[0], lines[1], lines[2:]
    assert set(rule) == {"-"} and len(rule) == max(len(ln) for ln in lines)
    # the last two words of every line (the numbers, or the header's x and y) end together
    ends = {tuple(right_edges(ln)[-2:]) for ln in [header, *body]}
    assert len(ends) == 1, lines


def test_left_aligned_columns_start_together_and_blank_rows_separate_groups():
    lines = render(["fault", "note"], [["nan", "held"], (), ["a much longer fault", "x"]], align="ll").splitlines()
    starts = {ln.index(word) for ln, word in ((lines[0], "note"), (lines[2], "held"), (lines[4], "x"))}
    assert len(starts) == 1 and lines[3] == ""


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="cells"):
        render(["a", "b"], [["1"]])
    with pytest.raises(ValueError, match="align"):
        render(["a", "b"], [["1", "2"]], align="lx")


def test_number_marks_what_is_not_a_measurement():
    assert number(math.nan) == "-" and number(math.inf) == "-" and number(1.23456) == "1.2346"


def test_the_hard_case_table_lines_up():
    case = HardCase(scenario="occluded", speed_mm_s=60, filter_resets=0, outliers=0, max_gap_frames=0.6, points=99,
                    held_points=7, g_maxe_mm=0.287, g_maxe_deg=0.211, servo_max_mm=1234.5, fov_margin_min_px=198,
                    frames=300, wall_s=1.0)
    short = HardCase(**{**case.__dict__, "scenario": "abrupt", "servo_max_mm": 1.0})
    lines = format_cases([case, short]).splitlines()
    assert len({tuple(right_edges(ln)[1:]) for ln in (lines[2], lines[3])}) == 1, lines


def test_the_statistics_table_lines_up():
    err = [[0.001, -2.5, 0.3, 10.0, 0.0, -0.01], [0.002, 2.5, -0.3, -10.0, 0.1, 0.01]]
    text = format_stats("t", Stats.of(err)).splitlines()
    assert text[1].split() == list(COORDS)
    assert len({tuple(right_edges(ln)[-6:]) for ln in text[1:]}) == 1, text


def test_a_closed_pipe_ends_the_cli_quietly():
    # `humanpt topics --table | head -0`: the reader is gone before the first line.
    p = subprocess.Popen([sys.executable, "-m", "humanpt.cli.main", "topics", "--table"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=60) == 141 and "Traceback" not in err and "Broken pipe" not in err, err
