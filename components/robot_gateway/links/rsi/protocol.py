"""KUKA RSI-style messages (UDP datagrams of XML), encoded and decoded; pure.

The robot controller sends every RSI cycle (4 ms or 12 ms) one ``<Rob>`` datagram::

    <Rob TYPE="KUKA"><RIst X="…" Y="…" Z="…" A="…" B="…" C="…"/>
      <AIPos A1="…" A2="…" A3="…" A4="…" A5="…" A6="…"/><Delay D="n"/><IPOC>k</IPOC></Rob>

``RIst``: the actual Cartesian pose of the flange in the robot base frame (X, Y, Z mm;
A, B, C deg: rotations about Z, Y, X, R = Rz(A) Ry(B) Rx(C)); ``AIPos``: the joints, deg;
``Delay``: the controller's count of late replies so far; ``IPOC``: the cycle's time stamp
(ms, + the cycle time per cycle). The client must answer within the cycle with::

    <Sen Type="ImFree"><RKorr X="…" Y="…" Z="…" A="…" B="…" C="…"/><IPOC>k</IPOC></Sen>

echoing the IPOC; ``RKorr`` is a *relative* correction for one cycle (mm, deg; same angle
convention) in the frame the robot's RSI configuration names (base or tool). Values go
on the wire with 4 decimals (0.0001 mm / deg). A datagram is printable ASCII of at most
``MAX_DATAGRAM`` bytes with no DOCTYPE, entity or character reference (:func:`check_bytes`,
before any XML parsing: no entity is ever expanded, the parse cost is bounded). Anything
that is not such a message raises :class:`RsiProtocolError` (one line, what was wrong).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from humanpt.geometry.transforms import rotation_angle_rad, rotation_from_ypr_deg, transform_from_x
from humanpt.robot_gateway.safety import clamp_norm, wire_rotation_deg

# A datagram longer than this is not an RSI message (the real ones are < 1.5 kB).
MAX_DATAGRAM = 4096
DECIMALS = 4  # wire resolution 1e-4 mm / deg
_QUANT = 10.0**-DECIMALS
_XYZABC = ("X", "Y", "Z", "A", "B", "C")
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")


class RsiProtocolError(ValueError):
    """A datagram that is not a usable RSI message."""


@dataclass(frozen=True, slots=True)
class RobState:
    """One ``<Rob>`` datagram: ``ipoc`` (ms stamp), ``rist`` (X, Y, Z mm, A, B, C deg of
    the flange in the base frame), ``aipos`` (joints deg), ``delay`` (late replies so far)."""

    ipoc: int
    rist: tuple[float, ...]
    aipos: tuple[float, ...]
    delay: int = 0

    def base_T_flange_mm(self) -> np.ndarray:
        """(4, 4) the flange in the base frame, mm (A, B, C = yaw, pitch, roll); read only."""
        return _transform(self.rist)


@dataclass(frozen=True, slots=True)
class RsiCorrection:
    """One ``<Sen>`` answer: the echoed ``ipoc`` and the relative correction ``rkorr`` =
    (X, Y, Z mm, A, B, C deg), as on the wire (rounded to 4 decimals)."""

    ipoc: int
    rkorr: tuple[float, float, float, float, float, float]

    @classmethod
    def hold(cls, ipoc: int) -> RsiCorrection:
        return cls(ipoc, (0.0,) * 6)

    @property
    def translation_mm(self) -> np.ndarray:
        return np.array(self.rkorr[:3])

    def angle_deg(self) -> float:
        """Rotation angle of Rz(A) Ry(B) Rx(C), degrees."""
        return _angle_deg(*self.rkorr[3:])

    def delta_T_mm(self) -> np.ndarray:
        """(4, 4) the correction as a transform, mm."""
        return transform_from_x(np.asarray(self.rkorr, dtype=float))


@lru_cache(maxsize=64)
def _transform(x_mm_deg: tuple[float, ...]) -> np.ndarray:
    """transform_from_x, cached (a robot at rest repeats its pose); the array is read only."""
    T = transform_from_x(np.asarray(x_mm_deg, dtype=float))
    T.flags.writeable = False
    return T


@lru_cache(maxsize=4096)
def _angle_deg(a_deg: float, b_deg: float, c_deg: float) -> float:
    """Angle of Rz(A) Ry(B) Rx(C), degrees. Cached: a steady motion repeats its wire values."""
    if a_deg == b_deg == c_deg == 0.0:
        return 0.0
    return math.degrees(rotation_angle_rad(rotation_from_ypr_deg([a_deg, b_deg, c_deg])))


def _fmt(v: float) -> str:
    s = f"{v:.{DECIMALS}f}"
    return "0.0000" if s == "-0.0000" else s


def _attrs(values, names) -> str:
    return " ".join(f'{n}="{_fmt(v)}"' for n, v in zip(names, values, strict=True))


def encode_rob(state: RobState) -> bytes:
    return (f'<Rob TYPE="KUKA"><RIst {_attrs(state.rist, _XYZABC)}/>'
            f'<AIPos {_attrs(state.aipos, _AXES)}/><Delay D="{state.delay}"/>'
            f"<IPOC>{state.ipoc}</IPOC></Rob>").encode("ascii")


def encode_sen(c: RsiCorrection, sen_type: str = "ImFree") -> bytes:
    return (f'<Sen Type="{sen_type}"><RKorr {_attrs(c.rkorr, _XYZABC)}/>'
            f"<IPOC>{c.ipoc}</IPOC></Sen>").encode("ascii")


# An RSI message is printable ASCII (and tab, CR, LF): any other byte (NUL, >= 0x80: UTF-16,
# UTF-8 beyond ASCII, a BOM) is refused before the XML parser sees it, so that no other
# encoding can carry what the byte checks below look for.
_NOT_ASCII = re.compile(rb"[^\t\n\r\x20-\x7e]")
# The only processing instruction allowed: a leading XML declaration, ASCII or UTF-8.
_DECLARATION = re.compile(
    rb"""\s*<\?xml\s+version\s*=\s*["']1\.\d{1,2}["']"""
    rb"""(?:\s+encoding\s*=\s*["']([A-Za-z0-9._-]{1,40})["'])?"""
    rb"""(?:\s+standalone\s*=\s*["'](?:yes|no)["'])?\s*\?>""")
_ENCODINGS = (b"ascii", b"us-ascii", b"utf-8", b"utf8")
# Numbers as RSI writes them: decimal, optional exponent (no "1_0", "inf", "nan", "0x1").
_FLOAT = re.compile(r"[+-]?(?:\d{1,30}(?:\.\d{0,30})?|\.\d{1,30})(?:[eE][+-]?\d{1,3})?")
_UINT = re.compile(r"\d{1,19}")


def _show(text: str | None, n: int = 24) -> str:
    """``text`` for an error message: repr'd (one line) and cut to ``n`` characters."""
    text = "" if text is None else text
    return repr(text[:n] + "...") if len(text) > n else repr(text)


def check_bytes(data: bytes) -> None:
    """Refuse, before any XML parsing, what cannot be an RSI message: too long, a byte that
    is not printable ASCII, a DOCTYPE / ENTITY / comment / CDATA (``<!``), a character or
    entity reference (``&``), a processing instruction, an encoding other than ASCII or
    UTF-8. What passes is parsed in time linear in its (bounded) length: no entity is ever
    expanded."""
    if len(data) > MAX_DATAGRAM:
        raise RsiProtocolError(f"datagram of {len(data)} bytes (an RSI message has < {MAX_DATAGRAM})")
    bad = _NOT_ASCII.search(data)
    if bad is not None:
        raise RsiProtocolError(f"byte 0x{data[bad.start()]:02x} at offset {bad.start()}: an RSI message is "
                               "printable ASCII only (no other encoding, no NUL)")
    if b"<!" in data:
        raise RsiProtocolError("a DOCTYPE, ENTITY, comment or CDATA ('<!'): not an RSI message")
    if b"&" in data:
        raise RsiProtocolError(f"a character or entity reference ('&' at offset {data.index(b'&')}): "
                               "not an RSI message")
    if b"<?" in data:
        decl = _DECLARATION.match(data)
        if decl is None or b"<?" in data[decl.end():]:
            raise RsiProtocolError("a processing instruction other than a leading XML declaration: "
                                   "not an RSI message")
        encoding = decl.group(1)
        if encoding is not None and encoding.lower() not in _ENCODINGS:
            raise RsiProtocolError(f"encoding {encoding.decode()!r} declared: an RSI message is ASCII")


def _root(data: bytes, tag: str) -> ET.Element:
    if not isinstance(data, bytes | bytearray):
        raise RsiProtocolError(f"a datagram is bytes, got {type(data).__name__}")
    check_bytes(data)
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise RsiProtocolError(f"malformed XML: {e}") from None
    except (ValueError, RecursionError) as e:  # (not expected after check_bytes: still one line)
        raise RsiProtocolError(f"unreadable XML: {type(e).__name__}: {_show(str(e), 80)}") from None
    if root.tag != tag:
        raise RsiProtocolError(f"<{_show(root.tag)[1:-1]}> where <{tag}> was expected")
    return root


def _floats(root: ET.Element, child: str, names) -> tuple[float, ...]:
    el = root.find(child)
    if el is None:
        raise RsiProtocolError(f"<{root.tag}> has no <{child}>")
    values = []
    for n in names:
        text = el.attrib.get(n)
        if text is None:
            raise RsiProtocolError(f"<{child}> lacks attribute {n}")
        text = text.strip()
        if _FLOAT.fullmatch(text) is None:
            raise RsiProtocolError(f"<{child} {n}={_show(text)}> is not a decimal number")
        values.append(float(text))
    if not all(map(math.isfinite, values)):
        raise RsiProtocolError(f"<{child}> has a non-finite value: {tuple(values)}")
    return tuple(values)


def _ipoc(root: ET.Element) -> int:
    el = root.find("IPOC")
    text = (el.text or "").strip() if el is not None else ""
    if _UINT.fullmatch(text) is None:
        raise RsiProtocolError(f"<{root.tag}> has no valid <IPOC> (got {_show(text)})")
    return int(text)


def decode_rob(data: bytes) -> RobState:
    root = _root(data, "Rob")
    delay_el = root.find("Delay")
    delay = 0
    if delay_el is not None:
        text = delay_el.attrib.get("D", "0").strip()
        if _UINT.fullmatch(text) is None:
            raise RsiProtocolError(f"<Delay D={_show(text)}> is not a count")
        delay = int(text)
    return RobState(_ipoc(root), _floats(root, "RIst", _XYZABC), _floats(root, "AIPos", _AXES), delay)


def decode_sen(data: bytes) -> RsiCorrection:
    root = _root(data, "Sen")
    return RsiCorrection(_ipoc(root), _floats(root, "RKorr", _XYZABC))  # type: ignore[arg-type]


def rsi_correction(ipoc: int, dp_mm: np.ndarray, rv_rad: np.ndarray, max_step_mm: float,
                   max_step_deg: float) -> RsiCorrection:
    """The RKorr for ``dp_mm`` (3,) and ``rv_rad`` (3,) (already clamped, in the robot's
    correction frame) rounded to the wire's 4 decimals such that the rounded step still
    respects the limits (rounding may add up to 0.00009 mm / deg: a step at the limit is
    shrunk by a few wire units if it would poke out)."""
    dp = np.asarray(dp_mm, dtype=float)
    rv = np.asarray(rv_rad, dtype=float)
    for margin in (0.0, 1.0, 2.0, 4.0, 8.0):
        dp_m, _ = clamp_norm(dp, max(0.0, max_step_mm - margin * _QUANT))
        rv_m, _ = clamp_norm(rv, math.radians(max(0.0, max_step_deg - margin * _QUANT)))
        # (drx, dry, drz) -> A = drz, B = dry, C = drx
        abc = wire_rotation_deg(rv_m)[::-1] if rv_m.any() else (0.0, 0.0, 0.0)
        values = tuple(round(float(v), DECIMALS) + 0.0 for v in (*dp_m, *abc))
        c = RsiCorrection(ipoc, values)  # type: ignore[arg-type]
        if (float(np.linalg.norm(c.translation_mm)) <= max_step_mm + 1e-12
                and c.angle_deg() <= max_step_deg + 1e-9):
            return c
    return RsiCorrection.hold(ipoc)  # not reached: 8 wire units cover any rounding
