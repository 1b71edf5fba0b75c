"""The one way a component's process is started (issue 30): ``python -m humanpt.runtime.run
NAME [options]`` (:mod:`humanpt.runtime.run`), NAME a component of the registry or
``router``.  ``humanpt up`` (:mod:`humanpt.runtime.supervisor`), the live twin, the benches
and re-recording all build their command lines here and start them with :func:`spawn`;
nothing starts the ``humanpt`` command line to get work done.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

ENTRY = "humanpt.runtime.run"  # the module every component process runs
ROUTER = "router"  # the name that starts the cell's Zenoh router instead of a component


def argv(name: str, *, config: str | Path | None = None, run_dir: str | Path | None = None,
         cell: str | None = None, connect: Sequence[str] = (), listen: Sequence[str] = (),
         identity: str | None = None, duration_s: float | None = None) -> list[str]:
    """The command line of component ``name``'s process (or the router's, ``name="router"``):
    ``config`` the TOML file, ``run_dir`` where it records, ``cell``/``connect``/``identity``
    override the file's ``[runtime]``, ``listen`` the router's endpoints, ``duration_s`` when
    it stops by itself."""
    out = [sys.executable, "-m", ENTRY, name]
    if config is not None:
        out += ["--config", str(config)]
    if cell:
        out += ["--cell", cell]
    for ep in connect:
        out += ["--connect", ep]
    if identity:
        out += ["--as", identity]
    if name == ROUTER:
        for ep in listen:
            out += ["--listen", ep]
    else:
        if run_dir is not None:
            out += ["--run-dir", str(run_dir)]
        if duration_s:
            out += ["--duration", repr(float(duration_s))]
    return out


def spawn(name: str, *, stdout=None, stderr=None, **options) -> subprocess.Popen:
    """Start component ``name``'s process (:func:`argv`'s ``options``); ``stdout``/``stderr``
    as :class:`subprocess.Popen` takes them (default: this process's)."""
    return subprocess.Popen(argv(name, **options), stdout=stdout, stderr=stderr)


def endpoint_addr(endpoint: str) -> tuple[str, int] | None:
    """(host, port) to reach a ``tcp/``/``tls/`` listen endpoint on this machine (a wildcard
    host is loopback); None for other transports."""
    if not endpoint.startswith(("tcp/", "tls/")):
        return None
    host, _, port = endpoint[4:].rpartition(":")
    host = host.strip("[]")
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    return host, int(port)


def wait_listening(host: str, port: int, timeout_s: float, alive: Callable[[], bool] = lambda: True,
                   stop: threading.Event | None = None) -> str:
    """Wait until something accepts TCP connections on ``host:port`` (a router that
    finished starting); "" then, else why not: the process died (``alive()`` false), ``stop``
    was set, or ``timeout_s`` passed."""
    deadline = time.monotonic() + timeout_s
    pause = stop or threading.Event()
    why = "nothing listened"
    while time.monotonic() < deadline:
        if not alive():
            return f"it exited before listening on {host}:{port}"
        if stop is not None and stop.is_set():
            return "stopped"
        try:
            with socket.create_connection((host, port), timeout=1.0):
                return ""
        except OSError as e:
            why = f"nothing listens on {host}:{port} ({e.strerror or e})"
        pause.wait(0.05)  # a port being opened tells no one: try again shortly
    return f"{why} after {timeout_s:g} s"


def stop_all(procs: Iterable[subprocess.Popen], timeout_s: float = 10.0, together: bool = True) -> None:
    """SIGTERM every process still running, last started first (components before their
    router, so they leave cleanly), wait up to ``timeout_s`` for each and kill what remains.
    ``together``: signal them all, then wait; else one at a time, each gone before the next."""
    procs = list(reversed(list(procs)))

    def wait(p: subprocess.Popen) -> None:
        try:
            p.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()

    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
        if not together:
            wait(p)
    for p in procs:
        wait(p)
