"""Watching a live cell's bus from Python (``humanpt topics`` and ``humanpt echo`` parse and
print): which topics flow and how fast, and each message decoded.

    from humanpt.runtime.monitor import listen, echo, describe
    alive, stats = listen(cfg, 2.0)
    echo(cfg, "perception/tob", lambda key, payload, type_name: print(describe(key, payload)[1]), count=3)
"""

from __future__ import annotations

import queue
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass

from humanpt.runtime import config as cfgmod
from humanpt.schemas import topics


def class_by_name(type_name: str | None):
    """The message class of a full protobuf type name known to this process (humanpt's and
    Foxglove's messages), or None."""
    if not type_name:
        return None
    from google.protobuf import descriptor_pool, message_factory

    package, _, name = type_name.rpartition(".")
    if package == "foxglove":  # Foxglove's classes register when imported: one module per message
        import importlib

        try:
            importlib.import_module(f"foxglove_schemas_protobuf.{name}_pb2")
        except ImportError:
            return None
    try:
        return message_factory.GetMessageClass(descriptor_pool.Default().FindMessageTypeByName(type_name))
    except KeyError:
        return None


def describe(key: str, payload: bytes, full: bool = False, type_name: str | None = None) -> tuple[str, str]:
    """(type name, text) of one sample: decoded by its topic's type, or, for a key not in the
    topic table, by the type its encoding names (``type_name``, application/protobuf;<type>);
    an image's pixels summarised unless ``full``."""
    from google.protobuf import text_format

    try:
        _, short = topics.short_from_key(key)
        cls = topics.message_type(short)
    except topics.UnknownTopicError:
        cls = class_by_name(type_name)
        if cls is None:
            what = f"its encoding names {type_name}, unknown here" if type_name else "no type in its encoding"
            return type_name or "?", f"<{len(payload)} bytes, not in the topic table; {what}>\n"
    msg = cls()
    try:
        msg.ParseFromString(payload)
    except Exception as e:  # noqa: BLE001
        return cls.DESCRIPTOR.full_name, f"<{len(payload)} bytes that do not decode: {e}>"
    if not full and cls.DESCRIPTOR.full_name == "foxglove.RawImage":
        msg = type(msg)(timestamp=msg.timestamp, frame_id=msg.frame_id, width=msg.width, height=msg.height,
                        encoding=msg.encoding, step=msg.step)
        return cls.DESCRIPTOR.full_name, text_format.MessageToString(msg) + f"data: <{len(payload)} bytes>\n"
    return cls.DESCRIPTOR.full_name, text_format.MessageToString(msg)


def type_of_key(key: str) -> str:
    """The message type of a full key, "?" for a key outside the topic table."""
    try:
        return topics.message_type(topics.short_from_key(key)[1]).DESCRIPTOR.full_name
    except topics.UnknownTopicError:
        return "?"


def publisher_of_key(key: str) -> str:
    """Who publishes a full key: the topic table's publisher, else the key's component part
    (``humanpt/<cell>/<component>/...``: every component publishes under its own name)."""
    try:
        short = topics.short_from_key(key)[1]
    except topics.UnknownTopicError:
        return "?"
    t = topics.TOPICS.get(short)
    return t.publisher if t is not None else short.split("/")[0]


def full_key(key: str, cell: str) -> str:
    """A short topic (perception/tob) as the cell's full key; a full key as it is."""
    return key if key.startswith(topics.KEY_PREFIX + "/") else f"{topics.KEY_PREFIX}/{cell}/{key}"


def check_echo(key: str, fields: list[str]) -> None:
    """ValueError for a key that names no topic of this version (wildcards are fine) or a
    field its type does not have, said before listening."""
    short = key.split("/", 2)[2] if key.count("/") >= 2 else key
    if "*" not in key and short not in topics.TOPICS:
        near = sorted(t for t in topics.TOPICS if short.split("/")[0] in t) or sorted(topics.TOPICS)
        raise ValueError(f"no topic {short!r} in this version (wildcards like '*/events' are fine); "
                         f"known: {', '.join(near)}")
    if fields and "*" not in key:
        from humanpt.schemas.convert import MessageError, message_field

        msg = topics.message_type(short)()
        for path in fields:
            try:
                message_field(msg, path)
            except MessageError as e:  # an index beyond an empty list is fine: a message may have entries
                if "entries, no [" not in str(e):
                    raise ValueError(str(e)) from None


def field_row(key: str, payload: bytes, fields: list[str]) -> list:
    """[stamp ns, key, value of each field] of one message (``message_field``); a message
    that does not decode, or lacks a field, raises ValueError naming it."""
    from humanpt.schemas.convert import message_field, message_stamp_ns

    try:
        _, short = topics.short_from_key(key)
        msg = topics.message_type(short).FromString(payload)
    except Exception as e:  # noqa: BLE001 - unknown topic or undecodable bytes: one message
        raise ValueError(f"{key}: cannot decode: {e}") from None
    return [message_stamp_ns(msg), key, *(message_field(msg, f) for f in fields)]


@dataclass(frozen=True)
class KeyStats:
    count: int
    nbytes: int
    rate_hz: float


def listen(cfg: cfgmod.ConfigFile, duration_s: float = 2.0) -> tuple[list[str], dict[str, KeyStats]]:
    """Listen to ``cfg``'s cell for ``duration_s``: (the components whose liveliness tokens
    are up, {key: its messages, bytes and rate})."""
    from humanpt.runtime.bus import liveliness_key, open_tool_session

    cell = cfg.runtime.cell
    stats: dict[str, list] = defaultdict(lambda: [0, 0, None, None])  # count, bytes, first, last
    lock = threading.Lock()

    def cb(sample):
        now = time.monotonic()
        with lock:
            s = stats[str(sample.key_expr)]
            s[0] += 1
            s[1] += len(sample.payload)
            s[2] = s[2] or now
            s[3] = now

    with open_tool_session(cfg.runtime) as session:
        sub = session.declare_subscriber(f"{topics.KEY_PREFIX}/{cell}/**", cb)
        alive = sorted(str(r.ok.key_expr).rsplit("/", 1)[-1]
                       for r in session.liveliness().get(liveliness_key(cell, "*")) if r.ok is not None)
        time.sleep(duration_s)  # the listening itself: what arrives in this time is the answer
        sub.undeclare()
    out = {}
    with lock:
        for key, (count, nbytes, first, last) in stats.items():
            out[key] = KeyStats(count, nbytes, (count - 1) / (last - first) if count > 1 and last > first else 0.0)
    return alive, out


def watch_rates(cfg: cfgmod.ConfigFile, interval_s: float, on_window: Callable[[dict[str, tuple[int, int]], float,
                                                                                   float], None],
                duration_s: float | None = None, stop: threading.Event | None = None) -> None:
    """Every ``interval_s`` until ``stop`` or ``duration_s``: ``on_window({key: (messages,
    bytes)}, elapsed_s, window_s)`` of what arrived on ``cfg``'s cell in that window."""
    from humanpt.runtime.bus import open_tool_session

    if not interval_s > 0:
        raise ValueError(f"--interval {interval_s:g}: must be > 0 s")
    stop = stop or threading.Event()
    lock = threading.Lock()
    window: dict[str, list[int]] = defaultdict(lambda: [0, 0])  # key -> [count, bytes] since the last call

    def cb(sample):
        with lock:
            w = window[str(sample.key_expr)]
            w[0] += 1
            w[1] += len(sample.payload)

    with open_tool_session(cfg.runtime) as session:
        sub = session.declare_subscriber(f"{topics.KEY_PREFIX}/{cfg.runtime.cell}/**", cb)
        start = last = time.monotonic()
        end = start + duration_s if duration_s else None
        while not stop.wait(interval_s if end is None else max(0.0, min(interval_s, end - time.monotonic()))):
            now = time.monotonic()
            with lock:
                snap = {k: (c, b) for k, (c, b) in window.items()}
                window.clear()
            on_window(snap, now - start, now - last)
            last = now
            if end is not None and now >= end - 1e-3:
                break
        sub.undeclare()


def echo(cfg: cfgmod.ConfigFile, key: str, on_sample: Callable[[str, bytes, str | None], None], *,
         count: int | None = None, duration_s: float | None = None, stop: threading.Event | None = None) -> int:
    """Subscribe to ``key`` (a short topic, a full key or a wildcard) on ``cfg``'s cell and
    call ``on_sample(key, payload, type name of its encoding)`` for each message, until
    ``count`` messages, ``duration_s`` or ``stop``; the number of messages."""
    from humanpt.runtime.bus import open_tool_session, type_name_of

    key = full_key(key, cfg.runtime.cell)
    stop = stop or threading.Event()
    q: queue.Queue = queue.Queue()
    n = 0
    with open_tool_session(cfg.runtime) as session:
        sub = session.declare_subscriber(key, lambda s: q.put((str(s.key_expr), s.payload.to_bytes(),
                                                                type_name_of(s.encoding))))
        deadline = time.monotonic() + duration_s if duration_s else None
        while not stop.is_set() and (count is None or n < count):
            if deadline and time.monotonic() >= deadline:
                break
            try:
                k, payload, type_name = q.get(timeout=0.1)
            except queue.Empty:
                continue
            on_sample(k, payload, type_name)
            n += 1
        sub.undeclare()
    return n


def rigs_in_use(cfg: cfgmod.ConfigFile, timeout_s: float = 3.0) -> dict:
    """{component: the Rig it runs with} of every component of ``cfg``'s cell that answers
    its rig queryable within ``timeout_s``."""
    from humanpt.runtime.bus import open_tool_session, rig_key
    from humanpt.runtime.rigfile import rig_from_json

    with open_tool_session(cfg.runtime) as session:
        replies = list(session.get(rig_key(cfg.runtime.cell, "*"), timeout=timeout_s))
    rigs = {}
    for r in replies:
        if r.ok is None:
            continue
        comp = str(r.ok.key_expr).split("/")[-2]
        rigs[comp] = rig_from_json(r.ok.payload.to_bytes().decode(), f"{comp}'s rig")
    return rigs
