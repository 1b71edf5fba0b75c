"""Run one component, or the cell's router, in this process: the entry point every component
process is started through (:mod:`humanpt.runtime.launcher`)::

    python -m humanpt.runtime.run NAME [--config FILE] [--cell C] [--connect EP]... [--as ID]
                                       [--run-dir DIR] [--duration S] [--listen EP]...

NAME is a component of the registry (test-only ones such as ``pinger`` included) or
``router``.  From Python: :func:`load_config`, :func:`run_component`, :func:`run_router`
(the argument parsing is :func:`main`'s, for ``__main__`` only).
"""

from __future__ import annotations

import dataclasses
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from humanpt.runtime import config as cfgmod

Say = Callable[[str], None]


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _stdout(line: str) -> None:
    print(line, flush=True)


def load_config(path: str | Path | None, *, cell: str | None = None, connect: Sequence[str] | None = None,
                identity: str | None = None) -> cfgmod.ConfigFile:
    """The config file ``path`` (built-in defaults for None), validated, with ``cell``,
    ``connect`` and ``identity`` overriding its ``[runtime]``; the rig it names is read (a
    missing or bad rig file fails here, before anything starts)."""
    from humanpt.runtime.registry import config_types

    cfg = cfgmod.load(path, config_types())
    for note in cfg.notes:  # a retired key kept equal to what replaced it (runtime/cycle.py)
        _stderr(f"note: {note}")
    changes: dict[str, object] = {}
    if cell:
        changes["cell"] = cell
    if connect:
        changes["connect"] = tuple(connect)
    if identity:
        changes["identity"] = identity
    if changes:
        try:
            rt = dataclasses.replace(cfg.runtime, **changes)
        except ValueError as e:
            raise cfgmod.ConfigError(f"command line: {e}") from e
        cfg = dataclasses.replace(cfg, runtime=rt)
    cfg.rig()
    return cfg


def stop_on_signals(extra: threading.Event | None = None) -> threading.Event:
    """An Event set by SIGINT or SIGTERM (``extra`` if given: it is set too)."""
    stop = extra or threading.Event()

    def handler(signum, frame):
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def run_stamp() -> str:
    """The time part of a default run directory's name."""
    return time.strftime("%Y%m%d-%H%M%S")


def run_router(cfg: cfgmod.ConfigFile, listen: Sequence[str] | None = None, stop: threading.Event | None = None,
               say: Say = _stdout, complain: Say = _stderr) -> int:
    """Run the cell's Zenoh router until ``stop`` is set (default: SIGINT/SIGTERM) on
    ``listen`` (default ``[runtime] listen``); 0, or 1 when it cannot listen."""
    import zenoh

    from humanpt.runtime.bus import zenoh_config

    listen = tuple(listen) if listen else cfg.runtime.listen
    conf = zenoh_config(cfg.runtime, mode="router", listen=listen, connect=())
    stop = stop or stop_on_signals()
    watch = reporter = None
    if cfg.runtime.security == "mtls" and cfg.runtime.report_denied:  # before zenoh.open: it sets zenoh's logging
        from humanpt.runtime.security import DenialReporter, DenialWatch

        reporter = DenialReporter(cfg.runtime.cell)
        watch = DenialWatch(reporter)
        watch.start()
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as e:
        complain(f"humanpt router: cannot listen on {', '.join(listen)}: {e}")
        if watch is not None:
            watch.stop()
        return 1
    if reporter is not None:
        reporter.attach(session)
    with session:
        if cfg.runtime.security == "mtls":
            from humanpt.runtime import security

            listen = tuple(security.tls_endpoint(e) for e in listen)
        say(f"humanpt router: listening on {', '.join(listen)} (zid {session.zid()}); Ctrl-C stops")
        if cfg.runtime.security == "mtls":
            certs = security.identities(security.pki_dir_of(cfg.runtime))
            say(f"humanpt router: mTLS (CA and certificates in {security.pki_dir_of(cfg.runtime)}); access "
                f"control default deny, allowing {', '.join(c.name for c in certs if c.role not in ('ca', 'router'))}"
                f" (`humanpt pki acl` prints it)")
        while not stop.wait(0.5):
            pass
        if reporter is not None:
            reporter.close()
    if watch is not None:
        watch.stop()
    say("humanpt router: stopped")
    return 0


def run_component(cfg: cfgmod.ConfigFile, name: str, run_dir: str | Path | None = None,
                  duration_s: float | None = None, stop: threading.Event | None = None,
                  say: Say = _stderr) -> int:
    """Run component ``name`` alone as a client of the router, recording into ``run_dir``
    (default ``[runtime] run_dir/<time>-<name>``), until ``stop`` (default: SIGINT/SIGTERM)
    or ``duration_s``; 0, or 1 when it could not run (its adapters did not open, the bus
    failed)."""
    from humanpt.runtime.live import LiveShell
    from humanpt.runtime.registry import adapters_for, core_class
    from humanpt.runtime.tuning import tune_realtime

    name = cfgmod.current_name(name)
    cls = core_class(name)
    core = cls.create(cfg.component(name, cls.config_type), cfg.rig())
    run_dir = Path(run_dir) if run_dir else Path(cfg.runtime.run_dir) / f"{run_stamp()}-{name}"
    try:
        adapters = adapters_for(name, core.config, run_dir=run_dir, rig=core.rig, config_file=cfg)
    except Exception as e:  # a serial port that does not open, say: name it and stop
        say(f"humanpt {name}: {e}")
        return 1
    shell = LiveShell(core, cfg.runtime, run_dir=run_dir, adapters=adapters, record=cfg.record)
    realtime = tune_realtime(core, cfg.runtime)
    if realtime:
        say(f"humanpt {name}: on a robot link's cycle: {realtime}")
    if stop is None:
        stop_on_signals(shell.stop)
    else:
        threading.Thread(target=lambda: (stop.wait(), shell.stop.set()), daemon=True).start()
    if duration_s:
        timer = threading.Timer(duration_s, shell.stop.set)
        timer.daemon = True
        timer.start()
    try:
        counters = shell.run()
    except Exception as e:  # zenoh.ZError and friends: say it plainly
        say(f"humanpt {name}: {e}")
        return 1
    say(f"humanpt {name}: stopped; consumed {counters.consumed}, produced {counters.produced}, "
        f"dropped {counters.dropped}, core errors {counters.core_errors}; "
        f"{shell.recorder.summary() if shell.recorder else 'recording off'}")
    return 0


def run(name: str, cfg: cfgmod.ConfigFile, *, listen: Sequence[str] = (), run_dir: str | Path | None = None,
        duration_s: float | None = None) -> int:
    """The router (``name="router"``) or component ``name``, as its process runs it."""
    from humanpt.runtime.launcher import ROUTER

    if name == ROUTER:
        return run_router(cfg, listen)
    return run_component(cfg, name, run_dir, duration_s)


def main(argv: list[str] | None = None) -> int:
    """``python -m humanpt.runtime.run NAME [options]`` (see the module's doc)."""
    import argparse
    import logging

    from humanpt.runtime.recording import RecordingError
    from humanpt.runtime.registry import UnknownComponentError
    from humanpt.runtime.tuning import tune_process

    ap = argparse.ArgumentParser(prog="python -m humanpt.runtime.run",
                                 description="Run one component (or the router) of a humanpt cell.")
    ap.add_argument("name", help="a component's name, or router")
    ap.add_argument("--config", "-c")
    ap.add_argument("--cell")
    ap.add_argument("--connect", action="append")
    ap.add_argument("--as", dest="identity")
    ap.add_argument("--listen", action="append", default=[])
    ap.add_argument("--run-dir")
    ap.add_argument("--duration", type=float)
    ap.add_argument("-v", "--verbose", action="count", default=0)
    a = ap.parse_args(argv)
    level = logging.WARNING - 10 * min(a.verbose, 2) if a.verbose else logging.INFO
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s: %(message)s", stream=sys.stderr)
    tune_process()
    try:
        cfg = load_config(a.config, cell=a.cell, connect=a.connect, identity=a.identity)
        return run(a.name, cfg, listen=a.listen, run_dir=a.run_dir, duration_s=a.duration)
    except (cfgmod.ConfigError, RecordingError, UnknownComponentError, FileNotFoundError, ValueError) as e:
        print(f"humanpt {a.name}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
