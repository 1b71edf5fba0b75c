"""Checks every core applies to an input before it touches any state.

Messages carry SI units (metres, radians, seconds, m/s...) and pixels; no physical quantity
of this system comes near 1e9 in them, so a float beyond that (or NaN, or inf) in any field of
an input is a forged or corrupted message, never data.

The check runs on every input of every core, so it is compiled once per message type into
plain attribute reads and comparisons (``-limit <= v <= limit`` is False for NaN and inf).
"""

from __future__ import annotations

import math

from google.protobuf.descriptor import Descriptor, FieldDescriptor
from google.protobuf.message import Message

# Largest magnitude of any float in a message (SI units, pixels).
ABSURD = 1e9

_FLOATS = (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT)
_checkers: dict[str, object] = {}  # full message name -> check(msg) -> bool, or None (no floats)


def _checker(desc: Descriptor):
    """``check(msg, limit) -> bool`` for messages of ``desc`` (None: no floats inside)."""
    name = desc.full_name
    if name in _checkers:
        return _checkers[name]
    _checkers[name] = None  # a recursive type checks its own nesting no deeper
    lines, env = ["def check(m, L):"], {}
    for i, fd in enumerate(desc.fields):
        if fd.type in _FLOATS:
            if fd.is_repeated:
                lines += [f"    for v in m.{fd.name}:", "        if not -L <= v <= L: return False"]
            else:
                lines += [f"    v = m.{fd.name}", "    if not -L <= v <= L: return False"]
        elif fd.type == FieldDescriptor.TYPE_MESSAGE and not fd.message_type.GetOptions().map_entry:
            sub = _checker(fd.message_type)
            if sub is None:
                continue
            env[f"c{i}"] = sub
            if fd.is_repeated:
                lines += [f"    for s in m.{fd.name}:", f"        if not c{i}(s, L): return False"]
            else:
                lines += [f"    if m.HasField({fd.name!r}) and not c{i}(m.{fd.name}, L): return False"]
    if len(lines) == 1:
        return None  # no floats inside: nothing to check
    lines.append("    return True")
    exec("\n".join(lines), env)  # noqa: S102 - source built above from the message's own descriptor
    _checkers[name] = env["check"]
    return env["check"]


def absurd_field(msg: Message, limit: float = ABSURD) -> str | None:
    """The first float field of ``msg`` (nested messages and repeated fields included) that
    is not finite or beyond ``limit`` in magnitude, as ``"path = value"``; None if all are
    sane."""
    check = _checker(msg.DESCRIPTOR)
    if check is None or check(msg, limit):
        return None
    return _find(msg, limit, "")


def _find(msg: Message, limit: float, path: str) -> str | None:
    """The slow path, only for a message that failed: name the field."""
    for fd, value in msg.ListFields():
        name = f"{path}{fd.name}"
        rep = fd.is_repeated
        if fd.type in _FLOATS:
            for i, v in enumerate(value if rep else (value,)):
                if not (math.isfinite(v) and -limit <= v <= limit):
                    return f"{name}{f'[{i}]' if rep else ''} = {v!r}"
        elif fd.type == FieldDescriptor.TYPE_MESSAGE and not fd.message_type.GetOptions().map_entry:
            for i, m in enumerate(value if rep else (value,)):
                bad = _find(m, limit, f"{name}{f'[{i}]' if rep else ''}.")
                if bad:
                    return bad
    return None
