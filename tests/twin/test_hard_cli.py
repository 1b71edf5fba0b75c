"""``humanpt experiment hard``: bad input is said once, before any run, and nothing is written."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("argv, fragment", [
    (["--speeds", "x"], "--speeds: numbers (mm/s) separated by commas"),
    (["--speeds", "-5"], "--speeds: each within (0, 1000]"),
    (["--scenario", "no_such_scenario"], "no_such_scenario"),
    (["--world", "ideal+no_such_source"], "no_such_source"),
    (["--set", "pose_filter.no_such_key=1"], "no_such_key"),
])
def test_bad_input_is_one_clear_message_and_nothing_runs(cli_main, tmp_path, capsys, argv, fragment):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        cli_main(["experiment", "hard", "--out", str(out), *argv])
    assert e.value.code not in (0, None)
    assert fragment in str(e.value.code) + capsys.readouterr().err
    assert not out.exists()


def test_world_and_speeds_belong_to_hard_only(cli_main):
    with pytest.raises(SystemExit) as e:
        cli_main(["experiment", "arc", "--speeds", "20"])
    assert "--speeds applies to experiment budget or hard" in str(e.value.code)
