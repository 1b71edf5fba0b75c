"""The live demo's start-up wait (issue 38 item 3, ``humanpt.twin.live._wait_alive``): it
ends when every component's liveliness token is up; when one exits it names it with its
status; when some never come up it names them (and those up), after a wait that each
component coming up restarts (so a loaded machine's slow start is not cut short).

A real router in this process, real liveliness tokens from a client session, real child
processes (an exited one, a running one). The stall limit is the thing tested here, so it
is short; the assertions are on what is said, not on times.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from humanpt.runtime.bus import liveliness_key
from humanpt.runtime.run import load_config
from humanpt.twin import live
from tests.conftest import zenoh_client


@pytest.fixture
def sleeper():
    p = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    yield p
    p.stdin.close()
    p.wait(timeout=30)


@pytest.mark.live
@pytest.mark.timeout(120)
def test_start_up_wait_names_what_failed(router, sleeper):
    port, cfg_path = router
    cfg = load_config(cfg_path)
    exited = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    exited.wait(timeout=60)
    with zenoh_client(port) as s:
        token = s.liveliness().declare_token(liveliness_key("test", "perception"))
        # a process that exited: named with its status at once, whatever is up
        why = live._wait_alive(cfg, ("perception", "controller"), 60.0, [("router", sleeper), ("camera", exited)])
        assert why == "camera (exit 3) exited before every component was up"
        # running, but controller never comes up: named, with what is up
        why = live._wait_alive(cfg, ("perception", "controller"), 1.0, [("router", sleeper)])
        assert why.startswith("controller not up after ") and why.endswith(
            "(running, but no component came up in the last 1 s; up: perception)"), why
        # everything up: nothing to say
        assert live._wait_alive(cfg, ("perception",), 60.0, [("router", sleeper)]) == ""
        token.undeclare()
