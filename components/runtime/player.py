"""The recording player (``humanpt runs play``, like ``ros2 bag play``): a run's recorded bus
outputs put back on the live cell at their recorded timing, so that ``echo``, the console's
status and the viewer work on an old run; and :func:`merge_run` (``humanpt runs merge``):
every output of a run in one MCAP, for Foxglove or rerun.

    from humanpt.runtime.player import play, run_files
    from humanpt.runtime.run import load_config
    res = play(load_config("cell.toml"), run_files("runs/x"), rate=2.0, topics={"controller/status"})
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from humanpt.runtime import config as cfgmod
from humanpt.runtime.recording import RecordingError
from humanpt.schemas import topics as topic_table

CLOCK_TOPIC = "player/clock"


def run_files(run: str | Path) -> list[Path]:
    """The .mcap recordings of a run directory, or the one file given (RecordingError when
    there is none)."""
    path = Path(run)
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise RecordingError(f"{path}: no .mcap recordings here")
        return files
    if path.exists():
        return [path]
    raise RecordingError(f"{path}: no such run directory or file")


def recorded_span_ns(files: Iterable[Path]) -> int | None:
    """Last minus first log time over ``files`` from their MCAP summaries (None when a file
    has none: an unfinished recording)."""
    from mcap.reader import make_reader

    starts, ends = [], []
    for f in files:
        try:
            with open(f, "rb") as fh:
                stats = make_reader(fh).get_summary().statistics
        except Exception:  # noqa: BLE001 - no summary (unfinished, damaged): the span is unknown
            return None
        if stats is None:
            return None
        if stats.message_count:
            starts.append(stats.message_start_time)
            ends.append(stats.message_end_time)
    return max(ends) - min(starts) if starts else 0


def check_topics(wanted: Iterable[str]) -> set[str]:
    """``wanted`` as a set of short topics of the table (ValueError naming the unknown ones)."""
    wanted = {t.strip() for t in wanted if t.strip()}
    unknown = sorted(t for t in wanted if t not in topic_table.TOPICS)
    if unknown:
        raise ValueError(f"--topics: {', '.join(unknown)} not in the topic table (short names such as "
                         f"controller/status; `humanpt topics --table` lists them)")
    return wanted


def check_options(rate: float, clock_period_s: float) -> None:
    """ValueError naming a rate or clock period that is not positive."""
    if not rate > 0:
        raise ValueError(f"--rate {rate:g}: must be > 0 (1 = recorded speed, 2 = twice as fast)")
    if not clock_period_s > 0:
        raise ValueError(f"--clock-period {clock_period_s:g}: must be > 0 s")


@dataclass
class PlayResult:
    messages: int = 0  # put on the bus
    topics: int = 0  # topics played
    rounds: int = 0
    stopped: bool = False  # by ``stop``, not by the end of the recording
    skipped: dict[str, str] = field(default_factory=dict)  # topic -> why it was not played
    notes: list[str] = field(default_factory=list)  # what could not be read (damage)


def play(cfg: cfgmod.ConfigFile, files: list[Path], *, rate: float = 1.0, loop: bool = False,
         topics: set[str] | None = None, clock: bool = False, clock_period_s: float = 0.1,
         stop: threading.Event | None = None, on_open: Callable[[], None] | None = None,
         progress: Callable[[float, int, int], None] | None = None) -> PlayResult:
    """Put every ``direction=out`` message of ``files`` on a bus topic (local topics never;
    only ``topics`` when given), merged by log time, on ``humanpt/<cell>/<topic>`` of
    ``cfg``'s cell: message k at (t_k - t_0) / ``rate`` after the first.  ``clock``: a
    ``player/clock`` Tick (header stamp = the recording's time) every ``clock_period_s`` of
    recorded time.  ``loop``: again from the start until ``stop``.  ``on_open()`` once
    connected; ``progress(recorded_s, messages, round)`` about once a second."""
    from humanpt.runtime.bus import declare_topic_publisher, open_tool_session
    from humanpt.runtime.recording import OUT, merge_entries
    from humanpt.schemas import humanpt_pb2 as pb

    check_options(rate, clock_period_s)
    cell = cfg.runtime.cell
    res = PlayResult()
    stop = stop or threading.Event()

    def keep(e) -> bool:
        if e.direction != OUT or e.topic not in topic_table.TOPICS or (topics is not None and e.topic not in topics):
            return False  # inputs, local topics (serial bytes, show: copies), topics not asked for
        if e.schema != topic_table.TOPICS[e.topic].type.DESCRIPTOR.full_name:
            res.skipped[e.topic] = f"recorded as {e.schema}, this version's type differs"
            return False
        return True

    with open_tool_session(cfg.runtime) as session:
        pubs: dict[str, object] = {}
        clock_pub = declare_topic_publisher(session, cell, CLOCK_TOPIC) if clock else None
        clock_period_ns = int(clock_period_s * 1e9)
        if on_open is not None:
            on_open()
        next_progress = time.monotonic()
        while not stop.is_set():
            t0 = wall0 = None
            next_clock_ns = clock_seq = 0
            played = 0
            for t_ns, _f, e in merge_entries(files, res.notes, keep):
                if t0 is None:
                    t0, wall0, next_clock_ns = t_ns, time.monotonic(), t_ns
                while clock_pub is not None and next_clock_ns <= t_ns:  # the clock's ticks due before it
                    if stop.wait(max(0.0, wall0 + (next_clock_ns - t0) / 1e9 / rate - time.monotonic())):
                        break
                    clock_pub.put(pb.Tick(header=pb.Header(stamp_ns=next_clock_ns, seq=clock_seq,
                                                           frame_id="recording"),
                                          period_ns=clock_period_ns).SerializeToString())
                    clock_seq += 1
                    next_clock_ns += clock_period_ns
                # wait on the stop event, not a sleep: a stop ends the wait at once
                if stop.wait(max(0.0, wall0 + (t_ns - t0) / 1e9 / rate - time.monotonic())):
                    break
                pub = pubs.get(e.topic)
                if pub is None:
                    pub = pubs[e.topic] = declare_topic_publisher(session, cell, e.topic, block=True)
                pub.put(e.data)
                res.messages += 1
                played += 1
                now = time.monotonic()
                if progress is not None and now >= next_progress:
                    next_progress = now + 1.0
                    progress((t_ns - t0) / 1e9, res.messages, res.rounds + 1)
            res.rounds += 1
            if not loop or played == 0:
                break
        for pub in [*pubs.values(), *([clock_pub] if clock_pub else [])]:
            pub.undeclare()
    res.topics = len(pubs)
    res.stopped = stop.is_set()
    return res


@dataclass
class MergeResult:
    messages: int
    recordings: int
    topics: int
    notes: list[str]  # recordings (or parts) that could not be read and were left out
    out: Path | None = None  # the file written
    cells: tuple[str, ...] = ()  # the cells the merged recordings are of


MERGED_METADATA = "humanpt.merged"  # a merged file's own metadata record (not a component's humanpt.run)
# What differs per component recording and so is not the run's: left out of the merged record.
_PER_COMPONENT = ("component", "core", "config", "pid", "start_time_ns", "continues", "lost_before")


def run_metadata(metas: list[dict[str, str]]) -> dict[str, str]:
    """The run's metadata for a merged file: each key every readable recording has with one
    value (the rig, the cell, the world, the schema version...), and the components merged.
    A key the recordings disagree on is kept as ``<key>.<component>`` per recording, so nothing
    recorded about the run (e.g. two different rigs) is lost."""
    out: dict[str, str] = {"components": ",".join(sorted(m.get("component", "?") for m in metas))}
    keys = sorted({k for m in metas for k in m} - set(_PER_COMPONENT))
    for k in keys:
        values = {m.get(k) for m in metas}
        if len(values) == 1:
            out[k] = next(iter(values))
        else:
            for m in metas:
                if k in m:
                    out[f"{k}.{m.get('component', '?')}"] = m[k]
    return out


def merged_path(run_dir: str | Path, out: str | Path) -> Path:
    """Where ``runs merge RUN OUT`` writes: ``OUT``, or ``OUT/<run>.mcap`` when OUT is an
    existing directory; RecordingError when that is inside the run directory, or its parent
    does not exist."""
    run_dir, out = Path(run_dir), Path(out)
    if out.is_dir():
        out = out / f"{run_dir.resolve().name or 'run'}.mcap"
    if out.resolve().parent == run_dir.resolve():
        raise RecordingError(f"{out}: write the merged file outside the run directory")
    if not out.parent.is_dir():
        raise RecordingError(f"{out}: no such directory {out.parent}")
    return out


def merge_run(run_dir: str | Path, out: str | Path) -> MergeResult:
    """Write the outputs of every component recording of ``run_dir`` into one MCAP ``out``
    (topics as full Zenoh keys, a component's local outputs under ``<component>/local/``,
    time order).  RecordingError when the run has no recording, or ``out`` is inside it."""
    from mcap.writer import Writer
    from mcap_protobuf.schema import register_schema

    from humanpt.runtime.recording import OUT, merge_entries, read_metadata

    run_dir = Path(run_dir)
    files = sorted(p for p in run_dir.glob("*.mcap")) if run_dir.is_dir() else []
    if not files:
        raise RecordingError(f"{run_dir}: no .mcap recordings here")
    out = merged_path(run_dir, out)
    notes: list[str] = []
    where: dict[Path, tuple[str, str]] = {}  # file -> (cell, component)
    metas: list[dict[str, str]] = []
    for f in files:
        try:
            meta, _ = read_metadata(f)
            metas.append(meta)
        except RecordingError:
            meta = {}  # merge_entries says why it leaves it out
        where[f] = (meta.get("cell", "cell0"), meta.get("component", f.stem.split(".")[0]))
    n = 0
    with open(out, "wb") as fh:
        w = Writer(fh)
        w.start(profile="humanpt", library="humanpt runs merge")
        w.add_metadata(MERGED_METADATA, run_metadata(metas))
        schema_ids: dict[str, int] = {}
        channels: dict[str, int] = {}
        for t_ns, f, e in merge_entries(files, notes, keep=lambda e: e.direction == OUT):
            cell, component = where[f]
            # Bus topics on their key; a component's local outputs (serial bytes...) apart.
            key = (f"{topic_table.KEY_PREFIX}/{cell}/{e.topic}" if "/" in e.topic
                   else f"{topic_table.KEY_PREFIX}/{cell}/{component}/local/{e.topic}")
            if key not in channels:
                try:
                    cls = topic_table.message_type(e.topic)
                except topic_table.UnknownTopicError:
                    continue  # a topic this version does not know: nothing to decode it with
                name = cls.DESCRIPTOR.full_name
                if name not in schema_ids:
                    schema_ids[name] = register_schema(w, cls)
                channels[key] = w.register_channel(topic=key, message_encoding="protobuf",
                                                   schema_id=schema_ids[name])
            w.add_message(channel_id=channels[key], log_time=t_ns, data=e.data, publish_time=t_ns, sequence=n)
            n += 1
        w.finish()
    cells = tuple(sorted({cell for cell, _ in where.values()}))
    return MergeResult(n, len(files), len(channels), notes, out, cells)
