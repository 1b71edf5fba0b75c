"""Implementations of the CLI verbs (see ``humanpt --help``)."""

from __future__ import annotations

import dataclasses
import json
import logging
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

from humanpt.runtime import config as cfgmod
from humanpt.runtime.bus import liveliness_key, open_tool_session, params_key, zenoh_config
from humanpt.runtime.registry import (
    COMPONENTS,
    PROFILES,
    UnknownComponentError,
    adapters_for,
    config_types,
    core_class,
)
from humanpt.schemas import topics

log = logging.getLogger("humanpt.cli")


# -- shared helpers ----------------------------------------------------------------------
def load_cfg(args) -> cfgmod.ConfigFile:
    """The config file of ``--config`` (validated), with ``--cell``/``--connect`` applied."""
    cfg = cfgmod.load(getattr(args, "config", None), config_types())
    changes = {}
    if getattr(args, "cell", None):
        changes["cell"] = args.cell
    if getattr(args, "connect", None):
        changes["connect"] = tuple(args.connect)
    if getattr(args, "identity", None):
        changes["identity"] = args.identity
    if changes:
        try:
            rt = dataclasses.replace(cfg.runtime, **changes)
        except ValueError as e:
            raise cfgmod.ConfigError(f"command line: {e}") from e
        cfg = dataclasses.replace(cfg, runtime=rt)
    cfg.rig()  # a missing or bad rig file fails here, before anything starts
    return cfg


def stop_on_signals(extra: threading.Event | None = None) -> threading.Event:
    """An Event set by SIGINT or SIGTERM (and by ``extra``'s owner)."""
    stop = extra or threading.Event()

    def handler(signum, frame):
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def run_stamp() -> str:
    return time.strftime("%Y%m%d-%H%M%S")


# -- router, components, up ------------------------------------------------------------------
def router(args) -> int:
    import zenoh

    cfg = load_cfg(args)
    listen = tuple(args.listen) if args.listen else cfg.runtime.listen
    conf = zenoh_config(cfg.runtime, mode="router", listen=listen, connect=())
    stop = stop_on_signals()
    watch = reporter = None
    if cfg.runtime.security == "mtls" and cfg.runtime.report_denied:  # before zenoh.open: it sets zenoh's logging
        from humanpt.runtime.security import DenialReporter, DenialWatch

        reporter = DenialReporter(cfg.runtime.cell)
        watch = DenialWatch(reporter)
        watch.start()
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as e:
        print(f"humanpt router: cannot listen on {', '.join(listen)}: {e}", file=sys.stderr)
        if watch is not None:
            watch.stop()
        return 1
    if reporter is not None:
        reporter.attach(session)
    with session:
        if cfg.runtime.security == "mtls":
            from humanpt.runtime import security

            listen = tuple(security.tls_endpoint(e) for e in listen)
        print(f"humanpt router: listening on {', '.join(listen)} (zid {session.zid()}); Ctrl-C stops",
              flush=True)
        if cfg.runtime.security == "mtls":
            certs = security.identities(security.pki_dir_of(cfg.runtime))
            print(f"humanpt router: mTLS (CA and certificates in {security.pki_dir_of(cfg.runtime)}); access "
                  f"control default deny, allowing {', '.join(c.name for c in certs if c.role not in ('ca', 'router'))}"
                  f" (`humanpt pki acl` prints it)", flush=True)
        while not stop.wait(0.5):
            pass
        if reporter is not None:
            reporter.close()
    if watch is not None:
        watch.stop()
    print("humanpt router: stopped", flush=True)
    return 0


def run_component(args) -> int:
    from humanpt.runtime.live import LiveShell

    cfg = load_cfg(args)
    name = args.component
    cls = core_class(name)
    core = cls.create(cfg.component(name, cls.config_type), cfg.rig())
    run_dir = Path(args.run_dir) if args.run_dir else Path(cfg.runtime.run_dir) / f"{run_stamp()}-{name}"
    try:
        adapters = adapters_for(name, core.config, run_dir=run_dir, rig=core.rig)
    except Exception as e:  # a serial port that does not open, say: name it and stop
        print(f"humanpt {name}: {e}", file=sys.stderr)
        return 1
    shell = LiveShell(core, cfg.runtime, run_dir=run_dir, adapters=adapters, record=cfg.record)
    stop_on_signals(shell.stop)
    if args.duration:
        threading.Timer(args.duration, shell.stop.set).start()
    try:
        counters = shell.run()
    except Exception as e:  # zenoh.ZError and friends: say it plainly
        print(f"humanpt {name}: {e}", file=sys.stderr)
        return 1
    print(f"humanpt {name}: stopped; consumed {counters.consumed}, produced {counters.produced}, "
          f"dropped {counters.dropped}, core errors {counters.core_errors}; "
          f"{shell.recorder.summary() if shell.recorder else 'recording off'}", file=sys.stderr, flush=True)
    return 0


def _endpoint_addr(ep: str) -> tuple[str, int] | None:
    if not ep.startswith(("tcp/", "tls/")):
        return None
    host, _, port = ep[4:].rpartition(":")
    host = host.strip("[]")
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    return host, int(port)


def _wait_port(addr: tuple[str, int], timeout_s: float, proc: subprocess.Popen) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        try:
            with socket.create_connection(addr, timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False


def _passthrough(args) -> list[str]:
    out = []
    if getattr(args, "config", None):
        out += ["--config", args.config]
    if getattr(args, "cell", None):
        out += ["--cell", args.cell]
    for ep in getattr(args, "connect", None) or []:
        out += ["--connect", ep]
    return out


def resolve_profile(args, cfg: cfgmod.ConfigFile) -> tuple[str, bool, tuple[str, ...]]:
    """(label, start a router?, components) of ``up``'s arguments."""
    if args.components:
        comps = tuple(c.strip() for c in args.components.split(",") if c.strip())
        label, with_router = "custom", True
    elif args.profile:
        if args.profile in cfg.profiles:
            label, with_router, comps = args.profile, True, cfg.profiles[args.profile]
        elif args.profile in PROFILES:
            prof = PROFILES[args.profile]
            label, with_router, comps = args.profile, prof["router"], tuple(prof["components"])
        else:
            raise cfgmod.ConfigError(f"unknown profile {args.profile!r}; known: "
                                     f"{', '.join(sorted(set(PROFILES) | set(cfg.profiles)))}")
    else:
        prof = PROFILES["loop"]
        label, with_router, comps = "loop", prof["router"], tuple(prof["components"])
    missing = [c for c in comps if c not in COMPONENTS]
    if missing:
        raise UnknownComponentError(f"profile {label!r} needs {', '.join(missing)}, not available in this "
                                    f"version (available: {', '.join(sorted(COMPONENTS))})")
    if args.no_router:
        with_router = False
    return label, with_router, comps


def up(args) -> int:
    cfg = load_cfg(args)
    label, with_router, comps = resolve_profile(args, cfg)
    run_dir = Path(args.run_dir) if args.run_dir else Path(cfg.runtime.run_dir) / f"{run_stamp()}-{label}"
    run_dir.mkdir(parents=True, exist_ok=True)
    print(f"humanpt up: profile {label}: {'router, ' if with_router else ''}{', '.join(comps)}", flush=True)
    print(f"humanpt up: recording to {run_dir}/", flush=True)
    stop = stop_on_signals()
    base = [sys.executable, "-m", "humanpt.cli.main"]
    children: list[tuple[str, subprocess.Popen]] = []
    failed: list[str] = []
    try:
        if with_router:
            proc = subprocess.Popen(base + ["router"] + _passthrough(args))
            children.append(("router", proc))
            addr = _endpoint_addr(cfg.runtime.listen[0])
            if addr and not _wait_port(addr, 10.0, proc):
                failed.append("router (did not start listening)")
                return 1
        for name in comps:
            proc = subprocess.Popen(base + [name, "--run-dir", str(run_dir)] + _passthrough(args))
            children.append((name, proc))
        deadline = time.monotonic() + args.duration if args.duration else None
        while not stop.wait(0.2):
            if deadline and time.monotonic() >= deadline:
                break
            dead = [(n, p.returncode) for n, p in children if p.poll() is not None]
            if dead:
                failed += [f"{n} (exit {rc})" for n, rc in dead]
                break
    finally:
        # Components first, the router last, so components leave cleanly.
        for _, p in reversed(children):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        if failed:
            print(f"humanpt up: stopped because a child died: {', '.join(failed)}", file=sys.stderr, flush=True)
    print(f"humanpt up: stopped; recordings in {run_dir}/", flush=True)
    from humanpt.runtime.recording import losses_lines

    for line in losses_lines(run_dir):  # a component's recording lost messages to a write error
        print(f"humanpt up: {line}", flush=True)
    return 1 if failed else 0


# -- inspection ----------------------------------------------------------------------------
def _describe(key: str, payload: bytes, full: bool = False) -> tuple[str, str]:
    from google.protobuf import text_format

    try:
        _, short = topics.short_from_key(key)
        cls = topics.message_type(short)
    except topics.UnknownTopicError:
        return "?", f"<{len(payload)} bytes, not in the topic table>"
    msg = cls()
    try:
        msg.ParseFromString(payload)
    except Exception as e:  # noqa: BLE001
        return cls.DESCRIPTOR.full_name, f"<{len(payload)} bytes that do not decode: {e}>"
    if not full and cls.DESCRIPTOR.full_name == "foxglove.RawImage":
        msg = type(msg)(timestamp=msg.timestamp, frame_id=msg.frame_id, width=msg.width, height=msg.height,
                        encoding=msg.encoding, step=msg.step)
        return cls.DESCRIPTOR.full_name, text_format.MessageToString(msg) + f"data: <{len(payload)} bytes>\n"
    return cls.DESCRIPTOR.full_name, text_format.MessageToString(msg)


def topics_cmd_table() -> int:
    print(f"{'key (humanpt/<cell>/...)':34s} {'type':26s} {'publisher':14s} description")
    for t in topics.TOPICS.values():
        print(f"{t.short:34s} {t.type.DESCRIPTOR.full_name:26s} {t.publisher:14s} {t.doc}")
    print(f"local inputs (never on the bus): {', '.join(topics.LOCAL_TOPICS)}")
    return 0


def topics_cmd(args) -> int:
    if args.table:
        return topics_cmd_table()
    cfg = load_cfg(args)
    cell = cfg.runtime.cell
    stats: dict[str, list] = defaultdict(lambda: [0, 0, None, None])  # count, bytes, first, last
    lock = threading.Lock()

    def cb(sample):
        now = time.monotonic()
        with lock:
            s = stats[str(sample.key_expr)]
            s[0] += 1
            s[1] += len(sample.payload)
            s[2] = s[2] or now
            s[3] = now

    with open_tool_session(cfg.runtime) as session:
        sub = session.declare_subscriber(f"{topics.KEY_PREFIX}/{cell}/**", cb)
        alive = sorted(str(r.ok.key_expr).rsplit("/", 1)[-1]
                       for r in session.liveliness().get(liveliness_key(cell, "*")) if r.ok is not None)
        time.sleep(args.duration)
        sub.undeclare()
    print(f"cell {cell}: components up: {', '.join(alive) or 'none'}")
    if not stats:
        print(f"no messages in {args.duration:g} s")
        return 0
    print(f"{'key':44s} {'type':26s} {'count':>7s} {'rate Hz':>8s} {'avg bytes':>10s}")
    for key in sorted(stats):
        count, nbytes, first, last = stats[key]
        rate = (count - 1) / (last - first) if count > 1 and last > first else 0.0
        try:
            tname = topics.message_type(topics.short_from_key(key)[1]).DESCRIPTOR.full_name
        except topics.UnknownTopicError:
            tname = "?"
        print(f"{key:44s} {tname:26s} {count:7d} {rate:8.1f} {nbytes / count:10.0f}")
    return 0


def _full_key(key: str, cell: str) -> str:
    return key if key.startswith(topics.KEY_PREFIX + "/") else f"{topics.KEY_PREFIX}/{cell}/{key}"


def echo(args) -> int:
    import queue as _queue

    cfg = load_cfg(args)
    key = _full_key(args.key, cfg.runtime.cell)
    short = key.split("/", 2)[2] if key.count("/") >= 2 else key
    if "*" not in key and short not in topics.TOPICS:
        near = sorted(t for t in topics.TOPICS if short.split("/")[0] in t) or sorted(topics.TOPICS)
        raise ValueError(f"no topic {short!r} in this version (wildcards like '*/events' are fine); "
                         f"known: {', '.join(near)}")
    fields = list(args.field or [])
    if args.csv and not fields:
        raise ValueError("--csv prints fields: name them with --field (e.g. --field header.stamp_ns)")
    if fields and "*" not in key:  # a field the topic's type does not have: said before listening
        from humanpt.schemas.convert import message_field

        for f in fields:
            _check_field_path(topics.message_type(short)(), f, message_field)
    writer = None
    if args.csv:
        import csv

        writer = csv.writer(sys.stdout)
        writer.writerow(["stamp_ns", "key", *fields])
    q: _queue.Queue = _queue.Queue()
    stop = stop_on_signals()
    n = 0
    with open_tool_session(cfg.runtime) as session:
        sub = session.declare_subscriber(key, lambda s: q.put((str(s.key_expr), s.payload.to_bytes())))
        deadline = time.monotonic() + args.duration if args.duration else None
        while not stop.is_set() and (args.count is None or n < args.count):
            if deadline and time.monotonic() >= deadline:
                break
            try:
                k, payload = q.get(timeout=0.1)
            except _queue.Empty:
                continue
            if fields:
                row = _field_row(k, payload, fields)
                if args.csv:
                    writer.writerow(row)
                else:
                    print(f"{row[0]} {row[1]} " + " ".join(f"{f}={v}" for f, v in zip(fields, row[2:], strict=True)))
                sys.stdout.flush()
            else:
                tname, text = _describe(k, payload, args.full)
                print(f"--- {k} ({tname})\n{text}", end="", flush=True)
            n += 1
        sub.undeclare()
    return 0


def _check_field_path(msg, path: str, message_field) -> None:
    """ValueError when ``path`` names no field of ``msg``'s type (an index beyond an empty
    list is fine: a message may have entries)."""
    from humanpt.schemas.convert import MessageError

    try:
        message_field(msg, path)
    except MessageError as e:
        if "entries, no [" not in str(e):
            raise ValueError(str(e)) from None


def _field_row(key: str, payload: bytes, fields: list[str]) -> list:
    """[stamp ns, key, value of each field] of one message (``message_field``); a message
    that does not decode, or lacks a field, raises ValueError naming it."""
    from humanpt.schemas.convert import message_field, message_stamp_ns

    try:
        _, short = topics.short_from_key(key)
        msg = topics.message_type(short).FromString(payload)
    except Exception as e:  # noqa: BLE001 - unknown topic or undecodable bytes: one message
        raise ValueError(f"{key}: cannot decode: {e}") from None
    return [message_stamp_ns(msg), key, *(message_field(msg, f) for f in fields)]


def _parse_assignment(a: str) -> tuple[str, object]:
    key, eq, value = a.partition("=")
    if not eq or not key:
        raise cfgmod.ConfigError(f"{a!r} is not KEY=VALUE")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def param(args) -> int:
    cfg = load_cfg(args)
    sets = dict(_parse_assignment(a) for a in args.assignments)
    with open_tool_session(cfg.runtime) as session:
        replies = list(session.get(params_key(cfg.runtime.cell, args.component),
                                   payload=json.dumps({"set": sets}), timeout=args.timeout))
    bodies = [json.loads(r.ok.payload.to_bytes()) for r in replies if r.ok is not None]
    if not bodies:
        rt = cfg.runtime
        why = (f"; under mTLS only an operator's certificate may query parameters, this one is "
               f"{rt.identity or 'tool'!r} (--as NAME)" if rt.security == "mtls" else "")
        print(f"humanpt param: no component {args.component!r} answered in cell {rt.cell} "
              f"within {args.timeout:g} s (is it running?{why})", file=sys.stderr)
        return 1
    body = bodies[0]
    for r in body.get("results", []):
        print(f"{'set' if r['ok'] else 'REJECTED'}: {r['text']}")
    print(json.dumps({"params": body.get("params"), "counters": body.get("counters")}, indent=2))
    return 0 if body.get("ok", False) else 1


# -- recordings ----------------------------------------------------------------------------
def replay(args) -> int:
    from humanpt.runtime.recording import RecordingError
    from humanpt.runtime.replay import (
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
            res = do_replay(f)
        except (RecordingError, cfgmod.ConfigError) as e:  # say why, go on with the other files
            print(f"humanpt replay: cannot replay {f}: {e}", file=sys.stderr, flush=True)
            codes.append(EXIT_UNREADABLE)
            continue
        print(res.report(), flush=True)
        codes.append(res.exit_code)
    # The worst verdict: unreadable, then a mismatch, then nothing compared.
    for code in (EXIT_UNREADABLE, EXIT_MISMATCH, EXIT_NOTHING_COMPARED):
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
            print(f"  {direction:3s} {topic:32s} {t.count:8d} msgs {t.rate_hz:8.1f} Hz{missed}")
        for note in f.notes:
            print(f"  note: {note}")
        bad |= bool(f.missing_inputs or f.notes)
    from humanpt.runtime.recording import losses_lines

    lost = losses_lines(args.run_dir)  # what a full disk (or another write error) cost
    for line in lost:
        print(line)
    total = sum(f.missing_inputs for f in infos)
    print(f"humanpt runs info: {len(infos)} recordings; inputs missed: {total}; "
          f"recordings with write losses: {len(lost)}")
    return 1 if bad or lost else 0


def runs_merge(args) -> int:
    from mcap.writer import Writer
    from mcap_protobuf.schema import register_schema

    from humanpt.runtime.recording import OUT, RecordingError, merge_entries, read_metadata

    run_dir = Path(args.run_dir)
    files = sorted(p for p in run_dir.glob("*.mcap")) if run_dir.is_dir() else []
    if not files:
        raise RecordingError(f"{run_dir}: no .mcap recordings here")
    out = Path(args.out)
    if out.resolve().parent == run_dir.resolve() and out.suffix == ".mcap":
        raise RecordingError(f"{out}: write the merged file outside the run directory")
    notes: list[str] = []
    where: dict[Path, tuple[str, str]] = {}  # file -> (cell, component)
    for f in files:
        try:
            meta, _ = read_metadata(f)
        except RecordingError:
            meta = {}  # merge_entries says why it leaves it out
        where[f] = (meta.get("cell", "cell0"), meta.get("component", f.stem.split(".")[0]))
    n = 0
    with open(out, "wb") as fh:
        w = Writer(fh)
        w.start(profile="humanpt", library="humanpt runs merge")
        schema_ids: dict[str, int] = {}
        channels: dict[str, int] = {}
        for t_ns, f, e in merge_entries(files, notes, keep=lambda e: e.direction == OUT):
            cell, component = where[f]
            # Bus topics on their key; a component's local outputs (serial bytes...) apart.
            key = (f"{topics.KEY_PREFIX}/{cell}/{e.topic}" if "/" in e.topic
                   else f"{topics.KEY_PREFIX}/{cell}/{component}/local/{e.topic}")
            if key not in channels:
                try:
                    cls = topics.message_type(e.topic)
                except topics.UnknownTopicError:
                    continue  # a topic this version does not know: nothing to decode it with
                name = cls.DESCRIPTOR.full_name
                if name not in schema_ids:
                    schema_ids[name] = register_schema(w, cls)
                channels[key] = w.register_channel(topic=key, message_encoding="protobuf",
                                                   schema_id=schema_ids[name])
            w.add_message(channel_id=channels[key], log_time=t_ns, data=e.data, publish_time=t_ns, sequence=n)
            n += 1
        w.finish()
    for note in notes:
        print(f"humanpt runs merge: warning: {note}", file=sys.stderr)
    print(f"humanpt runs merge: {n} messages from {len(files)} recordings on {len(channels)} topics -> {out}")
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
    if args.check:
        print(f"{cfg.source}: OK; rig {rig_source}: OK ({rig.methods()})")
        return 0
    print(f"# effective configuration ({cfg.source}; defaults where it is silent)")
    print(f"# rig: {rig_source} ({rig.methods()}); `humanpt rig show` prints it")
    sections = {"runtime": (cfg.runtime, cfgmod.RuntimeConfig), "record": (cfg.record, cfgmod.RecordConfig)}
    for name in sorted(COMPONENTS):
        cls = core_class(name).config_type
        sections[name] = (cfg.component(name, cls), cls)
    for name, (value, cls) in sections.items():
        print(f"\n[{name}]")
        notes = cfgmod.field_notes(cls)
        for k, v in cfgmod.to_table(value).items():
            note = f"  # {notes[k]}" if k in notes else ""
            print(f"{k} = {json.dumps(v)}{note}")
    return 0


def path_cmd(args) -> int:
    from humanpt.controller import pathfile

    out_path = Path(args.output)
    if out_path.exists() and out_path.resolve() == Path(args.input).resolve():
        raise ValueError(f"{args.output}: is the input; write the result to another file")
    if out_path.exists() and not args.overwrite:
        raise ValueError(f"{args.output}: exists; give --overwrite to replace it")
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
    Path(args.output).write_text(pathfile.to_val2(p.points(which), args.name, args.speed))
    print(f"humanpt path val: {len(p)} points -> {args.output}")
    return 0

