"""What a recorded run holds: per component recording, its messages per topic and the
sequence gaps in what it received (``humanpt runs info``).

Every humanpt message carries a per-topic sequence number (``header.seq``) from its
publisher; a subscriber records every input it consumed, so a message it never got (a
network partition, a full queue) shows as a gap in the sequence of that topic in its
recording, and a publisher that restarted shows as a sequence starting again.

:func:`run_summary` adds what the run as a whole was: its duration (first to last message
of any recording, on the recording's time base), its size and MB per minute, the rig it ran
with (the run directory's rig.toml, else the rig recorded in each file's metadata), the
warnings and errors its components published (``<component>/events`` outputs of severity
warning or error, counted by component and code) and the messages a shell dropped (the
``direction=dropped`` channels, by topic).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from humanpt.runtime.recording import DROPPED, IN, OUT, RecordingError, iter_entries, read_metadata
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics


@dataclass
class TopicInfo:
    """One topic of one recording, one direction."""

    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    missing: int = 0  # messages missing from the publisher's sequence (inputs only)
    gaps: int = 0  # places where the sequence jumps ahead
    largest_gap: int = 0
    restarts: int = 0  # the sequence started again (a publisher restarted)
    schema: str = ""  # the full protobuf type name it was recorded with

    @property
    def rate_hz(self) -> float:
        if self.count < 2 or self.first_ns is None or self.last_ns == self.first_ns:
            return 0.0
        return (self.count - 1) / ((self.last_ns - self.first_ns) / 1e9)


@dataclass
class FileInfo:
    path: Path
    component: str = "?"
    start_ns: int | None = None
    end_ns: int | None = None
    size_bytes: int = 0
    topics: dict[tuple[str, str], TopicInfo] = field(default_factory=dict)  # (direction, topic)
    notes: list[str] = field(default_factory=list)  # truncation, skipped chunks, unreadable
    metadata: dict[str, str] = field(default_factory=dict)  # the humanpt.run record
    # (severity name, code) -> count, of the events this component published (warning and up)
    warnings: Counter = field(default_factory=Counter)
    dropped: Counter = field(default_factory=Counter)  # topic -> messages the shell dropped

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9

    @property
    def missing_inputs(self) -> int:
        return sum(t.missing for (d, _), t in self.topics.items() if d == IN)


def file_info(path: str | Path) -> FileInfo:
    """Counts, rates and input sequence gaps of one recording (read to any damage)."""
    p = Path(path)
    info = FileInfo(p, size_bytes=p.stat().st_size if p.exists() else 0)
    try:
        meta, complete = read_metadata(p)
    except RecordingError as e:
        info.notes.append(str(e))
        return info
    info.component = meta.get("component", "?")
    info.metadata = meta
    if not complete:
        info.notes.append(f"{p}: not closed (the component did not stop cleanly)")
    last_seq: dict[str, int] = {}
    per: dict[tuple[str, str], TopicInfo] = defaultdict(TopicInfo)
    for e in iter_entries(p, info.notes):
        if e.direction == DROPPED:
            info.dropped[e.topic] += 1
            continue
        if e.direction not in (IN, OUT):
            continue
        if e.direction == OUT and e.topic.endswith("/events"):
            _count_warning(info, e)
        info.start_ns = e.t_ns if info.start_ns is None else info.start_ns
        info.end_ns = e.t_ns
        t = per[(e.direction, e.topic)]
        t.schema = t.schema or e.schema
        t.count += 1
        t.first_ns = e.t_ns if t.first_ns is None else t.first_ns
        t.last_ns = e.t_ns
        if e.direction != IN or e.topic not in topics.TOPICS:
            continue
        try:
            seq = e.decode().header.seq
        except (AttributeError, ValueError, RecordingError):
            continue  # images carry no sequence number (foxglove.RawImage)
        prev = last_seq.get(e.topic)
        last_seq[e.topic] = seq
        if prev is None:
            continue
        if seq > prev + 1:
            t.gaps += 1
            t.missing += seq - prev - 1
            t.largest_gap = max(t.largest_gap, seq - prev - 1)
        elif seq < prev - 1:
            t.restarts += 1
    info.topics = dict(per)
    return info


def run_info(run_dir: str | Path) -> list[FileInfo]:
    """:func:`file_info` of every recording of a run (segments included), in name order; of
    the one recording given as a file (``runs play`` takes either)."""
    d = Path(run_dir)
    if d.is_file():
        return [file_info(d)]
    if not d.is_dir():
        raise RecordingError(f"{d}: no such run directory or .mcap file")
    files = sorted(d.glob("*.mcap"))
    if not files:
        raise RecordingError(f"{d}: no .mcap recordings here")
    return [file_info(f) for f in files]


_SEVERITY_NAMES = {pb.SEVERITY_WARNING: "warning", pb.SEVERITY_ERROR: "error", pb.SEVERITY_FATAL: "fatal"}


def _count_warning(info: FileInfo, e) -> None:
    try:
        ev = e.decode()
    except (RecordingError, topics.UnknownTopicError):
        return
    if ev.severity >= pb.SEVERITY_WARNING:
        info.warnings[(_SEVERITY_NAMES.get(ev.severity, "error"), ev.code or "?")] += 1


@dataclass
class RunSummary:
    """A run as a whole (``humanpt runs info``'s last lines)."""

    files: list[FileInfo]
    total_bytes: int  # every file of the run directory (recordings, rig, paths, ...)
    recordings_bytes: int  # the .mcap files
    rig: str  # where the rig came from and how it was obtained, one line
    warnings: Counter  # (component, severity name, code) -> count
    dropped: Counter  # (component, topic) -> messages dropped

    @property
    def start_ns(self) -> int | None:
        starts = [f.start_ns for f in self.files if f.start_ns is not None]
        return min(starts) if starts else None

    @property
    def duration_s(self) -> float:
        ends = [f.end_ns for f in self.files if f.end_ns is not None]
        return 0.0 if self.start_ns is None else (max(ends) - self.start_ns) / 1e9

    @property
    def mb_per_minute(self) -> float:
        """Recorded MB (1e6 bytes, the .mcap files) per minute of run; 0 for an empty run."""
        return self.recordings_bytes / 1e6 / (self.duration_s / 60.0) if self.duration_s > 0 else 0.0


def _rig_line(run_dir: Path, files: list[FileInfo], folder: bool = True) -> str:
    from humanpt.runtime.rigfile import load_rig, rig_from_json

    recorded = {f.metadata["rig"] for f in files if f.metadata.get("rig")}
    differ = f"; the recordings hold {len(recorded)} different rigs" if len(recorded) > 1 else ""
    path = run_dir / "rig.toml"
    if folder and path.exists():  # (one file given: its own recorded rig, not its folder's)
        try:
            rig = load_rig(path)
            return f"{path.name}: {rig.name} ({rig.methods()}){differ}"
        except Exception as e:  # noqa: BLE001 - a damaged rig file: say so, go on
            return f"{path.name}: unreadable ({e}){differ}"
    if recorded:
        try:
            rig = rig_from_json(sorted(recorded)[0])
            return f"recorded in the files: {rig.name} ({rig.methods()}){differ}"
        except Exception as e:  # noqa: BLE001
            return f"recorded in the files, unreadable ({e})"
    return "none recorded"


def run_summary(run_dir: str | Path, files: list[FileInfo] | None = None) -> RunSummary:
    """The whole run of :func:`run_info` (given ``files``, not read again)."""
    files = run_info(run_dir) if files is None else files
    d = Path(run_dir) if Path(run_dir).is_dir() else Path(run_dir).parent
    warnings: Counter = Counter()
    dropped: Counter = Counter()
    for f in files:
        for (sev, code), n in f.warnings.items():
            warnings[(f.component, sev, code)] += n
        for topic, n in f.dropped.items():
            dropped[(f.component, topic)] += n
    total = (sum(p.stat().st_size for p in d.rglob("*") if p.is_file()) if Path(run_dir).is_dir()
             else Path(run_dir).stat().st_size)
    return RunSummary(files, total, sum(f.size_bytes for f in files), _rig_line(d, files, Path(run_dir).is_dir()), warnings, dropped)
