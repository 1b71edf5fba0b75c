"""Universal Robots RTDE (Real-Time Data Exchange, protocol version 2), encoded and decoded;
pure (bytes in, values out: no sockets, no clock).

RTDE runs over TCP (the controller listens on port 30004). Every packet is ``uint16 size``
(the whole packet, these 3 header bytes included), ``uint8 type``, then a big-endian payload:

====  ===========================  =======================================================
type  client -> controller          controller -> client
====  ===========================  =======================================================
'V'   uint16 protocol version       uint8 accepted
'v'   (empty)                       uint32 major, minor, bugfix, build
'O'   double frequency, names CSV   uint8 recipe id, types CSV ("NOT_FOUND" for unknown)
'I'   names CSV                     uint8 recipe id, types CSV ("IN_USE": another client's)
'S'   (empty)                       uint8 accepted
'P'   (empty)                       uint8 accepted
'U'   uint8 recipe id, the inputs   uint8 recipe id, the outputs (every cycle once started)
'M'   text message                  text message (uint8 length + text, uint8 length +
                                    source, uint8 level)
====  ===========================  =======================================================

A recipe's data are its variables' values in order, each by its type (:data:`TYPES`).
:class:`Framer` cuts a byte stream into packets; anything that is not RTDE (a size under 3
or above :data:`MAX_PACKET`, an unknown type, a payload of the wrong length, a type name
that is not RTDE's) raises :class:`RtdeProtocolError` with one line saying what.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.transforms import make_transform, matrix_from_rotvec, rotvec_from_matrix

PROTOCOL_VERSION = 2
MAX_PACKET = 4096  # a whole recipe of every variable is ~2 kB; RTDE packets are small

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")
PACKET_TYPES = frozenset((REQUEST_PROTOCOL_VERSION, GET_URCONTROL_VERSION, TEXT_MESSAGE, DATA_PACKAGE,
                          SETUP_OUTPUTS, SETUP_INPUTS, START, PAUSE))

# RTDE's data types: struct format (big-endian) and the number of values.
TYPES: dict[str, tuple[str, int]] = {
    "BOOL": ("?", 1),
    "UINT8": ("B", 1),
    "UINT32": ("I", 1),
    "UINT64": ("Q", 1),
    "INT32": ("i", 1),
    "DOUBLE": ("d", 1),
    "VECTOR3D": ("3d", 3),
    "VECTOR6D": ("6d", 6),
    "VECTOR6INT32": ("6i", 6),
    "VECTOR6UINT32": ("6I", 6),
}

# robot_mode, safety_mode, runtime_state values (UR's RTDE guide)
ROBOT_MODE_RUNNING = 7
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_REDUCED = 2
SAFETY_MODE_PROTECTIVE_STOP = 3
# runtime_state (UR's RTDE guide): the program's state
RUNTIME_STOPPING = 0
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
RUNTIME_PAUSING = 3
RUNTIME_PAUSED = 4
RUNTIME_RESUMING = 5
RUNTIME_NAMES = {RUNTIME_STOPPING: "STOPPING", RUNTIME_STOPPED: "STOPPED", RUNTIME_PLAYING: "PLAYING",
                 RUNTIME_PAUSING: "PAUSING", RUNTIME_PAUSED: "PAUSED", RUNTIME_RESUMING: "RESUMING"}
# robot_status_bits: bit 0 power on, bit 1 program running, bit 2 teach button, bit 3 power button
STATUS_BIT_POWER_ON = 1
STATUS_BIT_PROGRAM_RUNNING = 2


class RtdeProtocolError(ValueError):
    """Bytes that are not a usable RTDE packet."""


@dataclass(frozen=True, slots=True)
class Packet:
    type: int
    payload: bytes

    @property
    def letter(self) -> str:
        return chr(self.type)


def pack(ptype: int, payload: bytes = b"") -> bytes:
    """One packet: size, type, payload."""
    size = 3 + len(payload)
    if size > MAX_PACKET:
        raise RtdeProtocolError(f"RTDE packet {chr(ptype)!r} of {size} bytes is over {MAX_PACKET}")
    return struct.pack(">HB", size, ptype) + payload


class Framer:
    """A TCP byte stream cut into RTDE packets. ``feed(data)`` returns the whole packets so far
    (a packet may come in pieces, several in one piece); a header that is not RTDE's raises
    :class:`RtdeProtocolError` and the stream is no longer in step (:meth:`reset` on a new
    connection)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        # After a bad header: skip to the next occurrence of these bytes (the header of the
        # data packages the link expects), not to lose the stream for good.
        self.sync: bytes | None = None
        self.errors: list[RtdeProtocolError] = []  # drained by the caller

    def reset(self) -> None:
        self._buf.clear()

    @property
    def pending(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[Packet]:
        """The whole packets so far; a bad header is put in :attr:`errors` and the bytes up to
        the next :attr:`sync` (all, without one) are dropped."""
        self._buf += data
        out: list[Packet] = []
        while len(self._buf) >= 3:
            size, ptype = struct.unpack_from(">HB", self._buf)
            bad = None
            if size < 3 or size > MAX_PACKET:
                bad = f"RTDE packet size {size} is not within 3..{MAX_PACKET}"
            elif ptype not in PACKET_TYPES:
                bad = f"RTDE packet type {ptype} is not RTDE's"
            if bad is not None:
                self.errors.append(RtdeProtocolError(bad + "; bytes dropped up to the next packet"))
                i = self._buf.find(self.sync, 1) if self.sync else -1
                if i < 0:
                    keep = len(self.sync) - 1 if self.sync else 0  # (the start of a sync cut in two)
                    del self._buf[:max(1, len(self._buf) - keep)]
                else:
                    del self._buf[:i]
                continue
            if len(self._buf) < size:
                break
            out.append(Packet(ptype, bytes(self._buf[3:size])))
            del self._buf[:size]
        return out


# -- payloads --------------------------------------------------------------------------------
def _need(payload: bytes, n: int, what: str) -> None:
    if len(payload) != n:
        raise RtdeProtocolError(f"RTDE {what}: payload of {len(payload)} bytes, expected {n}")


def encode_u8(value: int) -> bytes:
    return struct.pack(">B", value)


def decode_u8(payload: bytes, what: str) -> int:
    _need(payload, 1, what)
    return payload[0]


def encode_version_request(version: int = PROTOCOL_VERSION) -> bytes:
    return pack(REQUEST_PROTOCOL_VERSION, struct.pack(">H", version))


def decode_version_request(payload: bytes) -> int:
    _need(payload, 2, "protocol version request")
    return struct.unpack(">H", payload)[0]


def encode_controller_version(major: int, minor: int, bugfix: int, build: int) -> bytes:
    return pack(GET_URCONTROL_VERSION, struct.pack(">IIII", major, minor, bugfix, build))


def decode_controller_version(payload: bytes) -> tuple[int, int, int, int]:
    _need(payload, 16, "controller version")
    return struct.unpack(">IIII", payload)


def _names(text: str, what: str) -> tuple[str, ...]:
    if text.endswith(","):
        text = text[:-1]  # (ur-rtde ends its list with a comma; the controller takes it)
    names = tuple(text.split(","))
    if not text or any(not n or not n.replace("_", "").isalnum() or not n.isascii() for n in names):
        raise RtdeProtocolError(f"RTDE {what}: {text[:60]!r} is not a list of variable names")
    return names


def _ascii(payload: bytes, what: str) -> str:
    try:
        return payload.decode("ascii")
    except UnicodeDecodeError:
        raise RtdeProtocolError(f"RTDE {what}: not ASCII text") from None


def encode_setup_outputs(frequency_hz: float, names: tuple[str, ...]) -> bytes:
    return pack(SETUP_OUTPUTS, struct.pack(">d", frequency_hz) + ",".join(names).encode("ascii"))


def decode_setup_outputs(payload: bytes) -> tuple[float, tuple[str, ...]]:
    if len(payload) < 9:
        raise RtdeProtocolError(f"RTDE output setup: payload of {len(payload)} bytes, expected a frequency "
                                "and names")
    (freq,) = struct.unpack_from(">d", payload)
    if not (math.isfinite(freq) and freq > 0):
        raise RtdeProtocolError(f"RTDE output setup: frequency {freq} is not > 0")
    return freq, _names(_ascii(payload[8:], "output setup"), "output setup")


def encode_setup_inputs(names: tuple[str, ...]) -> bytes:
    return pack(SETUP_INPUTS, ",".join(names).encode("ascii"))


def decode_setup_inputs(payload: bytes) -> tuple[str, ...]:
    return _names(_ascii(payload, "input setup"), "input setup")


def encode_setup_reply(ptype: int, recipe_id: int, types: tuple[str, ...]) -> bytes:
    return pack(ptype, encode_u8(recipe_id) + ",".join(types).encode("ascii"))


def decode_setup_reply(payload: bytes, what: str) -> tuple[int, tuple[str, ...]]:
    """(recipe id, types); a type may be NOT_FOUND or IN_USE (the caller decides)."""
    if len(payload) < 2:
        raise RtdeProtocolError(f"RTDE {what} reply: payload of {len(payload)} bytes")
    types = tuple(_ascii(payload[1:], what).split(","))
    for t in types:
        if t not in TYPES and t not in ("NOT_FOUND", "IN_USE"):
            raise RtdeProtocolError(f"RTDE {what} reply: type {t[:30]!r} is not RTDE's")
    return payload[0], types


def encode_text(text: str, source: str = "humanpt", level: int = 1) -> bytes:
    t, s = text.encode("ascii", "replace")[:255], source.encode("ascii", "replace")[:255]
    return pack(TEXT_MESSAGE, encode_u8(len(t)) + t + encode_u8(len(s)) + s + encode_u8(level))


def decode_text(payload: bytes) -> tuple[str, str, int]:
    """(text, source, level) of an 'M' packet."""
    try:
        n = payload[0]
        text = payload[1:1 + n]
        m = payload[1 + n]
        source = payload[2 + n:2 + n + m]
        level = payload[2 + n + m]
        _need(payload, 3 + n + m, "text message")
    except IndexError:
        raise RtdeProtocolError(f"RTDE text message: {len(payload)} bytes cut short") from None
    return text.decode("ascii", "replace"), source.decode("ascii", "replace"), level


@dataclass(frozen=True)
class Recipe:
    """A set-up recipe: its id, variable names and types (all RTDE's)."""

    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]

    def __post_init__(self) -> None:
        if len(self.names) != len(self.types):
            raise RtdeProtocolError(f"RTDE recipe {self.recipe_id}: {len(self.names)} names, {len(self.types)} types")
        bad = [f"{n}={t}" for n, t in zip(self.names, self.types, strict=True) if t not in TYPES]
        if bad:
            raise RtdeProtocolError(f"RTDE recipe {self.recipe_id}: not available: {', '.join(bad)}")
        # the struct format (a string, not a struct.Struct: a recipe is plain data, as snapshots
        # need it; the struct module caches the compiled format)
        object.__setattr__(self, "_fmt", ">" + "".join(TYPES[t][0] for t in self.types))

    @property
    def size(self) -> int:
        return struct.calcsize(self._fmt)

    def encode(self, values: dict[str, object]) -> bytes:
        """A data package ('U') with ``values`` by name (each a number or a sequence)."""
        flat: list = []
        for n, t in zip(self.names, self.types, strict=True):
            v = values[n]
            if TYPES[t][1] == 1:
                flat.append(v)
            else:
                v = tuple(v)
                if len(v) != TYPES[t][1]:
                    raise ValueError(f"{n}: {len(v)} values for {t}")
                flat.extend(v)
        return pack(DATA_PACKAGE, encode_u8(self.recipe_id) + struct.pack(self._fmt, *flat))

    def decode(self, payload: bytes) -> dict[str, object]:
        """The values of a data package's payload (its recipe id first)."""
        _need(payload, 1 + self.size, f"data package of recipe {self.recipe_id}")
        if payload[0] != self.recipe_id:
            raise RtdeProtocolError(f"RTDE data package of recipe {payload[0]}, expected {self.recipe_id}")
        flat = struct.unpack_from(self._fmt, payload, 1)
        out: dict[str, object] = {}
        i = 0
        for n, t in zip(self.names, self.types, strict=True):
            k = TYPES[t][1]
            out[n] = flat[i] if k == 1 else tuple(flat[i:i + k])
            i += k
        return out


# -- UR poses: p[x, y, z (m), rx, ry, rz (rotation vector, rad)] -------------------------------
def transform_from_ur_pose(pose) -> np.ndarray:
    """(4, 4), mm, of a UR pose (m, rotation vector rad); RtdeProtocolError if not finite."""
    p = np.asarray(pose, float)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise RtdeProtocolError(f"a UR pose is 6 finite numbers, got {tuple(pose)!r}")
    return make_transform(matrix_from_rotvec(p[3:]), p[:3] * 1000.0)


def ur_pose_from_transform(a_T_b_mm: np.ndarray) -> tuple[float, ...]:
    """A UR pose (m, rotation vector rad) of a (4, 4) transform in mm."""
    rv = rotvec_from_matrix(a_T_b_mm[:3, :3])
    return tuple(float(v) for v in (*(a_T_b_mm[:3, 3] / 1000.0), *rv))
