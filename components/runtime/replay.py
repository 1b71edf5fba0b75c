"""The replay shell: re-run a component on its recorded inputs and compare outputs.

The core is rebuilt from the recording's metadata (core class and config), fed every
recorded input in order with the time it was given, and its outputs are compared byte
for byte with the recorded ones (run == replay is exact within one build).  The first
divergence is reported with the fields that differ.

A verdict is never reached on nothing: a recording of which no message can be read
raises :class:`RecordingError`; one that holds no inputs, or whose truncation leaves no
output to compare, is "nothing compared", not a match.  A recording that cannot be read in
full (cut, never closed, a chunk damaged or refused, messages whose channel is lost) is
compared up to the damage and the report says how much was read, but it is never a match:
at best INCOMPLETE.  Exit statuses of ``humanpt replay``: :data:`EXIT_MATCH`,
:data:`EXIT_MISMATCH`, :data:`EXIT_UNREADABLE`, :data:`EXIT_NOTHING_COMPARED`,
:data:`EXIT_INCOMPLETE`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from google.protobuf import descriptor_pb2, text_format
from google.protobuf.message import DecodeError, Message
from mcap.reader import make_reader
from mcap.records import Schema

from humanpt.runtime import cycle
from humanpt.runtime.config import build
from humanpt.runtime.core import Core
from humanpt.runtime.recording import (
    FULL,
    IN,
    OUT,
    Recording,
    RecordingDamage,
    RecordingError,
    SnapshotEntry,
    iter_records,
    read,
    resolve_images,
    strip_image,
)
from humanpt.runtime.registry import COMPONENTS, class_path, core_class
from humanpt.runtime.snapshot import SnapshotError, parse_snapshot
from humanpt.schemas import humanpt_pb2, topics


def build_core(rec: Recording) -> Core:
    """A fresh core of the recorded component and config.

    The core class comes from the registry of known components (``runtime.registry``), by
    the class path the recording names: nothing a recording says is ever imported, so a
    planted module or a forged path cannot run code.  Replaying a core the registry does not
    know (a test's own) takes an explicit ``core_factory``."""
    path = rec.metadata.get("core")
    if not path:
        raise RecordingError(f"{rec.path}: the recording does not name its core class")
    known = {p: name for name, p in COMPONENTS.items()}
    if path not in known:
        raise RecordingError(
            f"{rec.path}: the recording names core class {path!r}, which is not a component of "
            f"this version ({', '.join(sorted(COMPONENTS))}); nothing named by a recording is imported")
    return _rebuild(core_class(known[path]), rec)


def recorded_rig(rec: Recording):
    """The rig a recording was made with (:class:`humanpt.geometry.rig.Rig`), or None."""
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.rigfile import RIG_METADATA, rig_from_json

    text = rec.metadata.get(RIG_METADATA)
    if text is None:
        return None
    try:
        return rig_from_json(text, f"{rec.path} (recorded rig)")
    except ConfigError as e:
        raise RecordingError(str(e)) from None


def _rebuild(cls: type[Core], rec: Recording) -> Core:
    """A fresh core of ``cls`` from the recording's config and rig."""
    # A recording made before the cell had one cycle (runtime/cycle.py) names the cycle its
    # core ran with in its config: mapped on reading (its robot states carry none).
    table, old_cycle_ns = cycle.recorded(rec.component, rec.config())
    cfg = build(cls.config_type, table, source=f"{rec.path} (recorded config)", section=rec.component)
    rig = recorded_rig(rec)
    if cls.uses_rig and rig is None:
        raise RecordingError(f"{rec.path}: recorded without a rig (an older humanpt kept the calibration "
                             f"in the components' configs); record it again with this version")
    core = cls.create(cfg, rig)
    if old_cycle_ns is not None and hasattr(core, "use_cycle"):
        core.use_cycle(old_cycle_ns)
    return core


def factory_with(*classes: type[Core]) -> Callable[[Recording], Core]:
    """A ``core_factory`` for :func:`replay` that also knows ``classes`` (a test's own cores,
    given as class objects, never looked up by name)."""
    extra = {class_path(c): c for c in classes}

    def factory(rec: Recording) -> Core:
        cls = extra.get(rec.metadata.get("core", ""))
        if cls is None:
            return build_core(rec)
        return _rebuild(cls, rec)

    return factory


def diff_messages(a: Message, b: Message, prefix: str = "") -> list[str]:
    """Fields that differ between two messages of the same type: ``path: a != b (by d)``."""
    out: list[str] = []
    if type(a) is not type(b):
        return [f"{prefix or '<message>'}: type {type(a).__name__} != {type(b).__name__}"]
    for fd in a.DESCRIPTOR.fields:
        name = f"{prefix}{fd.name}"
        va, vb = getattr(a, fd.name), getattr(b, fd.name)
        if fd.is_repeated:
            la, lb = list(va), list(vb)
            if len(la) != len(lb):
                out.append(f"{name}: {len(la)} items != {len(lb)} items")
                continue
            for i, (x, y) in enumerate(zip(la, lb, strict=True)):
                out += _diff_value(fd, x, y, f"{name}[{i}]")
        else:
            out += _diff_value(fd, va, vb, name)
    return out


def _diff_value(fd, x, y, name: str) -> list[str]:
    if fd.type == fd.TYPE_MESSAGE:
        return diff_messages(x, y, name + ".")
    if x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)):
        return []
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return [f"{name}: {x!r} != {y!r} (by {y - x:+.6g})"]
    if isinstance(x, bytes):
        return [f"{name}: {len(x)} bytes != {len(y)} bytes"]
    return [f"{name}: {x!r} != {y!r}"]


@dataclass
class Divergence:
    index: int  # position in the output stream
    recorded: tuple[int, str, bytes] | None  # (t_ns, topic, data)
    replayed: tuple[int, str, bytes] | None
    fields: list[str] = field(default_factory=list)

    def describe(self) -> str:
        lines = [f"first divergence at output #{self.index}:"]
        for label, item in (("recorded", self.recorded), ("replayed", self.replayed)):
            if item is None:
                lines.append(f"  {label}: (no message)")
                continue
            t, topic, data = item
            lines.append(f"  {label}: t_ns={t} topic={topic} ({len(data)} bytes)")
        if self.fields:
            lines.append("  fields that differ (recorded != replayed):")
            lines += [f"    {f}" for f in self.fields[:20]]
            if len(self.fields) > 20:
                lines.append(f"    ... and {len(self.fields) - 20} more")
        return "\n".join(lines)


EXIT_MATCH = 0  # the recording was read in full and every output compared identical
EXIT_MISMATCH = 1  # an output differs, is missing or is extra
EXIT_UNREADABLE = 2  # the recording cannot be read (missing, not MCAP, no message, ...)
EXIT_NOTHING_COMPARED = 3  # readable, but no input to replay or no output left to compare
EXIT_INCOMPLETE = 4  # not read in full: the outputs read are identical, but that is not a match


@dataclass
class ReplayResult:
    path: Path
    component: str
    inputs: int
    recorded_outputs: int  # read from the recording (up to a truncation)
    replayed_outputs: int  # made by the replay from the inputs read
    divergence: Divergence | None
    truncated: str | None  # why the file could not be read in full, None when it was
    compared: int = 0  # output pairs found identical (before the divergence, if any)
    messages_read: int = 0  # every message read: inputs, outputs, dropped inputs
    # A segment resumed after a write error (metadata ``continues``): the core's state at its
    # start was never recorded, so a fresh core cannot replay it. Why, else None.
    continuation: str | None = None
    # Inputs the run did not keep (images without pixels: ``[record] images``, a producer's
    # recording cut short): the replay stops at the first. What, else None.
    missing: str | None = None
    notes: list[str] = field(default_factory=list)  # every reason it was not read in full
    # Replayed from a snapshot (``start_s`` / ``last_s``): where, for people; None: from the start.
    start: str | None = None

    @property
    def nothing_compared(self) -> bool:
        """No input to replay, or a truncation (or a missing input) that leaves no recorded
        output to compare while the replay made some: no verdict either way."""
        if self.divergence is not None:
            return False
        return self.continuation is not None or self.inputs == 0 or (
            (self.truncated is not None or self.missing is not None)
            and self.compared == 0 and self.replayed_outputs > 0
        )

    @property
    def incomplete(self) -> bool:
        """Identical as far as it goes, but the recording could not be read in full."""
        return self.divergence is None and not self.nothing_compared and self.truncated is not None

    @property
    def match(self) -> bool:
        return self.divergence is None and not self.nothing_compared and self.truncated is None

    @property
    def exit_code(self) -> int:
        if self.match:
            return EXIT_MATCH
        if self.nothing_compared:
            return EXIT_NOTHING_COMPARED
        return EXIT_INCOMPLETE if self.incomplete else EXIT_MISMATCH

    def report(self) -> str:
        head = (f"{self.path}: component {self.component}: {self.messages_read} messages read, "
                f"{self.inputs} inputs replayed, {self.recorded_outputs} outputs recorded, "
                f"{self.replayed_outputs} replayed, {self.compared} compared")
        if self.start:
            head += f"\n  {self.start}"
        trunc = ""
        if self.truncated:
            trunc = (f"\n  the recording could not be read in full: {self.messages_read} messages read; only the "
                     f"{self.recorded_outputs} outputs read before the first damage are compared")
            notes = self.notes or [self.truncated]
            trunc += "".join(f"\n  - {n}" for n in notes[:6])
            if len(notes) > 6:
                trunc += f"\n  - ... and {len(notes) - 6} more"
        if self.missing:
            trunc += f"\n  inputs missing: {self.missing}"
        if self.nothing_compared:
            why = (self.continuation or ("no input was read before the first damage"
                                         if self.inputs == 0 and self.truncated
                                         else "the recording holds no inputs" if self.inputs == 0
                                         else "no recorded output before the first missing input"
                                         if self.missing and not self.truncated
                                         else "no recorded output survives the truncation"))
            return f"{head}{trunc}\n  NOTHING COMPARED: {why}; this is not a match"
        if self.incomplete:
            return (f"{head}{trunc}\n  INCOMPLETE: the {self.compared} outputs read are identical to the replay's, "
                    f"but the recording could not be read in full; this is not a match")
        if self.match:
            if self.compared == 0:
                return f"{head}{trunc}\n  MATCH: the core output nothing, recorded or replayed"
            upto = " up to the first missing input" if self.missing else ""
            return f"{head}{trunc}\n  MATCH: every output is identical{upto} ({self.compared} compared)"
        return f"{head}{trunc}\n  MISMATCH\n{self.divergence.describe()}"


def _decode(topic: str, data: bytes) -> Message | None:
    try:
        msg = topics.message_type(topic)()
        msg.ParseFromString(data)
        return msg
    except Exception:  # noqa: BLE001 - a diff is best effort
        return None


Stream = list[tuple[int, str, bytes]]  # (log time ns, short topic, serialised message)


def missing_inputs(rec: Recording) -> str | None:
    """Put back the pixels of the images ``rec`` recorded without them (``recording.
    resolve_images``; raises RecordingError when the producer's recording is not there)
    and cut the recording before its first input still without them: a core cannot be
    replayed past an input it never gets.  Returns what is missing, for people (None:
    nothing).  Idempotent."""
    if rec.resolved:
        return rec.missing
    left = resolve_images(rec)
    rec.resolved = True
    inputs = [e for e in left if e.direction == IN]
    if not inputs:
        return None
    first = inputs[0]
    by_topic: dict[str, int] = {}
    for e in inputs:
        by_topic[e.topic] = by_topic.get(e.topic, 0) + 1
    n_in = sum(1 for e in rec.entries if e.direction == IN)
    cut = rec.entries.index(first)
    rec.entries = rec.entries[:cut]
    rec.missing = (
        f"{len(inputs)} of {n_in} inputs have no pixels in the run "
        f"({', '.join(f'{t} {n}' for t, n in sorted(by_topic.items()))}); the first, #{first.index} at "
        f"t_ns={first.t_ns}: {first.missing or '?'}; replayed and compared up to it")
    return rec.missing


def choose_snapshot(rec: Recording, *, start_s: float | None = None, last_s: float | None = None,
                    ) -> SnapshotEntry | None:
    """The last snapshot of ``rec`` at or before the start asked for: ``start_s`` seconds of
    input time after its first input, or ``last_s`` before its last; None when there is none
    (or neither is given).  Only snapshots within the entries kept (before a gap or a missing
    input) count."""
    if start_s is None and last_s is None:
        return None
    times = [e.t_ns for e in rec.entries if e.direction == IN]
    if not times:
        return None
    start_ns = times[0] + round(start_s * 1e9) if start_s is not None else times[-1] - round(last_s * 1e9)
    best = None
    for s in rec.snapshots:
        if s.at <= len(rec.entries) and s.t_ns <= start_ns:
            best = s
    return best


def thaw_snapshot(rec: Recording, snap: SnapshotEntry, core: Core) -> int:
    """Put ``snap`` into ``core`` (fresh from the recording): checks that the snapshot is this
    component's and follows as many inputs in the file as it says; returns that number.
    Raises RecordingError (one line) when it is refused."""
    what = f"{rec.path}: the snapshot at t_ns={snap.t_ns}"
    try:
        table = parse_snapshot(snap.data, what)
        if table.get("component") != rec.component:
            raise SnapshotError(f"{what}: it is of component {str(table.get('component'))[:40]!r}, the "
                                f"recording of {rec.component!r}")
        n_in = sum(1 for e in rec.entries[:snap.at] if e.direction == IN)
        if table["inputs"] != n_in or table["t_ns"] != snap.t_ns:
            raise SnapshotError(f"{what}: it follows input #{table['inputs']} at t_ns={table['t_ns']}, the file "
                                f"has {n_in} inputs before it")
        core.thaw(table.get("core"))
    except SnapshotError as e:
        text = str(e)
        raise RecordingError(text if text.startswith(what) else f"{what}: {text}") from None
    return n_in


def _schemas(path: Path) -> list[Schema]:
    """The schema records of a recording: from its summary when it was closed, else read
    through (a damaged file: those before the damage; the replay itself reports it)."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        if summary is not None and summary.schemas:
            return list(summary.schemas.values())
    except Exception:  # noqa: BLE001 - no usable summary: read through below
        pass
    out: list[Schema] = []
    try:
        for r in iter_records(path, []):
            if isinstance(r, Schema):
                out.append(r)
    except (RecordingError, RecordingDamage, OSError):
        pass
    return out


def fields_newer_than(rec: Recording) -> dict[str, tuple[str, ...]]:
    """Message type -> the fields this build's schema has and the recording's does not (a
    field added since, e.g. ``RobotState.cycle_period_ns``): a replay leaves them out of its
    outputs before comparing, as the recording could not hold them.  Empty for a recording
    made with this schema."""
    recorded: dict[str, frozenset[str]] = {}
    for r in _schemas(Path(rec.path)):
        if r.encoding == "protobuf" and r.name not in recorded:
            try:
                fds = descriptor_pb2.FileDescriptorSet.FromString(r.data)
            except DecodeError:
                continue
            for f in fds.file:
                for m in f.message_type:
                    recorded.setdefault(f"{f.package}.{m.name}" if f.package else m.name,
                                        frozenset(fd.name for fd in m.field))
    out = {}
    for name, fields in recorded.items():
        try:
            desc = humanpt_pb2.DESCRIPTOR.pool.FindMessageTypeByName(name)
        except KeyError:
            continue
        newer = tuple(fd.name for fd in desc.fields if fd.name not in fields)
        if newer:
            out[name] = newer
    return out


def replay_recording(rec: Recording, core_factory: Callable[[Recording], Core] = build_core,
                     snapshot: SnapshotEntry | None = None) -> tuple[Stream, Stream]:
    """(recorded outputs, replayed outputs) of a recording: a fresh core fed every recorded
    input (of a truncated recording, the replayed stream runs past the recorded one's cut);
    with ``snapshot`` (of ``rec.snapshots``), the fresh core thawed from it and fed the inputs
    after it, and the outputs after it compared.

    Images recorded without their pixels are first resolved (:func:`missing_inputs`: the
    recording is cut before an input that cannot be); a recorded output image still without
    them (``[record] images`` did not keep it) is compared without its pixels."""
    missing_inputs(rec)
    core = core_factory(rec)
    entries = rec.entries
    newer = fields_newer_than(rec)
    if snapshot is not None:
        thaw_snapshot(rec, snapshot, core)
        entries = entries[snapshot.at:]
    replayed: Stream = []
    for e in entries:
        if e.direction != IN:
            continue
        for topic, msg in core.step(e.t_ns, e.topic, e.decode()):
            unknown = newer.get(msg.DESCRIPTOR.full_name)
            if unknown:  # fields added since the recording: not demanded of it
                for name in unknown:
                    msg.ClearField(name)
            replayed.append((e.t_ns, topic, msg.SerializeToString()))
    outputs = [e for e in entries if e.direction == OUT]
    recorded: Stream = [(e.t_ns, e.topic, e.data) for e in outputs]
    for i, e in enumerate(outputs):
        if e.payload != FULL and i < len(replayed) and replayed[i][1] == e.topic:
            try:
                t, topic, data = replayed[i]
                msg = topics.message_type(topic)()
                msg.ParseFromString(data)
                replayed[i] = (t, topic, strip_image(msg).SerializeToString())
            except Exception:  # noqa: BLE001 - not an image: the comparison shows it
                pass
    return recorded, replayed


def replay(path: str | Path, core_factory: Callable[[Recording], Core] = build_core, *,
           start_s: float | None = None, last_s: float | None = None) -> ReplayResult:
    """Replay one component recording; see the module docstring.

    ``start_s`` (seconds of input time after the first input) or ``last_s`` (seconds before
    the last): start from the core's last snapshot at or before that time (``[record]
    snapshot_period_s``), thawed into the fresh core, and compare the outputs after it; a
    recording without one replays from its start (the report says which).  A snapshot that
    is refused (crafted, of another version) raises RecordingError (one line)."""
    if start_s is not None and last_s is not None:
        raise ValueError("replay: give start_s or last_s, not both")
    for v in (start_s, last_s):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise ValueError(f"replay: a start of {v!r} s (a finite number of seconds >= 0 expected)")
    rec = read(path)
    if not rec.entries and rec.truncated:
        raise RecordingError(f"{rec.truncated}: no message could be read, nothing to replay")
    if "continues" in rec.metadata:
        why = (f"this segment continues {rec.metadata['continues'] or 'the recording'} after "
               f"{rec.metadata.get('lost_before', '?')} messages were lost to a write error: the core's "
               f"state at its start was not recorded, so it cannot be replayed from its config")
        return ReplayResult(rec.path, rec.component, len(rec.inputs), len(rec.outputs), 0, None, rec.truncated,
                            0, len(rec.entries), continuation=why, notes=rec.notes)
    n_read = len(rec.entries)  # before a gap or a missing input cuts them
    if rec.first_gap is not None:
        # Messages are missing there (a chunk skipped): the core's state after it is unknown, so
        # the inputs after it cannot be replayed and the outputs after it cannot be compared.
        rec.entries = rec.entries[:rec.first_gap]
    missing_inputs(rec)  # (cuts the entries before an input without its pixels)
    snap = choose_snapshot(rec, start_s=start_s, last_s=last_s)
    start = None
    if start_s is not None or last_s is not None:
        asked = (f"{start_s:g} s after the first input" if start_s is not None
                 else f"{last_s:g} s before the last input")
        if snap is None:
            start = f"no snapshot at or before {asked}: replayed from the start"
        else:
            n_in = sum(1 for e in rec.entries[:snap.at] if e.direction == IN)
            start = (f"from the snapshot at t_ns={snap.t_ns} (the last at or before {asked}): the core thawed "
                     f"after input #{n_in}; the inputs before it and their outputs not replayed")
    recorded, replayed = replay_recording(rec, core_factory, snap)
    missing = rec.missing
    # The lost chunk of a truncated file held the tail of both streams (an input without its
    # pixels cut both): compare what both have.
    replayed_cmp = replayed[:len(recorded)] if rec.truncated or missing else replayed
    div = None
    compared = min(len(recorded), len(replayed_cmp))
    for i in range(max(len(recorded), len(replayed_cmp))):
        r = recorded[i] if i < len(recorded) else None
        p = replayed_cmp[i] if i < len(replayed_cmp) else None
        if r != p:
            fields: list[str] = []
            if r and p:
                if r[1] != p[1]:
                    fields.append(f"topic: {r[1]!r} != {p[1]!r}")
                if r[0] != p[0]:
                    fields.append(f"t_ns: {r[0]} != {p[0]} (by {p[0] - r[0]:+d})")
                if r[1] == p[1]:
                    a, b = _decode(r[1], r[2]), _decode(p[1], p[2])
                    if a is not None and b is not None:
                        fields += diff_messages(a, b)
            div = Divergence(i, r, p, fields)
            compared = i
            break
    n_inputs = sum(1 for e in rec.entries[snap.at if snap else 0:] if e.direction == IN)
    return ReplayResult(rec.path, rec.component, n_inputs, len(recorded), len(replayed), div,
                        rec.truncated, compared, n_read, missing=missing, notes=rec.notes, start=start)


def message_text(topic: str, data: bytes) -> str:
    """One-line text of a recorded message, for people."""
    msg = _decode(topic, data)
    return "<undecodable>" if msg is None else text_format.MessageToString(msg, as_one_line=True)[:500]
