"""Implementations of the CLI verbs (see ``humanpt --help``)."""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
from pathlib import Path

from humanpt.runtime import config as cfgmod
from humanpt.runtime import cycle as cell_cycle
from humanpt.runtime import run, supervisor
from humanpt.runtime.files import write_atomic
from humanpt.runtime.registry import (
    COMPONENTS,
    config_types,
    core_class,
)
from humanpt.runtime.run import load_config, run_router, run_stamp, stop_on_signals
from humanpt.schemas import topics

log = logging.getLogger("humanpt.cli")


# -- shared helpers ----------------------------------------------------------------------
def load_cfg(args) -> cfgmod.ConfigFile:
    """The config file of ``--config`` (validated), with ``--cell``/``--connect``/``--as`` applied."""
    return load_config(getattr(args, "config", None), cell=getattr(args, "cell", None),
                       connect=getattr(args, "connect", None), identity=getattr(args, "identity", None))


# -- router, components, up ------------------------------------------------------------------
def router(args) -> int:
    return run_router(load_cfg(args), args.listen)


def run_component(args) -> int:
    return run.run_component(load_cfg(args), args.component, args.run_dir, args.duration)


def up(args) -> int:
    cfg = load_cfg(args)
    comps = args.components.split(",") if args.components else None
    prof = supervisor.resolve_profile(cfg, args.profile, comps, args.no_router)
    run_dir = Path(args.run_dir) if args.run_dir else Path(cfg.runtime.run_dir) / f"{run_stamp()}-{prof.label}"
    print(f"humanpt up: profile {prof.label}: {'router, ' if prof.router else ''}{', '.join(prof.components)}",
          flush=True)
    print(f"humanpt up: recording to {run_dir}/", flush=True)
    res = supervisor.up(cfg, prof, run_dir, config_file=args.config, cell=args.cell, connect=args.connect or (),
                        duration_s=args.duration, stop=stop_on_signals(),
                        say=lambda line: print(f"humanpt up: {line}", flush=True))
    if res.failed:
        print(f"humanpt up: stopped because a child died: {', '.join(res.failed)}", file=sys.stderr, flush=True)
    print(f"humanpt up: stopped; recordings in {run_dir}/", flush=True)
    from humanpt.runtime.recording import losses_lines

    for line in losses_lines(run_dir):  # a component's recording lost messages to a write error
        print(f"humanpt up: {line}", flush=True)
    return res.exit_code


# -- inspection ----------------------------------------------------------------------------
def table(head: list[str], rows: list[list[str]], align: str) -> list[str]:
    """Lines of a text table whose columns fit their widest cell (``align``: one ``<`` or
    ``>`` per column); the last column is not padded."""
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]

    def line(cells: list[str]) -> str:
        out = [f"{c:{a}{w}s}" if i < len(cells) - 1 or a == ">" else c
               for i, (c, a, w) in enumerate(zip(cells, align, widths, strict=True))]
        return "  ".join(out).rstrip()

    return [line(head), *(line(r) for r in rows)]


def topics_cmd_table(as_json: bool = False) -> int:
    if as_json:  # the same as schemas/topics.json
        print(topics.table_json(), end="")
        return 0
    rows = [[t.short, t.type.DESCRIPTOR.full_name, t.publisher, t.doc] for t in topics.TOPICS.values()]
    print("\n".join(table(["key (humanpt/<cell>/...)", "type", "publisher", "description"], rows, "<<<<")))
    print(f"local inputs (never on the bus): {', '.join(topics.LOCAL_TOPICS)}")
    return 0


def topics_cmd(args) -> int:
    from humanpt.runtime.monitor import listen, publisher_of_key, type_of_key

    if args.table or args.json:
        return topics_cmd_table(args.json)
    if args.hz:
        return topics_hz(args)
    duration = 2.0 if args.duration is None else args.duration
    cfg = load_cfg(args)
    alive, stats = listen(cfg, duration)
    print(f"cell {cfg.runtime.cell}: components up: {', '.join(alive) or 'none'}")
    if not stats:
        print(f"no messages in {duration:g} s")
        return 0
    rows = [[key, type_of_key(key), publisher_of_key(key), str(s.count), f"{s.rate_hz:.1f}",
             f"{s.nbytes / s.count:.0f}"] for key, s in sorted(stats.items())]
    print("\n".join(table(["key", "type", "publisher", "count", "rate Hz", "avg bytes"], rows, "<<<>>>")))
    return 0


def hz_table(window: dict[str, tuple[int, int]], seconds: float) -> list[str]:
    """The lines of one ``topics --hz`` refresh: per key, messages and bytes in the last
    ``seconds`` as a rate (Hz) and a bandwidth (kB/s, 1 kB = 1000 bytes), then the total."""
    from humanpt.runtime.monitor import type_of_key

    rows = []
    for key in sorted(window):
        count, nbytes = window[key]
        rows.append([key, type_of_key(key), f"{count / seconds:.1f}", f"{nbytes / seconds / 1e3:.1f}",
                     f"{(nbytes / count if count else 0):.0f}"])
    count = sum(c for c, _ in window.values())
    nbytes = sum(b for _, b in window.values())
    rows.append(["total", "", f"{count / seconds:.1f}", f"{nbytes / seconds / 1e3:.1f}", ""])
    return table(["key", "type", "rate Hz", "kB/s", "avg bytes"], rows, "<<>>>")


def topics_hz(args) -> int:
    """``humanpt topics --hz``: rates and bandwidth per key over each --interval, until
    --duration (if given) or Ctrl-C."""
    from humanpt.runtime.monitor import watch_rates

    if not args.interval > 0:
        raise ValueError(f"--interval {args.interval:g}: must be > 0 s")
    cfg = load_cfg(args)
    tty = sys.stdout.isatty()

    def show(snap: dict[str, tuple[int, int]], elapsed_s: float, window_s: float) -> None:
        head = f"cell {cfg.runtime.cell}, {elapsed_s:.1f} s: rates over the last {window_s:.1f} s"
        body = hz_table(snap, window_s) if snap else ["no messages"]
        # a terminal gets a table refreshed in place; a pipe a block per interval
        print(("\x1b[H\x1b[J" if tty else "") + "\n".join([head, *body]) + ("" if tty else "\n"), flush=True)

    watch_rates(cfg, args.interval, show, args.duration, stop_on_signals())
    return 0


def echo(args) -> int:
    from humanpt.runtime import monitor

    cfg = load_cfg(args)
    key = monitor.full_key(args.key, cfg.runtime.cell)
    fields = list(args.field or [])
    if args.csv and not fields:
        raise ValueError("--csv prints fields: name them with --field (e.g. --field header.stamp_ns)")
    monitor.check_echo(key, fields)
    writer = None
    if args.csv:
        import csv

        writer = csv.writer(sys.stdout)
        writer.writerow(["stamp_ns", "key", *fields])

    def show(k: str, payload: bytes, type_name: str | None) -> None:
        if fields:
            row = monitor.field_row(k, payload, fields)
            if writer is not None:
                writer.writerow(row)
            else:
                print(f"{row[0]} {row[1]} " + " ".join(f"{f}={v}" for f, v in zip(fields, row[2:], strict=True)))
            sys.stdout.flush()
        else:
            tname, text = monitor.describe(k, payload, args.full, type_name)
            print(f"--- {k} ({tname})\n{text}", end="", flush=True)

    monitor.echo(cfg, key, show, count=args.count, duration_s=args.duration, stop=stop_on_signals())
    return 0


def _no_answer(cfg, component: str, timeout: float) -> int:
    from humanpt.runtime.params import no_answer

    print(f"humanpt param: {no_answer(cfg, component, timeout)}", file=sys.stderr)
    return 1


def _param_action(args) -> tuple[str, str, list[str]]:
    """(action, component, rest) of ``param``'s positionals: ``COMPONENT [KEY=VALUE...]``,
    ``dump COMPONENT [FILE]`` or ``load COMPONENT FILE``."""
    if args.component not in ("dump", "load"):
        return "set", cfgmod.current_name(args.component), list(args.assignments)
    rest = list(args.assignments)
    if not rest:
        raise ValueError(f"param {args.component}: name the component (humanpt param {args.component} COMPONENT"
                         f"{' [FILE]' if args.component == 'dump' else ' FILE'})")
    most = 2
    if len(rest) > most or (args.component == "load" and len(rest) != 2):
        raise ValueError(f"param {args.component}: expected COMPONENT {'[FILE]' if args.component == 'dump' else 'FILE'}"
                         f", got {' '.join(rest)}")
    return args.component, cfgmod.current_name(rest[0]), rest[1:]


def param(args) -> int:
    from humanpt.runtime import params

    action, component, rest = _param_action(args)
    if action == "dump":
        return param_dump(args, component, rest[0] if rest else None)
    if action == "load":
        return param_load(args, component, rest[0])
    cfg = load_cfg(args)
    body = params.query(cfg, component, dict(params.parse_assignment(a) for a in rest), args.timeout)
    if body is None:
        return _no_answer(cfg, component, args.timeout)
    for r in body.get("results", []):
        print(f"{'set' if r['ok'] else 'REJECTED'}: {r['text']}")
    print(json.dumps({"params": body.get("params"), "counters": body.get("counters")}, indent=2))
    return 0 if body.get("ok", False) else 1


def param_dump(args, component: str, out: str | None) -> int:
    """``humanpt param dump COMPONENT [FILE]``: the live parameters as TOML."""
    from humanpt.runtime import params

    if out is not None and Path(out).exists() and not args.overwrite:
        raise FileExistsError(f"{out}: exists; give --overwrite to replace it")
    cfg = load_cfg(args)
    body = params.query(cfg, component, {}, args.timeout)
    if body is None:
        return _no_answer(cfg, component, args.timeout)
    text = params.dump_text(cfg, component, body.get("params") or {})
    if out is None:
        print(text, end="")
    else:
        write_atomic(out, text)  # never through a link planted at its name
        print(f"humanpt param: {len(body.get('params') or {})} live parameters of {component} -> {out}",
              file=sys.stderr)
    return 0


def param_load(args, component: str, path: str) -> int:
    """``humanpt param load COMPONENT FILE``: :func:`humanpt.runtime.params.load_file`."""
    from humanpt.runtime import params

    params.read_file(path, component)  # a bad file is named before the config is read
    cfg = load_cfg(args)
    res = params.load_file(cfg, component, path, args.timeout)
    if not res.answered:
        return _no_answer(cfg, component, args.timeout)
    if res.refused:
        for r in res.refused:
            print(f"REJECTED: {r['text']}", file=sys.stderr)
        print(f"humanpt param load: {component} refused {len(res.refused)} of {res.keys}; "
              f"{'the others were set back' if res.restored else 'COULD NOT SET BACK ' + ', '.join(res.set_back)}"
              f" (nothing changed{'' if res.restored else '?'})", file=sys.stderr)
        return 1
    for r in res.results:
        print(f"set: {r['text']}")
    print(f"humanpt param load: {res.keys} parameters of {component} from {path}")
    return 0


# -- recordings ----------------------------------------------------------------------------
def replay(args) -> int:
    from humanpt.runtime.recording import RecordingError
    from humanpt.runtime.replay import (
        EXIT_INCOMPLETE,
        EXIT_MATCH,
        EXIT_MISMATCH,
        EXIT_NOTHING_COMPARED,
        EXIT_UNREADABLE,
    )
    from humanpt.runtime.replay import replay as do_replay

    path = Path(args.run)
    if path.is_dir():
        if args.component:
            files = [path / f"{args.component}.mcap"]
            if not files[0].exists():
                have = ", ".join(sorted(p.stem for p in path.glob("*.mcap"))) or "none"
                raise RecordingError(f"{path}: no recording of component {args.component!r} "
                                     f"(recordings here: {have})")
        else:
            files = sorted(path.glob("*.mcap"))
            if not files:
                raise RecordingError(f"{path}: no .mcap recordings in this directory")
    elif path.exists():
        files = [path]
    else:
        raise RecordingError(f"{path}: no such run directory or file")
    codes = []
    for f in files:
        try:
            res = do_replay(f, start_s=getattr(args, "from_s", None), last_s=getattr(args, "last", None))
        except (RecordingError, cfgmod.ConfigError) as e:  # say why, go on with the other files
            print(f"humanpt replay: cannot replay {f}: {e}", file=sys.stderr, flush=True)
            codes.append(EXIT_UNREADABLE)
            continue
        print(res.report(), flush=True)
        codes.append(res.exit_code)
    # The worst verdict: unreadable, then a mismatch, then not read in full, then nothing compared.
    for code in (EXIT_UNREADABLE, EXIT_MISMATCH, EXIT_INCOMPLETE, EXIT_NOTHING_COMPARED):
        if code in codes:
            return code
    return EXIT_MATCH


def runs_info(args) -> int:
    from humanpt.runtime.runinfo import run_info

    infos = run_info(args.run_dir)
    bad = False
    for f in infos:
        print(f"{f.path.name}: component {f.component}, {f.duration_s:.1f} s, {f.size_bytes / 1e6:.2f} MB")
        rows = sorted(f.topics.items(), key=lambda kv: (kv[0][0] != "in", kv[0][1]))
        for (direction, topic), t in rows:
            missed = ""
            if t.missing:
                missed = f"  MISSED {t.missing} in {t.gaps} gap(s), largest {t.largest_gap}"
            if t.restarts:
                missed += f"  publisher restarted {t.restarts}x"
            print(f"  {direction:3s} {topic:32s} {t.schema:26s} {t.count:8d} msgs {t.rate_hz:8.1f} Hz{missed}")
        for note in f.notes:
            print(f"  note: {note}")
        bad |= bool(f.missing_inputs or f.notes)
    from humanpt.runtime.recording import losses_lines
    from humanpt.runtime.runinfo import run_summary

    lost = losses_lines(args.run_dir)  # what a full disk (or another write error) cost
    for line in lost:
        print(line)
    run = run_summary(args.run_dir, infos)
    print(f"run: {run.duration_s:.1f} s, {len(infos)} recordings {run.recordings_bytes / 1e6:.2f} MB "
          f"({run.mb_per_minute:.1f} MB/min), directory {run.total_bytes / 1e6:.2f} MB")
    print(f"rig: {run.rig}")
    if run.warnings:
        print(f"warnings and errors published ({sum(run.warnings.values())}):")
        for (comp, sev, code), n in sorted(run.warnings.items()):
            print(f"  {comp:14s} {sev:8s} {code:28s} {n:6d}")
    else:
        print("warnings and errors published: none")
    if run.dropped:
        print(f"messages dropped by the shells ({sum(run.dropped.values())}):")
        for (comp, topic), n in sorted(run.dropped.items()):
            print(f"  {comp:14s} {topic:32s} {n:6d}")
    else:
        print("messages dropped by the shells: none")
    total = sum(f.missing_inputs for f in infos)
    print(f"humanpt runs info: {len(infos)} recordings; inputs missed: {total}; "
          f"recordings with write losses: {len(lost)}")
    return 1 if bad or lost else 0


def runs_merge(args) -> int:
    from humanpt.runtime.player import merge_run

    res = merge_run(args.run_dir, args.out)
    for note in res.notes:
        print(f"humanpt runs merge: warning: {note}", file=sys.stderr)
    print(f"humanpt runs merge: {res.messages} messages from {res.recordings} recordings on {res.topics} topics "
          f"-> {res.out}")
    if len(res.cells) == 1:
        from humanpt.scene.layout import write_layout

        layout = write_layout(res.out.with_suffix(".layout.json"), res.cells[0])
        print(f"humanpt runs merge: Foxglove layout for cell {res.cells[0]} -> {layout} (Layouts > Import)")
    return 0


def runs_play(args) -> int:
    """``humanpt runs play``: :func:`humanpt.runtime.player.play` with a progress line."""
    from humanpt.runtime import player

    player.check_options(args.rate, args.clock_period)
    files = player.run_files(args.run)
    wanted = player.check_topics(args.topics.split(",")) if args.topics else None
    cfg = load_cfg(args)
    span_ns = player.recorded_span_ns(files)
    tty = sys.stderr.isatty()
    total = f" / {span_ns / 1e9:.1f}" if span_ns is not None else ""

    def progress(recorded_s: float, n: int, round_: int) -> None:
        print(f"{chr(13) if tty else ''}humanpt runs play: {recorded_s:7.1f}{total} s recorded, "
              f"{n} messages{f', round {round_}' if args.loop else ''}",
              end="" if tty else "\n", file=sys.stderr, flush=True)

    def header() -> None:
        print(f"humanpt runs play: {len(files)} recordings of {args.run} -> cell {cfg.runtime.cell} at "
              f"x{args.rate:g}{', looping' if args.loop else ''}"
              f"{', clock on ' + player.CLOCK_TOPIC if args.clock else ''}; Ctrl-C stops", file=sys.stderr, flush=True)

    res = player.play(cfg, files, rate=args.rate, loop=args.loop, topics=wanted, clock=args.clock,
                      clock_period_s=args.clock_period, stop=stop_on_signals(), on_open=header, progress=progress)
    for note in dict.fromkeys(res.notes):
        print(f"\nhumanpt runs play: warning: {note}", file=sys.stderr)
    for topic, why in sorted(res.skipped.items()):
        print(f"humanpt runs play: warning: {topic} not played: {why}", file=sys.stderr)
    print(f"{chr(10) if tty else ''}humanpt runs play: {'stopped' if res.stopped else 'done'}; {res.messages} "
          f"messages on {res.topics} topics{f' in {res.rounds} rounds' if args.loop else ''}",
          file=sys.stderr, flush=True)
    if res.messages == 0:
        print("humanpt runs play: nothing to play (no bus outputs recorded"
              f"{' on the topics asked for' if wanted else ''})", file=sys.stderr)
        return 1
    return 0


def runs_list(args) -> int:
    from humanpt.runtime.recording import RecordingError, read_metadata

    root = Path(args.dir)
    if not root.is_dir():
        raise RecordingError(f"{root}: no such directory")
    runs = sorted(p for p in root.iterdir() if p.is_dir() and any(p.glob("*.mcap")))
    if not runs:
        print(f"no runs under {root}/")
    for r in runs:
        parts = []
        for f in sorted(r.glob("*.mcap")):
            try:
                meta, complete = read_metadata(f)
                parts.append(f"{f.stem} ({f.stat().st_size / 1e6:.2f} MB{'' if complete else ', unfinished'})")
            except RecordingError:
                parts.append(f"{f.stem} (unreadable)")
        print(f"{r}: {', '.join(parts)}")
    return 0


def config(args) -> int:
    cfg = cfgmod.load(args.config, config_types())
    rig = cfg.rig()
    rig_source = cfg.rig_path() or "nominal design values (no [runtime] rig)"
    for note in cfg.notes:
        print(f"note: {note}", file=sys.stderr)
    if args.check:
        print(f"{cfg.source}: OK; rig {rig_source}: OK ({rig.methods()})")
        print("\n".join(cell_cycle.report(cfg.cycle_period_ns, cfg.cycle_link)))
        return 0
    print(f"# effective configuration ({cfg.source}; defaults where it is silent)")
    print(f"# rig: {rig_source} ({rig.methods()}); `humanpt rig show` prints it")
    print("\n".join(f"# {line}" for line in cell_cycle.report(cfg.cycle_period_ns, cfg.cycle_link)))
    sections = {"runtime": cfg.runtime, "record": cfg.record}
    types = config_types()  # the config modules only: the server's install prints them too
    for name in sorted(COMPONENTS):
        sections[name] = cfg.component(name, types[name])
    for name, value in sections.items():
        print(f"\n[{name}]")
        notes = cfgmod.field_notes(type(value))  # the class read: the link's own for [robot_gateway]
        for k, v in cfgmod.to_table(value).items():
            note = f"  # {notes[k]}" if k in notes else ""
            print(f"{k} = {json.dumps(v)}{note}")
    return 0


def robot_files(args) -> int:
    from humanpt.robot_gateway.links import link_kind

    cfg = cfgmod.load(args.config, config_types())
    gw = cfg.component("robot_gateway", core_class("robot_gateway").config_type)
    write = link_kind(gw.link).write_robot_files
    if write is None:
        raise ValueError(f"[robot_gateway] link = {gw.link!r}: humanpt writes no robot-side files for it "
                         "(robot files are written for link = \"rsi\" (KUKA), \"abb\" (ABB EGM) and \"ur\" (UR RTDE))")
    paths = write(gw, args.out, args.sensor_ip, args.overwrite)
    for p in paths:
        print(f"humanpt robot-files: {p}")
    print(f"humanpt robot-files: {len(paths)} files for link {gw.link} at {gw.cycle_period_ms:g} ms; how to install "
          f"them: components/robot_gateway/links/{gw.link}/README.md")
    return 0


def check_output(out: str | Path, src: str | Path, overwrite: bool) -> None:
    """A command's output file: never its input, never an existing file unless
    ``overwrite`` (ValueError saying which)."""
    out = Path(out)
    if out.exists() and out.resolve() == Path(src).resolve():
        raise ValueError(f"{out}: is the input; write the result to another file")
    if out.exists() and not overwrite:
        raise ValueError(f"{out}: exists; give --overwrite to replace it")


def path_cmd(args) -> int:
    from humanpt.controller import pathfile

    check_output(args.output, args.input, args.overwrite)
    p = pathfile.read(args.input)
    if args.path_verb == "smooth":
        # Held orientations filled in first (Path6.points); the flags and the filter's
        # covariances are kept as recorded.
        out = dataclasses.replace(
            p, x_g=pathfile.smooth(p.points("G"), p.stamp_ns, accel_sigma=args.accel, meas_sigma=args.sigma),
            x_tip=None if p.x_tip is None else pathfile.smooth(p.points("tip"), p.stamp_ns, accel_sigma=args.accel,
                                                               meas_sigma=args.sigma))
        pathfile.write(args.output, out)
        print(f"humanpt path smooth: {len(p)} points -> {args.output}")
        return 0
    which = {"auto": "auto", "G": "G", "tip": "tip"}[args.point]
    write_atomic(args.output, pathfile.to_val2(p.points(which), args.name, args.speed))  # never through a link
    print(f"humanpt path val: {len(p)} points -> {args.output}")
    return 0

