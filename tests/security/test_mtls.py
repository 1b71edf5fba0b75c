"""mTLS and the generated access control against a real router (issue 19 items 1-2).

A Python session in router mode on loopback, ``[runtime] security = "mtls"``, with the
access control :func:`humanpt.runtime.security.access_control` builds from the topic
table; clients are real sessions with real certificates from a real CA. What is refused
is judged by what a subscriber with the gateway's identity receives (and, so that a
refusal is not mistaken for a slow link, by a positive control through the same router).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import threading

import pytest
import zenoh

from humanpt.bench.faults import intruder_config
from humanpt.runtime import security
from humanpt.runtime.bus import free_tcp_port, liveliness_key, zenoh_config
from humanpt.runtime.config import RuntimeConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from tests.conftest import wait_matching

CELL = "sec"
COMMAND = topics.TOPICS["controller/command"].key(CELL)
TOB = topics.TOPICS["perception/tob"].key(CELL)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """(RuntimeConfig of the cell's clients, the router's session, a foreign PKI dir)."""
    d = tmp_path_factory.mktemp("pki")
    security.init_ca(d, CELL)
    for name in ("router", "controller", "robot_gateway", "perception", "tool"):
        security.issue(d, name)
    security.issue(d, "welder", role="operator")
    # valid for a day, three days ago: expired two days ago
    security.issue(d, "old-tool", role="tool", days=1, now=dt.datetime.now(dt.UTC) - dt.timedelta(days=3))
    foreign = tmp_path_factory.mktemp("foreign-pki")
    security.init_ca(foreign, CELL)  # another CA, same cell name, same names
    security.issue(foreign, "controller")
    port = free_tcp_port()
    ep = (f"tcp/127.0.0.1:{port}",)
    # 1 s: a refused client fails within it (zenoh reports a refused handshake as a timeout)
    rt = RuntimeConfig(cell=CELL, security="mtls", pki=str(d), connect=ep, listen=ep, connect_timeout_s=1.0)
    with zenoh.open(zenoh_config(rt, mode="router", listen=rt.listen, connect=())) as router:
        yield rt, router, foreign


def session(rt: RuntimeConfig, name: str) -> zenoh.Session:
    return zenoh.open(zenoh_config(rt, identity=name))


def bare_config(rt: RuntimeConfig, endpoint: str, tls: dict | None) -> zenoh.Config:
    """A client config by hand (what an intruder would write), not through humanpt's."""
    return intruder_config(endpoint, tls)


def command(seq: int) -> bytes:
    return pb.FlangeCommand(header=pb.Header(seq=seq), cycle=seq).SerializeToString()


class Inbox:
    """What a subscriber received, with an event per arrival."""

    def __init__(self):
        self.items: list[tuple[str, bytes]] = []
        self.arrived = threading.Event()

    def __call__(self, sample: zenoh.Sample) -> None:
        self.items.append((str(sample.key_expr), sample.payload.to_bytes()))
        self.arrived.set()

    def wait_for(self, pred, timeout: float = 5.0) -> bool:
        while not any(pred(k, v) for k, v in list(self.items)):
            self.arrived.clear()
            if any(pred(k, v) for k, v in list(self.items)):
                return True
            if not self.arrived.wait(timeout):
                return False
        return True


def refused(conf: zenoh.Config) -> bool:
    try:
        s = zenoh.open(conf)
    except zenoh.ZError:
        return True
    s.close()
    return False


def test_a_client_without_a_valid_certificate_cannot_connect(cell):
    """(a) no certificate, plaintext; (d) another CA's; (e) an expired one: each refused
    (zenoh.open fails within its 1 s connect timeout); the cell's own certificate connects
    at once through the same router (so the refusals are the certificates')."""
    rt, _, foreign = cell
    ep = rt.connect[0]
    tls_ep = security.tls_endpoint(ep)
    ca = str(security.pki_dir_of(rt) / security.CA_CERT)
    assert refused(bare_config(rt, tls_ep, {"root_ca_certificate": ca})), "a client without a certificate connected"
    assert refused(bare_config(rt, ep, None)), "a plaintext client connected to the TLS port"
    # another CA's controller certificate, presented by a client that trusts our CA
    intruder = {**security.tls_section(foreign, "controller"), "root_ca_certificate": ca}
    assert refused(bare_config(rt, tls_ep, intruder)), "another CA's certificate was accepted"
    assert refused(zenoh_config(rt, identity="old-tool")), "an expired certificate was accepted"
    with session(rt, "tool") as s:  # positive control
        assert str(s.zid())


def test_only_the_controller_identity_commands_the_gateway(cell):
    """(b) a valid non-controller certificate (perception) puts on the command key: the
    router refuses it, the gateway's subscriber never receives it; the controller's put
    reaches it. A tool and an operator cannot put there either."""
    rt, _, _ = cell
    gw_inbox, observer = Inbox(), Inbox()
    with session(rt, "robot_gateway") as gw, session(rt, "tool") as watcher, session(rt, "tool") as tool, \
            session(rt, "controller") as ctl, session(rt, "perception") as rogue, \
            session(rt, "welder") as welder:
        gw_sub = gw.declare_subscriber(COMMAND, gw_inbox)
        # (a session of its own: a session delivers its own puts to its own subscribers)
        obs_sub = watcher.declare_subscriber(f"humanpt/{CELL}/**", observer)
        rogue_cmd = rogue.declare_publisher(COMMAND)
        rogue_tob = rogue.declare_publisher(TOB)
        wait_matching(rogue_cmd)  # the router tells the rogue there is a subscriber: it does send
        wait_matching(rogue_tob)
        for i in range(3):
            rogue_cmd.put(command(1000 + i))
        # A fence: the rogue's own key, which the router lets through after the puts above
        # (one link, in order): once the observer has it, the rogue's commands were handled.
        rogue_tob.put(b"fence")
        assert observer.wait_for(lambda k, v: k == TOB), "the rogue's allowed put never arrived"
        for s in (tool, welder):
            s.put(COMMAND, command(2000))
            s.liveliness().get(liveliness_key(CELL, "*"), timeout=2.0)  # a round trip: the put is handled
        ctl_pub = ctl.declare_publisher(COMMAND)
        wait_matching(ctl_pub)
        ctl_pub.put(command(1))
        assert gw_inbox.wait_for(lambda k, v: v == command(1)), "the controller's command never arrived"
        assert observer.wait_for(lambda k, v: v == command(1)), "the watching tool never saw the command"
        got = [pb.FlangeCommand.FromString(v).cycle for _, v in gw_inbox.items]
        seen = [pb.FlangeCommand.FromString(v).cycle for k, v in observer.items if k == COMMAND]
        for x in (rogue_cmd, rogue_tob, ctl_pub, gw_sub, obs_sub):
            x.undeclare()
    assert got == [1], f"the gateway received commands {got}; only the controller's (cycle 1) may reach it"
    assert seen == [1], f"a tool subscribed to everything saw commands {seen}"


def test_a_liveliness_token_only_under_its_own_name(cell):
    """(c) zenoh issue 1562 (tokens once passed a deny-all ACL): a certified component
    (perception) declares a token named like the controller: the gateway's liveliness
    subscriber never sees it; the real controller's token is seen (positive control),
    and perception's token under its own name is seen by a tool."""
    rt, _, _ = cell
    gw_inbox, tool_inbox = Inbox(), Inbox()
    ctl_key, own_key = liveliness_key(CELL, "controller"), liveliness_key(CELL, "perception")
    with session(rt, "robot_gateway") as gw, session(rt, "tool") as tool, \
            session(rt, "perception") as rogue, session(rt, "controller") as ctl:
        gw_sub = gw.liveliness().declare_subscriber(ctl_key, gw_inbox, history=True)
        tool_sub = tool.liveliness().declare_subscriber(liveliness_key(CELL, "*"), tool_inbox, history=True)
        fake = rogue.liveliness().declare_token(ctl_key)
        own = rogue.liveliness().declare_token(own_key)  # the fence: after the fake one, on one link
        assert tool_inbox.wait_for(lambda k, v: k == own_key), "perception's own token was not seen"
        alive = [str(r.ok.key_expr) for r in tool.liveliness().get(liveliness_key(CELL, "*"), timeout=2.0)
                 if r.ok is not None]
        assert ctl_key not in alive, "the rogue's token named controller passed the router"
        assert not gw_inbox.items, f"the gateway saw a controller token from the rogue: {gw_inbox.items}"
        real = ctl.liveliness().declare_token(ctl_key)
        assert gw_inbox.wait_for(lambda k, v: k == ctl_key), "the real controller's token never arrived"
        for x in (fake, own, real, gw_sub, tool_sub):
            x.undeclare()


def test_tools_read_and_only_operators_set_parameters(cell):
    """A tool may read (subscribe, who is alive, rigs) but not query parameters (a
    parameter query may carry a change); an operator may."""
    rt, _, _ = cell
    from humanpt.runtime.bus import params_key, rig_key

    asked: list[str] = []
    with session(rt, "controller") as ctl, session(rt, "tool") as tool, session(rt, "welder") as welder:
        def serve(key: str):
            def cb(q: zenoh.Query) -> None:
                asked.append(key)
                q.reply(key, b"{}")  # on its own key, as the live shell (a query may be a wildcard)
            return cb

        qp = ctl.declare_queryable(params_key(CELL, "controller"), serve(params_key(CELL, "controller")))
        qr = ctl.declare_queryable(rig_key(CELL, "controller"), serve(rig_key(CELL, "controller")))
        rig_q = tool.declare_querier(rig_key(CELL, "controller"), timeout=2.0)
        tool_q = tool.declare_querier(params_key(CELL, "controller"), timeout=1.0)
        op_q = welder.declare_querier(params_key(CELL, "controller"), timeout=2.0)
        for q in (rig_q, tool_q, op_q):
            wait_matching(q)  # the queryables are known (egress of declarations is everyone's)
        # what `humanpt rig show` asks: every component's rig (a wildcard)
        rigs = [r.ok for r in tool.get(rig_key(CELL, "*"), timeout=2.0) if r.ok is not None]
        tool_params = [r.ok for r in tool_q.get(payload=b'{"set": {"x": 1}}') if r.ok is not None]
        op_params = [r.ok for r in op_q.get() if r.ok is not None]
        for x in (rig_q, tool_q, op_q, qp, qr):
            x.undeclare()
    assert len(rigs) == 1, "a tool could not read the controller's rig"
    assert tool_params == [], "a read-only tool reached the parameter queryable"
    assert len(op_params) == 1, "an operator could not reach the parameter queryable"
    assert asked == [rig_key(CELL, "controller"), params_key(CELL, "controller")]


def test_no_certificate_no_session(cell, tmp_path):
    """A process whose certificate the PKI does not hold fails before it opens anything,
    naming the file and the command that makes it."""
    rt, _, _ = cell
    with pytest.raises(security.PkiError, match="humanpt pki issue pose_filter"):
        zenoh_config(rt, identity="pose_filter")
    with pytest.raises(security.PkiError, match="humanpt pki init"):
        zenoh_config(dataclasses.replace(rt, pki=str(tmp_path / "none")), identity="controller")


def test_a_certificate_the_router_does_not_hold_may_do_nothing(cell):
    """Issued by the cell's CA after the router started (its access control lists the
    certificates it held then): the client connects, but even its own key is refused."""
    rt, _, _ = cell
    security.issue(security.pki_dir_of(rt), "sim_robot")
    truth = topics.TOPICS["sim_robot/truth"].key(CELL)
    observer = Inbox()
    with session(rt, "tool") as watcher, session(rt, "sim_robot") as late, session(rt, "controller") as ctl:
        sub = watcher.declare_subscriber(f"humanpt/{CELL}/**", observer)
        late.put(truth, b"late")
        late.liveliness().get(liveliness_key(CELL, "*"), timeout=1.0)  # a round trip after the put
        pub = ctl.declare_publisher(COMMAND)
        wait_matching(pub)
        pub.put(command(7))  # reaches the watcher after anything the router let through before
        assert observer.wait_for(lambda k, v: v == command(7)), "the controller's command never arrived"
        sub.undeclare()
        pub.undeclare()
    assert [k for k, _ in observer.items if k == truth] == [], "an identity the router does not know published"
