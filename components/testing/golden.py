"""Golden replay of the reference runs, and per-topic comparison of two output streams.

The reference runs in ``recordings/<run>/`` (made live on the digital twin by
``humanpt runs rerecord``) guard the components' behaviour:

- :func:`check_component` replays one component recording with the product's replay shell
  (:func:`humanpt.runtime.replay.replay`) and demands the recorded outputs exactly.  Its
  failure message names the run, the component, the topic, the first differing message
  (its index on that topic and in the whole output stream, its time) and the fields that
  differ with their deltas, then summarises the whole replay per topic.
- :func:`compare_streams` compares two output streams per topic: messages added and
  removed, messages that differ, and the largest difference per field (numbers by value,
  images and other byte strings byte by byte, enums and text by count).  ``humanpt runs
  rerecord`` uses it to show what an intended change did before the new runs are accepted.

Messages are paired per topic either by *step* (the same log time and the same position
among that step's outputs: exact when both streams come from the same inputs) or by
*order* (the n-th message on a topic with the n-th: for two live runs, whose clocks and
timing differ).  For two live runs, stamps are compared relative to each recording's first
message (``relative_stamps``), so that the wall-clock start does not swamp the differences.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from google.protobuf.message import Message

from humanpt.runtime.config import ConfigError
from humanpt.runtime.core import Core
from humanpt.runtime.recording import Recording, RecordingError, read
from humanpt.runtime.replay import ReplayResult, build_core, replay
from humanpt.schemas import topics

Stream = list[tuple[int, str, bytes]]  # (log time ns, short topic, serialised message)
Pairing = Literal["step", "order"]

RERECORD_HINT = (
    "if the change is intended, `humanpt runs rerecord` shows its effect on every "
    "reference run and replaces them (see recordings/README.md)"
)


class GoldenError(ValueError):
    """The reference runs cannot be used (none found, or a run directory is malformed)."""


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
    differing: int = 0  # paired messages in which it differs
    max_abs: float = 0.0  # largest |new - old| (numbers, bytes)
    signed: float = 0.0  # new - old where |new - old| is largest
    at: int = -1  # index on the topic (old stream) of that message
    example: str = ""  # for text: "old -> new" of the first difference

    def describe(self) -> str:
        if self.kind == "text":
            return f"{self.field}: differs in {self.differing} message(s), first at #{self.at}: {self.example}"
        what = "max |d| (bytes as uint8)" if self.kind == "bytes" else "max |d|"
        return (
            f"{self.field}: {what} {self.max_abs:.6g} (new - old = {self.signed:+.6g} at #{self.at}; "
            f"differs in {self.differing})"
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
    first: int | None = None  # index on the topic (old stream) of the first differing pair
    fields: list[FieldDelta] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return not (self.added or self.removed or self.differing)

    def describe(self, max_fields: int = 8) -> list[str]:
        head = f"{self.topic}: {self.old_count} -> {self.new_count} messages"
        if self.identical:
            return [head + ", identical"]
        head += f", {self.added} added, {self.removed} removed, {self.differing} differ"
        if self.first is not None:
            head += f" (first at #{self.first})"
        lines = [head]
        shown = (
            sorted(self.fields, key=_field_rank)[:max_fields] if max_fields >= 0 else self.fields
        )
        lines += ["    " + f.describe() for f in sorted(shown, key=lambda f: self.fields.index(f))]
        if len(self.fields) > len(shown):
            lines.append(f"    ... and {len(self.fields) - len(shown)} more field(s) differ")
        return lines


def _field_rank(f: FieldDelta) -> tuple:
    # The fields most worth a reviewer's eye first: more differing messages, then by size.
    return (-f.differing, -f.max_abs)


@dataclass
class StreamDiff:
    """Two output streams compared per topic (topics in order of first appearance)."""

    topics: list[TopicDiff]

    @property
    def identical(self) -> bool:
        return all(t.identical for t in self.topics)

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
            differs = _diff_pair(
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
        td.added = len(kb) - len(paired_b)
        td.fields = list(fields.values())
        result.append(td)
    return StreamDiff(result)


def _diff_pair(
    topic: str,
    index: int,
    da: bytes,
    db: bytes,
    fields: dict[str, FieldDelta],
    log_times: tuple[int, int] | None,
    offsets: tuple[int, int] | None,
) -> bool:
    """Fold one differing pair into ``fields``; False when nothing differs after all."""
    a, b = _decode(topic, da), _decode(topic, db)
    if a is None or b is None:
        fa, fb = {"<bytes>": da}, {"<bytes>": db}
    else:
        fa, fb = flatten(a), flatten(b)
    if log_times is not None:
        fa["(log time ns)"], fb["(log time ns)"] = log_times
    differs = False
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
            _fold(fields, name, "bytes", index, float(d[k]))
        elif _is_number(x) and _is_number(y):
            _fold(fields, name, "number", index, y - x)
        else:
            fd = fields.setdefault(name, FieldDelta(name, "text"))
            if fd.differing == 0:
                fd.at, fd.example = index, f"{_short(x)} -> {_short(y)}"
            fd.differing += 1
    if not differs and da != db and offsets is None:
        # Equal field by field once read (e.g. only a quaternion's sign), not byte for byte.
        fd = fields.setdefault("(bytes)", FieldDelta("(bytes)", "text"))
        if fd.differing == 0:
            fd.at, fd.example = (
                index,
                "the encodings differ; the fields are equal (up to quaternion sign)",
            )
        fd.differing += 1
        differs = True
    return differs


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _short(v) -> str:
    if isinstance(v, bytes):
        return f"<{len(v)} bytes>"
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def _fold(fields: dict[str, FieldDelta], name: str, kind: str, index: int, delta: float) -> None:
    fd = fields.setdefault(name, FieldDelta(name, kind))
    fd.differing += 1
    if abs(delta) > fd.max_abs or fd.at < 0:
        fd.max_abs, fd.signed, fd.at = abs(float(delta)), float(delta), index


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
    core = core_factory(rec)
    replayed: Stream = []
    for e in rec.inputs:
        for topic, msg in core.step(e.t_ns, e.topic, e.decode()):
            replayed.append((e.t_ns, topic, msg.SerializeToString()))
    recorded: Stream = [(e.t_ns, e.topic, e.data) for e in rec.outputs]
    if rec.truncated:
        replayed = replayed[: len(recorded)]
    return rec, recorded, replayed


@dataclass
class GoldenResult:
    """The verdict on one component of one reference run; ``message`` says why."""

    ref: ReferenceFile
    ok: bool
    message: str
    replay: ReplayResult | None = None
    diff: StreamDiff | None = None


def check_component(
    ref: ReferenceFile | str | Path, core_factory: CoreFactory = build_core, *, max_fields: int = 8
) -> GoldenResult:
    """Replay one reference recording and demand its recorded outputs exactly."""
    if not isinstance(ref, ReferenceFile):
        p = Path(ref)
        ref = ReferenceFile(p.parent.name, p.stem, p)
    who = f"reference run {ref.run!r}, component {ref.component!r} ({ref.path})"
    try:
        result = replay(ref.path, core_factory)
    except (RecordingError, ConfigError) as e:
        # Old recordings are never misread: an incompatible one is refused, naming why.
        return GoldenResult(ref, False, f"{who}: cannot be replayed: {e}\n  {RERECORD_HINT}")
    if result.truncated:
        return GoldenResult(
            ref, False, f"{who}: the reference recording is damaged: {result.truncated}", result
        )
    if result.inputs == 0 or result.recorded_outputs == 0:
        return GoldenResult(
            ref,
            False,
            f"{who}: {result.inputs} inputs and {result.recorded_outputs} outputs "
            "recorded: a reference recording that holds nothing tests nothing",
            result,
        )
    if result.match:
        return GoldenResult(
            ref,
            True,
            f"{who}: {result.inputs} inputs replayed, {result.recorded_outputs} outputs identical",
            result,
        )
    div = result.divergence
    # The whole replay once more, to say where the divergence sits on its topic and what
    # else differs (only on failure: it costs a second replay).
    try:
        rec, recorded, replayed = replay_streams(ref.path, core_factory)
        diff = compare_streams(recorded, replayed, pairing="step")
    except Exception as e:  # noqa: BLE001 - the first divergence is the verdict; this is detail
        rec, recorded, replayed, diff = None, [], [], None
        extra = f"  (no per-topic summary: {type(e).__name__}: {e})"
    item = div.recorded or div.replayed
    t_ns, topic = item[0], item[1]
    stream = recorded if div.recorded is not None else replayed
    on_topic = sum(1 for _, tp, _ in stream[: div.index] if tp == topic)
    t_first = rec.entries[0].t_ns if rec is not None and rec.entries else t_ns
    lines = [
        f"{who}: replaying its {result.inputs} recorded inputs does not reproduce its recorded outputs",
        f"  first differing message: topic {topic}, message #{on_topic} on that topic "
        f"(output #{div.index}), t_ns={t_ns} ({(t_ns - t_first) / 1e9:.3f} s into the recording)",
    ]
    for label, it in (("recorded", div.recorded), ("replayed", div.replayed)):
        lines.append(
            f"    {label}: "
            + ("(no message)" if it is None else f"topic {it[1]}, t_ns={it[0]}, {len(it[2])} bytes")
        )
    if div.recorded is not None and div.replayed is not None and div.recorded[0] != div.replayed[0]:
        lines.append(
            "    (they come from different steps: the replay added or lost messages; "
            "the per-topic summary below pairs messages by step)"
        )
    if div.fields:
        lines.append("  fields that differ (recorded != replayed, by replayed - recorded):")
        lines += [f"    {f}" for f in div.fields[: max_fields * 3]]
        if len(div.fields) > max_fields * 3:
            lines.append(f"    ... and {len(div.fields) - max_fields * 3} more")
    if diff is not None:
        lines.append(
            f"  the whole replay, per topic (recorded -> replayed; {len(recorded)} -> {len(replayed)} "
            "outputs):"
        )
        lines.append(diff.describe(max_fields, indent="    ", only_changes=True))
    else:
        lines.append(extra)
    lines.append(f"  {RERECORD_HINT}")
    return GoldenResult(ref, False, "\n".join(lines), result, diff)


def check_all(
    files: Iterable[ReferenceFile], core_factory: CoreFactory = build_core
) -> list[GoldenResult]:
    """:func:`check_component` of each file."""
    return [check_component(f, core_factory) for f in files]
