"""The CLI: every verb has a --help that helps; errors are clear."""

from __future__ import annotations

import pytest

from humanpt.cli.main import TEST_ONLY_COMPONENTS, build_parser, main
from humanpt.runtime.registry import COMPONENTS

VERBS = ["router", "up", "topics", "echo", "param", "replay", "runs", "config", "bench", *COMPONENTS]
USER_VERBS = [v for v in VERBS if v not in TEST_ONLY_COMPONENTS]


@pytest.mark.parametrize("verb", VERBS)
def test_every_verb_has_help(verb, capsys):
    with pytest.raises(SystemExit) as e:
        main([verb, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: humanpt " + verb)
    assert len(out.splitlines()) > 4


def test_top_level_help_lists_every_verb(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for verb in USER_VERBS:
        assert f"    {verb}" in out


def test_test_only_components_are_not_user_verbs(capsys, cli_main):
    # issue 30: pinger and ponger (the runtime's self-test pair) are not listed to users...
    assert TEST_ONLY_COMPONENTS == {"pinger", "ponger"}
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert "pinger" not in out.split("options:")[0] and "ponger" not in out.split("options:")[0]
    # ...but still run for the tests (their --help, a config check through them)
    with pytest.raises(SystemExit) as e:
        main(["pinger", "--help"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("usage: humanpt pinger")


def test_no_verb_prints_help_and_fails(capsys, cli_main):
    assert cli_main([]) == 2
    assert "usage: humanpt" in capsys.readouterr().out


def test_config_check_names_the_bad_key(tmp_path, capsys, cli_main):
    f = tmp_path / "h.toml"
    f.write_text("[ponger]\nprefx = 'x'\n")
    assert cli_main(["config", "--config", str(f), "--check"]) == 2
    err = capsys.readouterr().err
    assert f"{f}: [ponger] unknown key 'prefx'" in err
    f.write_text("[ponger]\nprefix = 'x'\n")
    assert cli_main(["config", "--config", str(f), "--check"]) == 0
    assert cli_main(["config", "--config", str(f)]) == 0
    assert 'prefix = "x"' in capsys.readouterr().out


def test_unknown_profile_and_component_are_named(tmp_path, capsys, cli_main):
    assert cli_main(["up", "--profile", "nosuch"]) == 2
    assert "unknown profile 'nosuch'" in capsys.readouterr().err
    assert cli_main(["up", "--components", "pinger,warp_drive"]) == 2
    assert "warp_drive" in capsys.readouterr().err


def test_topic_table(capsys, cli_main):
    assert cli_main(["topics", "--table"]) == 0
    out = capsys.readouterr().out
    assert "perception/tob" in out and "humanpt.TobMeasurement" in out and "foxglove.RawImage" in out


def test_parser_builds():
    assert build_parser().prog == "humanpt"
