"""Checks every core applies to an input before it touches any state.

Messages carry SI units (metres, radians, seconds, m/s...) and pixels; no physical quantity
of this system comes near 1e9 in them, so a float beyond that (or NaN, or inf) in any field of
an input is a forged or corrupted message, never data.
"""

from __future__ import annotations

import math

import numpy as np
from google.protobuf.descriptor import FieldDescriptor
from google.protobuf.message import Message

# Largest magnitude of any float in a message (SI units, pixels).
ABSURD = 1e9

_FLOATS = (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT)


def _repeated(fd: FieldDescriptor) -> bool:
    return fd.is_repeated


def _sane(msg: Message, limit: float) -> bool:
    """Fast pass: whether every float of ``msg`` is finite and within ``limit``."""
    isfinite = math.isfinite
    for fd, value in msg.ListFields():
        t = fd.type
        if t in _FLOATS:
            if _repeated(fd):
                if len(value) > 8:
                    a = np.fromiter(value, float, len(value))
                    if not (np.isfinite(a).all() and np.abs(a).max() <= limit):
                        return False
                    continue
                values = value
            else:
                values = (value,)
            for v in values:
                if not (isfinite(v) and -limit <= v <= limit):
                    return False
        elif t == FieldDescriptor.TYPE_MESSAGE and not fd.message_type.GetOptions().map_entry:
            for m in (value if _repeated(fd) else (value,)):
                if not _sane(m, limit):
                    return False
    return True


def absurd_field(msg: Message, limit: float = ABSURD) -> str | None:
    """The first float field of ``msg`` (nested messages and repeated fields included) that
    is not finite or beyond ``limit`` in magnitude, as ``"path = value"``; None if all are
    sane.  Only fields that are set are visited."""
    return None if _sane(msg, limit) else _find(msg, limit, "")


def _find(msg: Message, limit: float, path: str) -> str | None:
    for fd, value in msg.ListFields():
        name = f"{path}{fd.name}"
        rep = _repeated(fd)
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
