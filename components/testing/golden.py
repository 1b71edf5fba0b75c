"""Golden replay of the reference runs, and per-topic comparison of two output streams.

The reference runs in ``recordings/<run>/`` (made live on the digital twin by
``humanpt runs rerecord``) guard the components' behaviour:

- :func:`check_component` replays one component recording on its recorded inputs and
  demands the recorded outputs: the same topics in the same order at the same times, every
  discrete field (integers, counts, sequence numbers, stamps, enums, modes, flags, strings,
  event codes, bytes on the serial line) exactly, and every float within the tolerance of
  its unit in :data:`TOLERANCES` (the one table), images within :data:`IMAGE_TOLERANCE`.
  So a reference run survives refactoring that changes the last bits of the arithmetic
  (or a library update that does), and still catches any change of behaviour.  Its message
  gives the largest difference per field; on failure it names the run, the component, the
  topic, the first offending message (its index on that topic and in the whole output
  stream, its time) and the fields that differ, then summarises the whole replay per topic.
  ``exact=True`` demands the recorded bytes (run == replay within one build, as
  :func:`humanpt.runtime.replay.replay` does).
- :func:`compare_streams` compares two output streams per topic: messages added and
  removed, messages that differ, and the largest difference per field (numbers by value,
  images and other byte strings byte by byte, enums and text by count), each with its
  tolerance.  ``humanpt runs rerecord`` uses it to show what an intended change did before
  the new runs are accepted.

Messages are paired per topic either by *step* (the same log time and the same position
among that step's outputs: exact when both streams come from the same inputs) or by
*order* (the n-th message on a topic with the n-th: for two live runs, whose clocks and
timing differ).  For two live runs, stamps are compared relative to each recording's first
message (``relative_stamps``), so that the wall-clock start does not swamp the differences.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from google.protobuf.message import Message

from humanpt.runtime.config import ConfigError
from humanpt.runtime.core import Core
from humanpt.runtime.recording import Recording, RecordingError, read
from humanpt.runtime.replay import build_core, diff_messages, replay_recording
from humanpt.schemas import topics

Stream = list[tuple[int, str, bytes]]  # (log time ns, short topic, serialised message)
Pairing = Literal["step", "order"]

RERECORD_HINT = (
    "if the change is intended, `humanpt runs rerecord` shows its effect on every "
    "reference run and replaces them (see recordings/README.md)"
)


class GoldenError(ValueError):
    """The reference runs cannot be used (none found, or a run directory is malformed)."""


# -- tolerances: the one table ------------------------------------------------------------
@dataclass(frozen=True)
class Tolerance:
    """A float field passes when ``|replayed - recorded| <= abs + rel * max(|both|)``."""

    unit: str
    abs: float
    rel: float = 0.0

    def accepts(self, a: float, b: float) -> bool:
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return abs(b - a) <= self.abs + self.rel * max(abs(a), abs(b))

    def __str__(self) -> str:
        rel = f" + {self.rel:g} x value" if self.rel else ""
        return f"{self.abs:g} {self.unit}{rel}"


# Float tolerances, by the unit a field's name (or its message) states.  Far above the
# rounding of double arithmetic (~1e-16 relative: what a refactoring or a library update
# changes), far below what the system resolves (3D points ~3e-6 m RMS, image centres
# ~6e-3 px RMS: perception/README.md).
TOLERANCES: dict[str, Tolerance] = {
    "m": Tolerance("m", 1e-9),
    "rad": Tolerance("rad", 1e-9),
    "quaternion": Tolerance("(quaternion component)", 1e-9),  # 1e-9 rad of rotation, about
    "px": Tolerance("px", 1e-6),
    "s": Tolerance("s", 1e-9),
    "m/s": Tolerance("m/s", 1e-9),
    "rad/s": Tolerance("rad/s", 1e-9),
    "ratio": Tolerance("(0..1)", 1e-9),
    # Mixed units (m^2, rad^2, (m/s)^2, ...), values down to ~1e-12: relative, with a floor
    # of (1e-9 m)^2 for the entries that are ~0.
    "covariance": Tolerance("(m, rad, s)^2", 1e-18, 1e-9),
}

# Which float field has which unit: the first rule that matches one of the field path's
# names, from the innermost out (``world_T_tob.translation.x``: ``x`` no, ``translation``
# yes).  A float field no rule covers fails the comparison: add a rule.
UNIT_RULES: list[tuple[str, str]] = [
    (r"_m_s$", "m/s"),
    (r"_rad_s$", "rad/s"),
    (r"_m$", "m"),
    (r"_rad$", "rad"),
    (r"_px$", "px"),
    (r"_s$", "s"),
    (r"^translation$", "m"),  # Pose.translation: metres (humanpt.proto)
    (r"^rotation$", "quaternion"),  # Pose.rotation
    (r"^covariance$", "covariance"),
    (r"^quality$", "ratio"),
    (r"_fraction$", "ratio"),
    (r"^source_brightness$", "ratio"),  # TobMeasurement: brightness for its size, ~1
    (r"_m2$|_rad2$", "covariance"),  # PathPoint's 3x3 covariances (issue 18)
    (r"^rotation_scale$", "ratio"),  # ControllerStatus (issue 18)
    # Foxglove's own types (the scene component, issue 20): poses and sizes in metres, image
    # annotations in pixels, colours 0..1, the camera calibration's matrices.
    (r"^orientation$", "quaternion"),
    (r"^(position|points|size|scale|diameter|thickness|font_size|head_diameter|head_length|"
     r"shaft_diameter|shaft_length|bottom_scale|top_scale)$", "m"),
    (r"^(colors?|fill_color|outline_colors?|background_color|text_color)$", "ratio"),
    (r"^(K|P)$", "px"),
    (r"^(D|R)$", "ratio"),
]


@dataclass(frozen=True)
class ImageTolerance:
    """Pixels of a rendered image: passes when the pixels that differ look like another
    draw of the shot noise on the blobs - few, small and zero-mean.

    The renderer draws each blob pixel's shot noise from a float expected value, so a
    change in the last bits of a pose re-draws the noise on the blobs (seen after a library
    update, 99 images: <= 303 of 307 200 pixels, <= 4 DN, RMS ~1.2 DN, <= 1.8 in the bias
    statistic below).  Another seed changes ~1 500 pixels, a source 1 % brighter biases
    them (statistic ~15), a blur 0.05 px wider or a background 5 % brighter: all fail.  A
    change below the noise passes (blur sigma 0.01 px wider): the images cannot tell it from
    a re-draw.
    """

    max_dn: int  # largest |difference| of one pixel, digital numbers
    max_fraction: float  # share of an image's pixels that may differ at all
    max_bias: float  # largest |sum(d)| / sqrt(sum(d^2)) over the differing pixels (~N(0, 1))

    def accepts(self, a: bytes, b: bytes) -> bool:
        if len(a) != len(b):
            return False
        d = np.frombuffer(b, np.uint8).astype(np.int64) - np.frombuffer(a, np.uint8)
        d = d[d != 0]
        if d.size == 0:
            return True
        return (
            int(np.abs(d).max()) <= self.max_dn
            and d.size <= self.max_fraction * len(a)
            and abs(int(d.sum())) <= self.max_bias * math.sqrt(int((d * d).sum()))
        )

    def __str__(self) -> str:
        return (f"<= {self.max_dn} DN at <= {self.max_fraction:.2%} of the pixels, zero-mean "
                f"(|sum d| <= {self.max_bias:g} sqrt(sum d^2))")


IMAGE_TOLERANCE = ImageTolerance(max_dn=6, max_fraction=1.5e-3, max_bias=5.0)
# Byte fields compared as images (message type, field); every other bytes field is exact.
IMAGE_FIELDS = {("foxglove.RawImage", "data")}

_INDEX = re.compile(r"\[\d+\]$|\[#\]$")


def tolerance_of(path: str) -> Tolerance | None:
    """The tolerance of the float field at ``path`` (a :func:`flatten` key), None when no
    rule of :data:`UNIT_RULES` covers it."""
    for name in reversed(path.split(".")):
        name = _INDEX.sub("", name)
        for pattern, unit in UNIT_RULES:
            if re.search(pattern, name):
                return TOLERANCES[unit]
    return None


# -- finding the reference runs ---------------------------------------------------------------
@dataclass(frozen=True)
class ReferenceFile:
    """One component recording of one reference run."""

    run: str  # the run directory's name, e.g. "arc"
    component: str  # the recording's file stem, e.g. "perception"
    path: Path

    @property
    def id(self) -> str:
        return f"{self.run}/{self.component}"


def reference_files(root: str | Path) -> list[ReferenceFile]:
    """Every ``<root>/<run>/<component>.mcap``, sorted by run and component.

    Raises :class:`GoldenError` when there is none: a golden test over nothing must fail,
    not pass.
    """
    root = Path(root)
    if not root.is_dir():
        raise GoldenError(f"{root}: no such directory (the reference runs live in recordings/)")
    files = [
        ReferenceFile(p.parent.name, p.stem, p)
        for run in sorted(d for d in root.iterdir() if d.is_dir() and not d.name.startswith("."))
        for p in sorted(run.glob("*.mcap"))
    ]
    if not files:
        raise GoldenError(
            f"{root}: no reference runs (<run>/<component>.mcap); "
            "record them with `humanpt runs rerecord`"
        )
    return files


# -- flattening messages into comparable fields ---------------------------------------------
_TIME_TYPES = ("google.protobuf.Timestamp", "google.protobuf.Duration")
_QUATERNION = "humanpt.Quaternion"


def flatten(msg: Message, prefix: str = "", out: dict | None = None) -> dict[str, object]:
    """``{field path: value}`` of every field of ``msg`` (set or default).

    Numbers stay numbers; enums become their names; a repeated field adds ``name[#]``
    (its length) and ``name[i]`` per item; a Timestamp or Duration becomes one integer of
    nanoseconds; bytes stay bytes.  A quaternion is given with ``w >= 0``: q and -q are
    the same rotation, and a sign flip near 180 deg would otherwise show as a change of ~2.
    """
    out = {} if out is None else out
    for fd in msg.DESCRIPTOR.fields:
        name = f"{prefix}{fd.name}"
        value = getattr(msg, fd.name)
        if fd.is_repeated:
            items = list(value)
            out[f"{name}[#]"] = len(items)
            for i, item in enumerate(items):
                _flatten_value(fd, item, f"{name}[{i}]", out)
        else:
            _flatten_value(fd, value, name, out)
    return out


def _flatten_value(fd, value, name: str, out: dict) -> None:
    if fd.type == fd.TYPE_MESSAGE:
        if fd.message_type.full_name in _TIME_TYPES:
            out[name] = int(value.seconds) * 1_000_000_000 + int(value.nanos)
        elif fd.message_type.full_name == _QUATERNION:
            q = (value.x, value.y, value.z, value.w)
            lead = next((c for c in (q[3], q[0], q[1], q[2]) if c != 0), 0.0)
            sign = -1.0 if lead < 0 else 1.0
            for axis, c in zip("xyzw", q, strict=True):
                out[f"{name}.{axis}"] = sign * c
        else:
            flatten(value, name + ".", out)
    elif fd.type == fd.TYPE_ENUM:
        ev = fd.enum_type.values_by_number.get(value)
        out[name] = ev.name if ev is not None else str(value)
    else:
        out[name] = value


def is_stamp(path: str) -> bool:
    """A field holding an absolute time (made relative when comparing two live runs)."""
    last = path.rsplit(".", 1)[-1]
    return last.endswith("stamp_ns") or last == "timestamp"


def _decode(topic: str, data: bytes) -> Message | None:
    try:
        msg = topics.message_type(topic)()
        msg.ParseFromString(data)
        return msg
    except Exception:  # noqa: BLE001 - an undecodable message is compared by its bytes
        return None


# -- comparing two streams ------------------------------------------------------------------
@dataclass
class FieldDelta:
    """How one field differs over the paired messages of a topic."""

    field: str
    kind: str  # "number", "bytes" (max |difference| of the bytes as uint8) or "text"
    tolerance: str = "exact"  # what it is compared with (TOLERANCES, IMAGE_TOLERANCE)
    differing: int = 0  # paired messages in which it differs
    beyond: int = 0  # ... of which beyond its tolerance
    first_beyond: int = -1  # index on the topic (old stream) of the first of those
    max_abs: float = 0.0  # largest |new - old| (numbers, bytes)
    signed: float = 0.0  # new - old where |new - old| is largest
    at: int = -1  # index on the topic (old stream) of that message
    max_count: int = 0  # bytes: most bytes that differ in one message
    example: str = ""  # for text: "old -> new" of the first difference
    judged: bool = True  # False for two live runs (pairing by order): no tolerance applies

    def describe(self) -> str:
        tol = f"; tolerance {self.tolerance}" if self.judged and self.tolerance != "exact" else ""
        if self.judged and self.beyond:
            tol += f"; BEYOND it in {self.beyond}, first at #{self.first_beyond}"
        if self.kind == "text":
            return (f"{self.field}: differs in {self.differing} message(s), first at #{self.at}: "
                    f"{self.example}{tol}")
        what = "max |d| (bytes as uint8)" if self.kind == "bytes" else "max |d|"
        count = f", up to {self.max_count} bytes in one" if self.kind == "bytes" else ""
        return (
            f"{self.field}: {what} {self.max_abs:.6g} (new - old = {self.signed:+.6g} at #{self.at}; "
            f"differs in {self.differing}{count}{tol})"
        )


@dataclass
class TopicDiff:
    """One topic of two streams compared."""

    topic: str
    old_count: int
    new_count: int
    added: int = 0  # messages only in the new stream
    removed: int = 0  # messages only in the old stream
    differing: int = 0  # paired messages that differ
    beyond: int = 0  # ... of which in a field beyond its tolerance (or a discrete field)
    first: int | None = None  # index on the topic (old stream) of the first differing pair
    first_beyond: int | None = None  # ... of the first pair beyond tolerance
    fields: list[FieldDelta] = field(default_factory=list)
    judged: bool = True  # False for two live runs (pairing by order): no tolerance applies

    @property
    def identical(self) -> bool:
        return not (self.added or self.removed or self.differing)

    @property
    def within_tolerance(self) -> bool:
        """Every message paired; discrete fields equal, floats and images within tolerance."""
        return not (self.added or self.removed or self.beyond)

    def describe(self, max_fields: int = 8) -> list[str]:
        head = f"{self.topic}: {self.old_count} -> {self.new_count} messages"
        if self.identical:
            return [head + ", identical"]
        head += f", {self.added} added, {self.removed} removed, {self.differing} differ"
        if self.first is not None:
            head += f" (first at #{self.first})"
        if self.judged and self.within_tolerance:
            head += ", all within tolerance"
        elif self.judged and self.beyond:
            head += f", {self.beyond} beyond tolerance (first at #{self.first_beyond})"
        lines = [head]
        shown = (
            sorted(self.fields, key=_field_rank)[:max_fields] if max_fields >= 0 else self.fields
        )
        lines += ["    " + f.describe() for f in sorted(shown, key=lambda f: self.fields.index(f))]
        if len(self.fields) > len(shown):
            lines.append(f"    ... and {len(self.fields) - len(shown)} more field(s) differ")
        return lines


def _field_rank(f: FieldDelta) -> tuple:
    # The fields most worth a reviewer's eye first: beyond tolerance, more differing
    # messages, then by size.
    return (-f.beyond, -f.differing, -f.max_abs)


@dataclass
class StreamDiff:
    """Two output streams compared per topic (topics in order of first appearance)."""

    topics: list[TopicDiff]

    @property
    def identical(self) -> bool:
        return all(t.identical for t in self.topics)

    @property
    def within_tolerance(self) -> bool:
        return all(t.within_tolerance for t in self.topics)

    def describe(self, max_fields: int = 8, indent: str = "  ", only_changes: bool = False) -> str:
        lines = []
        for t in self.topics:
            if only_changes and t.identical:
                continue
            lines += [indent + line for line in t.describe(max_fields)]
        return "\n".join(lines)


def _keys(stream: Sequence[tuple[int, str, bytes]], pairing: Pairing) -> dict[str, list[tuple]]:
    """Per topic, the pairing key of each message, in stream order."""
    out: dict[str, list[tuple]] = {}
    seen: dict[tuple, int] = {}
    for t_ns, topic, _ in stream:
        if pairing == "step":
            k = (topic, t_ns)
            n = seen.get(k, 0)
            seen[k] = n + 1
            out.setdefault(topic, []).append((t_ns, n))
        else:
            out.setdefault(topic, []).append((len(out.get(topic, [])),))
    return out


def compare_streams(
    old: Sequence[tuple[int, str, bytes]],
    new: Sequence[tuple[int, str, bytes]],
    *,
    pairing: Pairing = "step",
    relative_stamps: bool = False,
) -> StreamDiff:
    """Compare two output streams per topic (see the module docstring).

    ``relative_stamps``: stamp fields (``*stamp_ns``, ``timestamp``) and the log time are
    compared relative to each stream's first message.
    """
    if pairing not in ("step", "order"):
        raise ValueError(f"pairing must be 'step' or 'order', got {pairing!r}")
    t0_old = min((t for t, _, _ in old), default=0) if relative_stamps else 0
    t0_new = min((t for t, _, _ in new), default=0) if relative_stamps else 0
    by_topic_old: dict[str, list[tuple[int, bytes]]] = {}
    by_topic_new: dict[str, list[tuple[int, bytes]]] = {}
    order: list[str] = []
    for stream, by in ((old, by_topic_old), (new, by_topic_new)):
        for t_ns, topic, data in stream:
            if topic not in by_topic_old and topic not in by_topic_new:
                order.append(topic)
            by.setdefault(topic, []).append((t_ns, data))
    keys_old, keys_new = _keys(old, pairing), _keys(new, pairing)
    result = []
    for topic in order:
        a_msgs, b_msgs = by_topic_old.get(topic, []), by_topic_new.get(topic, [])
        ka, kb = keys_old.get(topic, []), keys_new.get(topic, [])
        index_b = {k: i for i, k in enumerate(kb)}
        td = TopicDiff(topic, len(a_msgs), len(b_msgs))
        fields: dict[str, FieldDelta] = {}
        paired_b = set()
        for i, k in enumerate(ka):
            j = index_b.get(k)
            if j is None:
                td.removed += 1
                continue
            paired_b.add(j)
            (ta, da), (tb, db) = a_msgs[i], b_msgs[j]
            if da == db and (pairing == "step" or ta - t0_old == tb - t0_new):
                continue
            differs, beyond = _diff_pair(
                topic,
                i,
                da,
                db,
                fields,
                (ta - t0_old, tb - t0_new) if pairing == "order" else None,
                (t0_old, t0_new) if relative_stamps else None,
            )
            if differs:
                td.differing += 1
                if td.first is None:
                    td.first = i
            if beyond:
                td.beyond += 1
                if td.first_beyond is None:
                    td.first_beyond = i
        td.added = len(kb) - len(paired_b)
        td.fields = list(fields.values())
        if pairing == "order":
            td.judged = False
            for fd in td.fields:
                fd.judged = False
        result.append(td)
    return StreamDiff(result)


def _align_quaternions(fa: dict, fb: dict) -> None:
    """Give each quaternion of ``fb`` the sign that brings it nearest to ``fa``'s (q and -q
    are one rotation; flatten's sign rule flips near w = 0 on the last bits)."""
    for key in [k for k in fb if k.endswith(".w") and tolerance_of(k) is TOLERANCES["quaternion"]]:
        base = key[:-2]
        axes = [f"{base}.{c}" for c in "xyzw"]
        if all(k in fa and k in fb for k in axes):
            if sum(fa[k] * fb[k] for k in axes) < 0:
                for k in axes:
                    fb[k] = -fb[k]


def _diff_pair(
    topic: str,
    index: int,
    da: bytes,
    db: bytes,
    fields: dict[str, FieldDelta],
    log_times: tuple[int, int] | None,
    offsets: tuple[int, int] | None,
) -> tuple[bool, bool]:
    """Fold one differing pair into ``fields``: (it differs, it differs beyond tolerance)."""
    a, b = _decode(topic, da), _decode(topic, db)
    if a is None or b is None:
        fa, fb, type_name = {"<bytes>": da}, {"<bytes>": db}, ""
    else:
        fa, fb, type_name = flatten(a), flatten(b), a.DESCRIPTOR.full_name
        _align_quaternions(fa, fb)
    if log_times is not None:
        fa["(log time ns)"], fb["(log time ns)"] = log_times
    differs = beyond = False
    for name in dict.fromkeys([*fa, *fb]):
        if name not in fa or name not in fb:
            continue  # an item that only one side has: its list's [#] length already differs
        x, y = fa[name], fb[name]
        if offsets is not None and is_stamp(name) and isinstance(x, int) and x and y:
            x, y = x - offsets[0], y - offsets[1]  # 0 means "none": leave it
        if x == y or (
            isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y)
        ):
            continue
        differs = True
        if isinstance(x, bytes) and isinstance(y, bytes) and len(x) == len(y):
            d = np.frombuffer(y, np.uint8).astype(np.int16) - np.frombuffer(x, np.uint8).astype(
                np.int16
            )
            k = int(np.argmax(np.abs(d)))
            image = (type_name, name) in IMAGE_FIELDS
            out = not (image and IMAGE_TOLERANCE.accepts(x, y))
            fd = _fold(fields, name, "bytes", str(IMAGE_TOLERANCE) if image else "exact",
                       index, float(d[k]), out)
            fd.max_count = max(fd.max_count, int(np.count_nonzero(d)))
        elif isinstance(x, float) and isinstance(y, float):
            tol = tolerance_of(name)
            out = tol is None or not tol.accepts(x, y)
            _fold(fields, name, "number", str(tol) if tol else "none: add a rule to UNIT_RULES",
                  index, y - x, out)
        elif _is_number(x) and _is_number(y):
            out = True  # integers (counts, sequence numbers, stamps, cycles): exact
            _fold(fields, name, "number", "exact", index, y - x, out)
        else:
            out = True  # enums, flags, strings, bytes of another length: exact
            fd = fields.setdefault(name, FieldDelta(name, "text"))
            if fd.differing == 0:
                fd.at, fd.example = index, f"{_short(x)} -> {_short(y)}"
            fd.differing += 1
            _beyond(fd, index)
        beyond |= out
    if not differs and da != db and offsets is None:
        # Equal field by field once read (e.g. only a quaternion's sign), not byte for byte.
        fd = fields.setdefault("(bytes)", FieldDelta("(bytes)", "text", "the fields"))
        if fd.differing == 0:
            fd.at, fd.example = (
                index,
                "the encodings differ; the fields are equal (up to quaternion sign)",
            )
        fd.differing += 1
        differs = True
    return differs, beyond


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _short(v) -> str:
    if isinstance(v, bytes):
        return f"<{len(v)} bytes>"
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def _beyond(fd: FieldDelta, index: int) -> None:
    fd.beyond += 1
    if fd.first_beyond < 0:
        fd.first_beyond = index


def _fold(fields: dict[str, FieldDelta], name: str, kind: str, tolerance: str, index: int,
          delta: float, beyond: bool) -> FieldDelta:
    fd = fields.setdefault(name, FieldDelta(name, kind, tolerance))
    fd.differing += 1
    if abs(delta) > fd.max_abs or fd.at < 0:
        fd.max_abs, fd.signed, fd.at = abs(float(delta)), float(delta), index
    if beyond:
        _beyond(fd, index)
    return fd


# -- replay ----------------------------------------------------------------------------------
CoreFactory = Callable[[Recording], Core]


def replay_streams(
    path: str | Path, core_factory: CoreFactory = build_core
) -> tuple[Recording, Stream, Stream]:
    """(recording, recorded outputs, replayed outputs) of one component recording.

    Feeds a fresh core every recorded input, as :func:`humanpt.runtime.replay.replay`
    does, and keeps both output streams for :func:`compare_streams`.
    """
    rec = read(path)
    recorded, replayed = replay_recording(rec, core_factory)
    return rec, recorded, replayed[: len(recorded)] if rec.truncated else replayed


@dataclass
class GoldenResult:
    """The verdict on one component of one reference run; ``message`` says why."""

    ref: ReferenceFile
    ok: bool
    message: str
    diff: StreamDiff | None = None


def check_component(
    ref: ReferenceFile | str | Path,
    core_factory: CoreFactory = build_core,
    *,
    max_fields: int = 8,
    exact: bool = False,
) -> GoldenResult:
    """Replay one reference recording and demand its recorded outputs: discrete fields
    exactly, floats and images within :data:`TOLERANCES` / :data:`IMAGE_TOLERANCE`, or
    (``exact``) byte for byte."""
    if not isinstance(ref, ReferenceFile):
        p = Path(ref)
        ref = ReferenceFile(p.parent.name, p.stem, p)
    who = f"reference run {ref.run!r}, component {ref.component!r} ({ref.path})"
    try:
        rec, recorded, replayed = replay_streams(ref.path, core_factory)
    except (RecordingError, ConfigError) as e:
        # Old recordings are never misread: an incompatible one is refused, naming why.
        return GoldenResult(ref, False, f"{who}: cannot be replayed: {e}\n  {RERECORD_HINT}")
    if rec.truncated:
        return GoldenResult(ref, False, f"{who}: the reference recording is damaged: {rec.truncated}")
    n_inputs = len(rec.inputs)
    if n_inputs == 0 or not recorded:
        return GoldenResult(
            ref,
            False,
            f"{who}: {n_inputs} inputs and {len(recorded)} outputs "
            "recorded: a reference recording that holds nothing tests nothing",
        )
    diff = compare_streams(recorded, replayed, pairing="step")
    if exact:
        first = next((i for i, (a, b) in enumerate(zip(recorded, replayed, strict=False)) if a != b),
                     None if len(recorded) == len(replayed) else min(len(recorded), len(replayed)))
        if first is None:
            return GoldenResult(
                ref, True, f"{who}: {n_inputs} inputs replayed, {len(recorded)} outputs identical",
                diff,
            )
        verdict = "does not reproduce its recorded outputs byte for byte"
    else:
        first = _first_offence(recorded, replayed, diff)
        if first is None:
            return GoldenResult(ref, True, _pass_message(who, n_inputs, recorded, diff, max_fields),
                                diff)
        verdict = ("does not reproduce its recorded outputs (discrete fields exactly, floats "
                   "within TOLERANCES of humanpt.testing.golden)")
    r = recorded[first] if first < len(recorded) else None
    p = replayed[first] if first < len(replayed) else None
    item = r or p
    t_ns, topic = item[0], item[1]
    stream = recorded if r is not None else replayed
    on_topic = sum(1 for _, tp, _ in stream[:first] if tp == topic)
    t_first = rec.entries[0].t_ns if rec.entries else t_ns
    lines = [
        f"{who}: replaying its {n_inputs} recorded inputs {verdict}",
        f"  first differing message: topic {topic}, message #{on_topic} on that topic "
        f"(output #{first}), t_ns={t_ns} ({(t_ns - t_first) / 1e9:.3f} s into the recording)",
    ]
    for label, it in (("recorded", r), ("replayed", p)):
        lines.append(
            f"    {label}: "
            + ("(no message)" if it is None else f"topic {it[1]}, t_ns={it[0]}, {len(it[2])} bytes")
        )
    if r is not None and p is not None and (r[0], r[1]) != (p[0], p[1]):
        lines.append(
            "    (they come from different steps or topics: the replay added, lost or reordered "
            "messages; the per-topic summary below pairs messages by step)"
        )
    fields = _field_lines(r, p)
    if fields:
        lines.append("  fields that differ (recorded != replayed, by replayed - recorded):")
        lines += [f"    {f}" for f in fields[: max_fields * 3]]
        if len(fields) > max_fields * 3:
            lines.append(f"    ... and {len(fields) - max_fields * 3} more")
    lines.append(
        f"  the whole replay, per topic (recorded -> replayed; {len(recorded)} -> {len(replayed)} "
        "outputs):"
    )
    lines.append(diff.describe(max_fields, indent="    ", only_changes=True))
    lines.append(f"  {RERECORD_HINT}")
    return GoldenResult(ref, False, "\n".join(lines), diff)


def _first_offence(recorded: Stream, replayed: Stream, diff: StreamDiff) -> int | None:
    """Output index of the first message that breaks the tolerant comparison: the first
    place where the two streams' (time, topic) sequences part, or the first message beyond
    tolerance; None when there is none."""
    candidates = []
    order_r = [(t, tp) for t, tp, _ in recorded]
    order_p = [(t, tp) for t, tp, _ in replayed]
    if order_r != order_p:
        n = min(len(order_r), len(order_p))
        candidates.append(next((i for i in range(n) if order_r[i] != order_p[i]), n))
    for td in diff.topics:
        if td.first_beyond is not None:
            on_topic = [i for i, (_, tp, _) in enumerate(recorded) if tp == td.topic]
            candidates.append(on_topic[td.first_beyond])
    return min(candidates) if candidates else None


def _field_lines(r, p) -> list[str]:
    if r is None or p is None or r[1] != p[1]:
        return []
    a, b = _decode(r[1], r[2]), _decode(p[1], p[2])
    if a is None or b is None:
        return [] if r[2] == p[2] else [f"<bytes>: {len(r[2])} bytes != {len(p[2])} bytes"]
    return diff_messages(a, b)


def _pass_message(who: str, n_inputs: int, recorded: Stream, diff: StreamDiff,
                  max_fields: int) -> str:
    differing = sum(t.differing for t in diff.topics)
    head = (f"{who}: {n_inputs} inputs replayed, {len(recorded)} outputs compared: "
            f"{len(recorded) - differing} identical")
    if not differing:
        return head
    lines = [f"{head}, {differing} within tolerance; the largest difference per field:"]
    for t in diff.topics:
        if not t.identical:
            lines += ["  " + line for line in t.describe(max_fields)]
    return "\n".join(lines)


def check_all(
    files: Iterable[ReferenceFile], core_factory: CoreFactory = build_core
) -> list[GoldenResult]:
    """:func:`check_component` of each file."""
    return [check_component(f, core_factory) for f in files]
