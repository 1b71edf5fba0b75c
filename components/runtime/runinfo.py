"""What a recorded run holds: per component recording, its messages per topic and the
sequence gaps in what it received (``humanpt runs info``).

Every humanpt message carries a per-topic sequence number (``header.seq``) from its
publisher; a subscriber records every input it consumed, so a message it never got (a
network partition, a full queue) shows as a gap in the sequence of that topic in its
recording, and a publisher that restarted shows as a sequence starting again.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from humanpt.runtime.recording import IN, OUT, RecordingError, iter_entries, read_metadata
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
    if not complete:
        info.notes.append(f"{p}: not closed (the component did not stop cleanly)")
    last_seq: dict[str, int] = {}
    per: dict[tuple[str, str], TopicInfo] = defaultdict(TopicInfo)
    for e in iter_entries(p, info.notes):
        if e.direction not in (IN, OUT):
            continue
        info.start_ns = e.t_ns if info.start_ns is None else info.start_ns
        info.end_ns = e.t_ns
        t = per[(e.direction, e.topic)]
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
    """:func:`file_info` of every recording of a run (segments included), in name order."""
    d = Path(run_dir)
    if not d.is_dir():
        raise RecordingError(f"{d}: no such run directory")
    files = sorted(d.glob("*.mcap"))
    if not files:
        raise RecordingError(f"{d}: no .mcap recordings here")
    return [file_info(f) for f in files]
