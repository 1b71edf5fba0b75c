"""A refused attempt is reported: ``[runtime] report_denied`` (default true) makes the router
(``humanpt router``, a process of its own) publish a warning event on ``router/events``
for what its access control refused (issue 19 item 2, "where zenoh allows")."""

from __future__ import annotations

import re

import zenoh

from humanpt.runtime import security
from humanpt.runtime.bus import zenoh_config
from humanpt.runtime.config import load
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from tests.conftest import free_port, wait_port, write_config
from tests.security.test_mtls import Inbox


def _mtls_router(tmp_path, procs):
    """A cell's PKI (router, perception, tool) and ``humanpt router`` under mTLS, reporting
    refusals: (the runtime config, the router process)."""
    pki = tmp_path / "pki"
    security.init_ca(pki, "test")
    for name in ("router", "perception", "tool"):
        security.issue(pki, name)
    port = free_port()
    cfg = write_config(tmp_path / "cell.toml", port, extra='security = "mtls"\npki = "pki"\n')
    router = procs.start("router", "--config", str(cfg))
    wait_port(port)
    return load(cfg).runtime, router


def test_the_router_reports_what_it_refused(tmp_path, procs):
    rt, router = _mtls_router(tmp_path, procs)
    events = Inbox()
    command = topics.TOPICS["controller/command"].key("test")
    with zenoh.open(zenoh_config(rt, identity="tool")) as tool, \
            zenoh.open(zenoh_config(rt, identity="perception")) as rogue:
        sub = tool.declare_subscriber(topics.TOPICS["router/events"].key("test"), events)

        def reported(k, v) -> bool:
            return "controller/command" in pb.Event.FromString(v).text

        # The router reports the 1st, 10th, 100th... refusal: keep trying until one is seen
        # (the tool's subscription may reach the router after the first).
        for _ in range(150):
            rogue.put(command, b"rogue")
            if events.wait_for(reported, timeout=0.1):
                break
        assert events.wait_for(reported, timeout=5.0), "no event for the refused command"
        sub.undeclare()
    out = procs.stop(router)
    evs = [pb.Event.FromString(v) for _, v in events.items]
    first = evs[0]
    assert first.code == "access_denied" and first.severity == pb.SEVERITY_WARNING and first.source == "router"
    assert "'perception'" in first.text and "Put" in first.text
    assert "listening on tls/" in out  # the router's own output still goes through
    assert "is authorized" not in out  # zenoh's trace of allowed traffic does not


def test_declaring_a_subscriber_is_not_reported_as_refused_puts(tmp_path, procs):
    """zenoh fills its permission cache for every message kind when a key is first
    declared ("is unauthorized to Put/Query/Reply..." for a tool that only subscribes):
    those lines are not attempts and must not be reported; a real refused put still is."""
    rt, router = _mtls_router(tmp_path, procs)
    events = Inbox()
    command = topics.TOPICS["controller/command"].key("test")

    def refusals(n: int):  # perception's refused puts until the router reports the n-th or later
        def seen(k, v) -> bool:
            m = re.search(r"'perception' \((\d+) so far\)", pb.Event.FromString(v).text)
            return m is not None and int(m.group(1)) >= n
        for _ in range(3 * n):
            rogue.put(command, b"rogue")
            if events.wait_for(seen, timeout=0.05):
                return True
        return events.wait_for(seen, timeout=5.0)

    with zenoh.open(zenoh_config(rt, identity="tool")) as tool, \
            zenoh.open(zenoh_config(rt, identity="perception")) as rogue:
        tool.declare_subscriber(topics.TOPICS["router/events"].key("test"), events)
        assert refusals(10)  # fence: the events reach the tool
        tool.declare_subscriber(command, lambda s: None)  # allowed; the cache fill "denies" the rest
        assert refusals(100)  # fence: the router has handled the declaration and reported since
    procs.stop(router)
    texts = [pb.Event.FromString(v).text for _, v in events.items]
    assert not [t for t in texts if "'tool'" in t], texts


def test_the_trace_is_read_as_attempts_named_by_certificate():
    """zenoh's trace, as 1.10 writes it: a cache fill (not attempts), a direct check naming
    the certificate, then checks from the cache naming only the session (zid): each refusal
    is reported once, with the certificate the zid was seen with."""
    import os

    zid = "97240f66a8c858d6fced9eae2f5c87ec"
    tool = "7eff580b33b852374a3c43dd433879d2"
    t = "TRACE rx-0 ThreadId(09) zenoh::net::routing::interceptor::access_control: "
    key = "humanpt/test/controller/command"
    lines = [
        f"{t}ACL (ingress): caching permissions for `{key}` ...",
        f"{t}{tool} on Interface(lo)+CertCommonName(tool)+Transport(Tls)+{tool} is unauthorized to Put (ingress) on {key}",
        f"{t}{tool} on Interface(lo)+CertCommonName(tool)+Transport(Tls)+{tool} is authorized to Declare Subscriber (ingress) on {key}",
        f"{t}Using cached result: {tool} is authorized to Declare Subscriber (ingress) on {key}",
        f"{t}{zid} on Interface(lo)+CertCommonName(perception)+Transport(Tls)+{zid} is unauthorized to Put (ingress) on {key}",
        f"{t}Using cached result: {zid} is unauthorized to Put (ingress) on {key}",
        "humanpt router: some other output",
    ]
    got = []
    watch = security.DenialWatch(got.append)
    r, w = os.pipe()
    watch._orig_fd = os.open(os.devnull, os.O_WRONLY)
    try:
        os.write(w, ("\n".join(lines) + "\n").encode())
        os.close(w)
        watch._pump(r)
    finally:
        os.close(watch._orig_fd)
    assert [(d.cn, d.message, d.key) for d in got] == [("perception", "Put", key)] * 2
