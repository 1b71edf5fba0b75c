"""Zenoh session configuration, the key expressions humanpt uses beside topics, and the
encoding of every sample put on a topic.

Every sample humanpt puts on a topic carries the Zenoh encoding ``application/protobuf``
with the message's full protobuf type name as its schema (``application/protobuf;humanpt.Tick``,
:func:`topic_encoding`), so a client in any language decodes it from ``sample.encoding`` and
the .proto files (schemas/humanpt.proto, schemas/foxglove/) without humanpt's topic table.
"""

from __future__ import annotations

import json

import zenoh

from humanpt.runtime.config import RuntimeConfig
from humanpt.schemas.topics import KEY_PREFIX


def zenoh_config(rt: RuntimeConfig, *, mode: str | None = None, listen: tuple[str, ...] | None = None,
                 connect: tuple[str, ...] | None = None, identity: str | None = None) -> zenoh.Config:
    """The Zenoh config of every session humanpt opens, from the ``[runtime]`` section
    (client of the router by default; a peer listens on ``peer_listen`` so the others can
    link to it directly).

    Multicast scouting is off unless ``multicast_scouting = true``: endpoints are explicit.

    With ``security = "mtls"`` (:mod:`humanpt.runtime.security`): endpoints are TLS
    (``tcp/`` taken as ``tls/``), the session presents the certificate of ``identity``
    (a component's name; default ``router`` for a router, else ``[runtime] identity`` or
    ``tool``) and accepts only peers certified by the cell's CA; a router also enforces
    the access control generated from the topic table for the identities the PKI issued.
    PkiError when the CA or the identity's certificate is missing.
    """
    from humanpt.runtime import security

    mode = mode or rt.mode
    mtls = rt.security == "mtls"
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    eps = rt.connect if connect is None else connect
    if listen is None and mode == "peer":
        listen = rt.peer_listen
    if mtls and mode == "peer":
        raise ValueError('security = "mtls" needs client sessions: peers would link to each other around the '
                         "router's access control")
    if mtls:
        eps = tuple(security.tls_endpoint(e) for e in eps)
        listen = None if listen is None else tuple(security.tls_endpoint(e) for e in listen)
    if eps:
        conf.insert_json5("connect/endpoints", json.dumps(list(eps)))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(rt.multicast_scouting))
    # A client waits this long for the router (it may still be starting), then fails clearly.
    conf.insert_json5("connect/timeout_ms", json.dumps(int(rt.connect_timeout_s * 1000)))
    if mtls:
        pki = security.pki_dir_of(rt)
        name = identity or ("router" if mode == "router" else rt.identity or security.DEFAULT_TOOL_IDENTITY)
        conf.insert_json5("transport/link/tls", json.dumps(security.tls_section(pki, name)))
        if mode == "router":
            conf.insert_json5("access_control", json.dumps(
                security.access_control(rt.cell, security.identities(pki))))
    return conf


PROTOBUF_MIME = "application/protobuf"


def topic_encoding(short: str) -> zenoh.Encoding:
    """The encoding of samples on bus topic ``short``: ``application/protobuf;<full type
    name>`` (UnknownTopicError for a topic not in the table)."""
    from humanpt.schemas.topics import message_type

    return zenoh.Encoding.APPLICATION_PROTOBUF.with_schema(message_type(short).DESCRIPTOR.full_name)


def type_name_of(encoding: zenoh.Encoding) -> str | None:
    """The protobuf type name a sample's encoding names, or None when it is not
    ``application/protobuf;<name>`` (a publisher that set none, another format)."""
    mime, sep, schema = str(encoding).partition(";")
    return schema if mime == PROTOBUF_MIME and sep and schema else None


def declare_topic_publisher(session: zenoh.Session, cell: str, short: str, block: bool = False) -> zenoh.Publisher:
    """A publisher on bus topic ``short`` of ``cell`` whose samples carry :func:`topic_encoding`
    (a topic this version's table lacks: plain ``application/protobuf``, no schema).
    ``block``: wait for a congested link instead of dropping the sample (zenoh's default
    drops: right for a live cell, where a late sample is worthless; a player of recordings
    must deliver every one)."""
    from humanpt.schemas.topics import KEY_PREFIX as prefix
    from humanpt.schemas.topics import UnknownTopicError

    try:
        encoding = topic_encoding(short)
    except UnknownTopicError:
        encoding = zenoh.Encoding.APPLICATION_PROTOBUF
    if block:
        return session.declare_publisher(f"{prefix}/{cell}/{short}", encoding=encoding,
                                         congestion_control=zenoh.CongestionControl.BLOCK)
    return session.declare_publisher(f"{prefix}/{cell}/{short}", encoding=encoding)


def free_tcp_port() -> int:
    """A free TCP port on loopback (for a self-contained router: demo, bench, tests)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def liveliness_key(cell: str, component: str) -> str:
    """The liveliness token of a running component."""
    return f"{KEY_PREFIX}/{cell}/{component}"


def rig_key(cell: str, component: str) -> str:
    """The rig queryable of a running component (its rig as JSON)."""
    return f"{KEY_PREFIX}/{cell}/{component}/rig"


def params_key(cell: str, component: str) -> str:
    """The parameter queryable of a running component."""
    return f"{KEY_PREFIX}/{cell}/{component}/params"


def open_tool_session(rt: RuntimeConfig, patient: bool = False) -> zenoh.Session:
    """A tool's session (topics, echo, param, console, the demo's own): always a client of
    the router. As a peer every component would link to it and re-route when it comes and
    goes (a ~35 ms stall of the servo loop seen as the demo's session left is gone since;
    the cause was not isolated further). Raises ConnectionError naming the router."""
    import dataclasses

    if not patient:  # a person waits: [runtime] tool_connect_timeout_s (patient: a router still starting)
        rt = dataclasses.replace(rt, connect_timeout_s=min(rt.connect_timeout_s, rt.tool_connect_timeout_s))
    conf = zenoh_config(rt, mode="client")
    try:
        return zenoh.open(conf)
    except zenoh.ZError as e:
        why = str(e).split(" at /")[0].rstrip(".")  # Zenoh appends its Rust source location
        how = ""
        if rt.security == "mtls":  # a refused certificate looks like a timeout: say which one was shown
            how = (f" over mTLS as {rt.identity or 'tool'!r} (its certificate must be signed by the cell's CA, "
                   f"be valid now, and the router's name must match one of its hosts)")
        raise ConnectionError(f"cannot reach the router at {', '.join(rt.connect)}{how} ({why}). "
                              "Start one with `humanpt router` or pass --connect ENDPOINT.") from e
