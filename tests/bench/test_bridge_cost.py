"""``humanpt bench bridge`` (issue 36): the table of what the Foxglove bridge costs the live
loop, by hand; a bad argument refused before any run.  (The live runs themselves are a
bench, measured and not asserted: `humanpt bench bridge`, figures in the bridge's README.)"""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.bench.summary import BridgeCost


def test_rows_give_each_condition_against_the_run_without():
    cost = BridgeCost(np.array([10.0, 20.0, 30.0]), np.array([11.0, 22.0, 33.0]), rounds=1, seconds=5.0)
    without, with_ = cost.rows()
    # numpy's percentile interpolates linearly: p99 of 10, 20, 30 is 20 + 0.98 x 10 = 29.8
    assert without == ["without the bridge", "3", "20.00", "1.000", "29.80", "1.000"]
    assert with_ == ["with the bridge", "3", "22.00", "1.100", "32.78", "1.100"]


@pytest.mark.parametrize("args", [["--rounds", "0"], ["--seconds", "0"], ["--seconds", "nan"]])
def test_bad_arguments_are_refused_before_any_run(args, cli_main, capsys):
    assert cli_main(["bench", "bridge", *args]) != 0
    err = capsys.readouterr().err
    assert "--seconds must be > 0 and --rounds >= 1" in err
