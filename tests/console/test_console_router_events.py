"""The console shows the router's refusals (issue 19 item 2, "reported by the console"):
under mTLS ``humanpt router`` publishes an ``access_denied`` warning on ``router/events``
for what its access control refused; ``humanpt console events`` prints it as it prints
any component's events, and a console whose own command the router refuses says so
instead of waiting for an answer that cannot come. A real router process, real
certificates, the console as a process."""

from __future__ import annotations

import os
import selectors
import time

import pytest
import zenoh

from humanpt.runtime import security
from humanpt.runtime.bus import zenoh_config
from humanpt.runtime.config import load
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from tests.conftest import free_port, run_cli, wait_port, write_config

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def secure_cell(tmp_path, procs):
    pki = tmp_path / "pki"
    security.init_ca(pki, "test")
    for name in ("router", "perception", "robot_gateway", "tool"):
        security.issue(pki, name)
    port = free_port()
    cfg = write_config(tmp_path / "cell.toml", port, extra='security = "mtls"\npki = "pki"\n')
    router = procs.start("router", "--config", str(cfg))
    wait_port(port)
    return cfg, router


def test_console_events_shows_the_routers_refusals(secure_cell, procs):
    cfg, router = secure_cell
    rt = load(cfg).runtime
    con = procs.start("console", "--config", str(cfg), "--as", "tool", "events", "--duration", "30", live=True)
    command = topics.TOPICS["controller/command"].key("test")
    with zenoh.open(zenoh_config(rt, identity="perception")) as rogue, \
            zenoh.open(zenoh_config(rt, identity="robot_gateway")) as gw:
        # a component's own warning too: the console shows both kinds alike
        gw_events = topics.TOPICS["robot_gateway/events"].key("test")
        marker = pb.Event(severity=pb.SEVERITY_WARNING, source="robot_gateway", code="bench_marker", text="x")
        # Keep trying until the console shows the refusal (the router reports the 1st, 10th,
        # 100th... per identity/message/key; the console's subscription may come after the 1st).
        buf = ""  # the console's output so far (a read may end mid-line)
        deadline = time.monotonic() + 25
        os.set_blocking(con.stdout.fileno(), False)
        sel = selectors.DefaultSelector()
        sel.register(con.stdout, selectors.EVENT_READ)
        i = 0
        while time.monotonic() < deadline:
            rogue.put(command, b"rogue")
            if i % 10 == 0:
                gw.put(gw_events, marker.SerializeToString())
            i += 1
            if sel.select(0.1):
                buf += con.stdout.read() or ""
            if shown(buf.splitlines(), command):
                break
    out = buf + procs.stop(con)
    procs.stop(router)
    assert shown(out.splitlines(), command), out


def shown(lines: list[str], command: str) -> bool:
    """Whether the console printed the router's refusal of a Put on ``command`` and the
    gateway's warning, each as an event line."""
    return (any(line.startswith("event router WARNING access_denied:") and f"refused Put (ingress) on {command} from "
                in line for line in lines)
            and any(line.startswith("event robot_gateway WARNING bench_marker: x") for line in lines))


def test_a_command_the_router_refuses_is_said_so(secure_cell):
    """A tool's certificate may not command (only an operator's): the console's record
    start is refused at the router; the console says so (the router's access_denied, or,
    when the router reported an earlier refusal of the same kind already, the timeout
    naming the certificate), not a plain "is it running?"."""
    cfg, _ = secure_cell
    rt = load(cfg).runtime
    with zenoh.open(zenoh_config(rt, identity="robot_gateway")) as gw:  # a listener on console/command
        got: list[bytes] = []
        sub = gw.declare_subscriber(topics.TOPICS["console/command"].key("test"),
                                    lambda s: got.append(s.payload.to_bytes()))
        r = run_cli("console", "--config", str(cfg), "--as", "tool", "--timeout", "3", "record", "start",
                    timeout=40)
        sub.undeclare()
    assert r.returncode == 1, r.stdout + r.stderr
    said = r.stdout + r.stderr
    assert ("REFUSED by the router" in said and "console/command" in said) or \
        ("only an operator's certificate may command" in said and "'tool'" in said), said
    assert got == [], "the tool's command reached a subscriber"
