"""A recorded run -> rerun: the function behind ``humanpt view``.

Every component recording's outputs (``direction=out``) are merged in time order (like
``humanpt runs merge``, streaming: constant memory), passed through a :class:`VizCore`
(the same choice of what to show as live) and logged with the same
:class:`~humanpt.viz.logger.RerunLogger` and blueprint.  The view's geometry comes from
the run: d_z from the recorded controller config, the hand-eye, PSVS and target from the
recorded rig.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import rerun as rr
from mcap.reader import make_reader

from humanpt.geometry.rig import Rig
from humanpt.runtime.config import ConfigError, build, to_table
from humanpt.runtime.recording import OUT, RecordingError, merge_entries, read_metadata
from humanpt.schemas import topics
from humanpt.viz.config import VizConfig
from humanpt.viz.core import SHOWN_TOPICS, VizCore
from humanpt.viz.logger import RerunLogger

__all__ = ["ConvertStats", "convert_run", "rig_for_run", "run_files", "viz_config_for_run"]

# Keys of the view's config taken from the run's own components (the rest of the geometry
# is the run's recorded rig).
_FROM_RUN = {"controller": ("dz_mm",)}


@dataclass
class ConvertStats:
    recordings: int = 0
    messages: int = 0  # outputs read
    shown: int = 0  # given to the logger
    total: int | None = None  # outputs expected (from the files' summaries), None if unknown
    seconds: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)  # drawn, per topic
    errors: dict[str, int] = field(default_factory=dict)  # could not be drawn, per topic
    notes: list[str] = field(default_factory=list)  # truncated recordings


def run_files(run_dir: str | Path) -> list[Path]:
    """The component recordings of a run (viz's own is left out: its outputs are copies)."""
    d = Path(run_dir)
    if not d.is_dir():
        raise RecordingError(f"{d}: no such run directory")
    files = [f for f in sorted(d.glob("*.mcap")) if f.stem != "viz"]
    if not files:
        raise RecordingError(f"{d}: no component recordings (.mcap) here")
    return files


def viz_config_for_run(run_dir: str | Path, base: VizConfig | None = None) -> VizConfig:
    """``base`` with the geometry of the run's recorded controller and perception configs."""
    table = to_table(base or VizConfig())
    for f in run_files(run_dir):
        try:
            meta, _ = read_metadata(f)
        except RecordingError:
            continue
        keys = _FROM_RUN.get(meta.get("component", ""))
        if not keys:
            continue
        import json

        recorded = json.loads(meta.get("config", "{}"))
        table.update({k: recorded[k] for k in keys if k in recorded})
    try:
        return build(VizConfig, table, source=f"{run_dir} (recorded configs)", section="viz")
    except ConfigError:
        return base or VizConfig()  # a run of an older layout: draw with the defaults


def recorded_cycle_ns(run_dir: str | Path) -> int | None:
    """The cycle (ns) a run made before robot states carried it ran with: its recorded
    controller config's retired cycle key (runtime.cycle.recorded); None for a newer run (its
    robot states carry the cycle) or none recorded."""
    import json

    from humanpt.runtime import cycle

    for f in run_files(run_dir):
        try:
            meta, _ = read_metadata(f)
        except RecordingError:
            continue
        if meta.get("component") == "controller":
            try:
                return cycle.recorded("controller", json.loads(meta.get("config", "{}")))[1]
            except (ValueError, TypeError, AttributeError):
                return None
    return None


def rig_for_run(run_dir: str | Path) -> Rig:
    """The rig the run's pipeline used: the one recorded with its controller (else with
    perception, the pose filter, any component); the nominal rig for a run without one."""
    from humanpt.runtime.rigfile import RIG_METADATA, rig_from_json

    found: dict[str, str] = {}
    for f in run_files(run_dir):
        try:
            meta, _ = read_metadata(f)
        except RecordingError:
            continue
        if RIG_METADATA in meta:
            found.setdefault(meta.get("component", ""), meta[RIG_METADATA])
    for name in ("controller", "perception", "pose_filter", *found):
        if name in found:
            try:
                return rig_from_json(found[name], f"{run_dir} ({name}'s recorded rig)")
            except ConfigError:
                continue
    return Rig()


def _expected_outputs(path: Path) -> int | None:
    """Number of shown outputs in a closed recording (from its summary), None if unknown."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - an unfinished file has no summary
        return None
    if summary is None or summary.statistics is None:
        return None
    return sum(
        n
        for cid, n in summary.statistics.channel_message_counts.items()
        if cid in summary.channels
        and summary.channels[cid].metadata.get("direction") == OUT
        and summary.channels[cid].topic in SHOWN_TOPICS
    )


def _merged_outputs(files: list[Path], notes: list[str]) -> Iterator[tuple[int, str, bytes]]:
    keep = lambda e: e.direction == OUT and e.topic in SHOWN_TOPICS  # noqa: E731
    for t_ns, _, e in merge_entries(files, notes, keep):
        yield t_ns, e.topic, e.data


def convert_run(
    run_dir: str | Path,
    rec: rr.RecordingStream,
    *,
    config: VizConfig | None = None,
    rig: Rig | None = None,
    image_every: int = 1,
    progress: Callable[[ConvertStats], None] | None = None,
    progress_every: int = 2000,
) -> ConvertStats:
    """Log a recorded run to ``rec`` (whose sinks the caller set).

    ``config``: the view's config (default: from the run, :func:`viz_config_for_run`);
    ``rig``: the geometry to draw with (default: the run's, :func:`rig_for_run`);
    ``image_every``: show every Nth image; ``progress(stats)`` is called every
    ``progress_every`` messages and at the end.
    """
    files = run_files(run_dir)
    cfg = config or viz_config_for_run(run_dir)
    import dataclasses

    cfg = dataclasses.replace(cfg, image_every=image_every)
    core = VizCore(cfg)
    logger = RerunLogger(rec, cfg, rig=rig or rig_for_run(run_dir), recorded_timeline=True)
    old_cycle_ns = recorded_cycle_ns(run_dir)
    if old_cycle_ns is not None:  # a run whose robot states carry no cycle: its controller's
        logger.cycle_period_ns = old_cycle_ns
    rec.set_log_time_enabled(False)  # the conversion's wall clock means nothing here
    stats = ConvertStats(recordings=len(files))
    totals = [_expected_outputs(f) for f in files]
    stats.total = None if any(t is None for t in totals) else sum(totals)
    t0 = time.perf_counter()
    for t_ns, topic, data in _merged_outputs(files, stats.notes):
        stats.messages += 1
        msg = topics.message_type(topic)()
        try:
            msg.ParseFromString(data)
        except Exception:  # noqa: BLE001 - a message that does not decode is counted, not fatal
            stats.errors[topic] = stats.errors.get(topic, 0) + 1
            continue
        for out_topic, out in core.step(t_ns, topic, msg):
            logger.log(topics.shown_short(out_topic), out, t_ns)
            stats.shown += 1
        if progress is not None and stats.messages % progress_every == 0:
            stats.seconds = time.perf_counter() - t0
            progress(stats)
    stats.seconds = time.perf_counter() - t0
    stats.counts = dict(logger.counts)
    for k, v in logger.errors.items():
        stats.errors[k] = stats.errors.get(k, 0) + v
    if progress is not None:
        progress(stats)
    return stats
