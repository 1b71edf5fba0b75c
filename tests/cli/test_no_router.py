"""Tools without a router, or asked for a topic that does not exist, say so in one line and
exit non-zero (issue 20, item 4)."""

from __future__ import annotations

import pytest

from tests.conftest import free_port, run_cli


@pytest.mark.parametrize("verb", [["topics"], ["echo", "camera/image", "-n", "1"], ["param", "controller"]])
def test_no_router_is_one_line_and_exit_1(tmp_path, verb):
    cfg = tmp_path / "h.toml"
    cfg.write_text(f'[runtime]\nconnect = ["tcp/127.0.0.1:{free_port()}"]\nconnect_timeout_s = 1.0\n')
    r = run_cli(*verb, "--config", str(cfg), timeout=60)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "cannot reach the router" in r.stderr and "humanpt router" in r.stderr


def test_echo_of_an_unknown_topic_names_the_near_ones(tmp_path):
    r = run_cli("echo", "camera/imag", "-n", "1")
    assert r.returncode == 2 and "no topic 'camera/imag'" in r.stderr and "camera/image" in r.stderr


def test_a_tool_gives_up_on_the_router_after_its_own_timeout_not_the_components(tmp_path):
    # Components wait connect_timeout_s for a router still starting; a person at a tool
    # waits tool_connect_timeout_s (issue 20: one line within seconds).  Were the
    # component's 600 s used, this would run into the test's timeout.
    cfg = tmp_path / "h.toml"
    cfg.write_text(f'[runtime]\nconnect = ["tcp/127.0.0.1:{free_port()}"]\nconnect_timeout_s = 600.0\n'
                   "tool_connect_timeout_s = 0.5\n")
    r = run_cli("topics", "--config", str(cfg), timeout=120)
    assert r.returncode == 1 and "cannot reach the router" in r.stderr, r.stderr
