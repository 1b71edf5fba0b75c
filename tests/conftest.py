"""Shared fixtures: a real Zenoh router on a free loopback port, config files, CLI runs."""

from __future__ import annotations

import logging
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from humanpt.runtime.bus import free_tcp_port

ROOT = Path(__file__).resolve().parents[1]


free_port = free_tcp_port  # one helper for the product and the tests


def write_config(path: Path, port: int, extra: str = "", cell: str = "test") -> Path:
    path.write_text(
        f'[runtime]\ncell = "{cell}"\nconnect = ["tcp/127.0.0.1:{port}"]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
        f'run_dir = "{path.parent / "runs"}"\nconnect_timeout_s = 5.0\n{extra}')
    return path


def humanpt_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "humanpt.cli.main", *args]


def run_cli(*args: str, timeout: float = 60, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(humanpt_cmd(*args), capture_output=True, text=True, timeout=timeout, cwd=kw.pop("cwd", ROOT),
                          **kw)


def wait_port(port: int, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise TimeoutError(f"nothing listens on port {port}")


def wait_for(pred, timeout: float, what: str, poll_s: float = 0.02) -> None:
    """Wait until ``pred()`` is true (polled every ``poll_s``), else fail naming ``what``."""
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(poll_s)


def wait_matching(publisher, timeout: float = 15.0) -> None:
    """Wait until a subscriber somewhere matches a Zenoh ``publisher``'s key expression, so
    that what it puts next is delivered (rather than sleeping until the peer is up)."""
    wait_for(lambda: publisher.matching_status.matching, timeout,
             f"a subscriber to {publisher.key_expr}")


class Procs:
    """Child processes that are stopped (TERM, then KILL) at the end of a test."""

    def __init__(self):
        self.procs: list[subprocess.Popen] = []

    def start(self, *args: str, **kw) -> subprocess.Popen:
        p = subprocess.Popen(humanpt_cmd(*args), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             cwd=kw.pop("cwd", ROOT), **kw)
        self.procs.append(p)
        return p

    def stop(self, p: subprocess.Popen, timeout: float = 15.0) -> str:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
        try:
            out, _ = p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            out, _ = p.communicate()
        return out or ""

    def stop_all(self):
        for p in reversed(self.procs):
            self.stop(p)


@pytest.fixture
def procs():
    ps = Procs()
    yield ps
    ps.stop_all()


@pytest.fixture
def router(tmp_path, procs):
    """A real router (``humanpt router``) on a free port; yields (port, config path)."""
    port = free_port()
    cfg = write_config(tmp_path / "humanpt.toml", port)
    procs.start("router", "--config", str(cfg))
    wait_port(port)
    return port, cfg


def zenoh_client(port: int):
    import zenoh

    from humanpt.runtime.bus import zenoh_config
    from humanpt.runtime.config import RuntimeConfig

    rt = RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",))
    return zenoh.open(zenoh_config(rt))


os.environ.setdefault("PYTHONUNBUFFERED", "1")


# -- process-wide settings ------------------------------------------------------------------
# A test must leave the interpreter as it found it: the GIL switch interval and the logging
# set-up are process-wide, and a test that changes them changes the timing and the output of
# every test after it. (glibc's allocator tuning cannot be read back: tests that may apply
# it run it in a subprocess, or through ``cli_main`` below, which leaves it out.)


def _process_settings() -> dict:
    """The process-wide settings a test must not leave changed."""

    def ours(handlers):  # pytest's own capture handlers change from phase to phase
        return [h for h in handlers if not type(h).__module__.startswith("_pytest")]

    root = logging.getLogger()
    loggers = {name: lg.level for name, lg in logging.root.manager.loggerDict.items()
               if name.startswith("humanpt") and isinstance(lg, logging.Logger)}
    return {"switch interval (s)": sys.getswitchinterval(), "root logger level": root.level,
            "root logger handlers": ours(root.handlers), "humanpt logger levels": loggers}


@pytest.fixture(autouse=True)
def _process_settings_unchanged():
    """Fails the test (at teardown) that leaves a process-wide setting changed."""
    before = _process_settings()
    yield
    after = _process_settings()
    changed = {k: (before[k], after[k]) for k in before
               if before[k] != after[k] and not (k == "humanpt logger levels"
                                                 and _levels_kept(before[k], after[k]))}
    if changed:
        pytest.fail(f"the test left process-wide settings changed (before, after): {changed}")


def _levels_kept(before: dict, after: dict) -> bool:
    """Loggers created by the test (level NOTSET) are no change."""
    return all(after.get(n) == lvl for n, lvl in before.items()) and all(
        lvl == logging.NOTSET for n, lvl in after.items() if n not in before)


@pytest.fixture
def cli_main(monkeypatch):
    """``humanpt.cli.main.main`` in this process, with the process left as it was: main
    sets the switch interval and configures logging for a CLI process; they are restored
    afterwards, and the allocator tuning (which cannot be undone) is skipped."""
    from humanpt.cli.main import main
    from humanpt.runtime import tuning

    monkeypatch.setattr(tuning, "tune_allocator", lambda: False)
    root = logging.getLogger()
    interval, level, handlers = sys.getswitchinterval(), root.level, list(root.handlers)
    try:
        yield main
    finally:
        sys.setswitchinterval(interval)
        root.setLevel(level)
        for h in root.handlers:
            if h not in handlers:
                root.removeHandler(h)
