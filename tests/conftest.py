"""Shared fixtures: a real Zenoh router on a free loopback port, config files, CLI runs."""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
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


# A command run by a small parent of its own (run_measured): a child forked from a large
# pytest process starts with that process's pages, and its peak RSS would count them (922 MB
# and 1787 MB seen in the whole suite for commands that peak at about 100 MB).
_MEASURE = """
import json, resource, subprocess, sys
p = subprocess.run(sys.argv[1:], stdin=subprocess.DEVNULL, capture_output=True)
print(json.dumps({"code": p.returncode, "out": p.stdout.decode(), "err": p.stderr.decode(),
                  "rss_kb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}))
"""


def run_measured(*args: str, timeout: float = 300) -> tuple[int, str, str, int]:
    """(exit status, stdout, stderr, peak RSS in kB) of a humanpt command, its own."""
    r = subprocess.run([sys.executable, "-c", _MEASURE, *humanpt_cmd(*args)], capture_output=True, text=True,
                       cwd=ROOT, timeout=timeout)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    return got["code"], got["out"], got["err"], got["rss_kb"]


def run_cli(*args: str, timeout: float = 60, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(humanpt_cmd(*args), capture_output=True, text=True, timeout=timeout, cwd=kw.pop("cwd", ROOT),
                          **kw)


def wait_port(port: int, timeout: float = 60.0, proc: subprocess.Popen | None = None) -> None:
    """Wait until something listens on ``port`` (``timeout`` only bounds a hang: a loaded
    machine took over 15 s to start a router); fails at once if ``proc`` exits."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"the process for port {port} exited ({proc.returncode}) before it listened")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise TimeoutError(f"nothing listens on port {port} after {timeout:g} s")


def wait_for(pred, timeout: float, what: str, poll_s: float = 0.02) -> None:
    """Wait until ``pred()`` is true (polled every ``poll_s``), else fail naming ``what``."""
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(poll_s)


def wait_matching(publisher, timeout: float = 60.0) -> None:
    """Wait until a subscriber somewhere matches a Zenoh ``publisher``'s key expression, so
    that what it puts next is delivered (rather than sleeping until the peer is up).
    ``timeout`` only bounds a hang: a loaded machine takes seconds to start a process."""
    wait_for(lambda: publisher.matching_status.matching, timeout,
             f"a subscriber to {publisher.key_expr}")


class Procs:
    """Child processes that are stopped (TERM, then KILL) at the end of a test. A child's
    output (stdout and stderr) goes to a file that :meth:`stop` returns: a pipe nobody reads
    until the end blocks a chatty child once it holds 64 KiB (seen: a router writing a line per
    refused put under a flood stopped routing). ``live=True``: a pipe, for a test that reads
    ``p.stdout`` as the child runs."""

    def __init__(self):
        self.procs: list[subprocess.Popen] = []
        self._out: dict[int, object] = {}

    def start(self, *args: str, live: bool = False, **kw) -> subprocess.Popen:
        import tempfile

        out = subprocess.PIPE if live else tempfile.TemporaryFile("w+", encoding="utf-8", errors="replace")
        p = subprocess.Popen(humanpt_cmd(*args), stdout=out, stderr=subprocess.STDOUT, text=True,
                             cwd=kw.pop("cwd", ROOT), **kw)
        if not live:
            self._out[p.pid] = out
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
        f = self._out.pop(p.pid, None)
        if f is not None:
            f.seek(0)
            out = f.read()
            f.close()
        return out or ""

    def stop_all(self):
        for p in reversed(self.procs):
            self.stop(p)


@pytest.fixture
def procs():
    ps = Procs()
    yield ps
    ps.stop_all()


class InProcessRouter:
    """A real Zenoh router in this process: the product's ``run_router`` (what ``humanpt
    router`` runs) on a thread, from a config file; ``stop()`` ends it. No process: no
    Python start-up and imports (~1.6 s CPU, seconds of wall time on a loaded machine) for a
    test whose subject is not the router's process. (Not for mTLS with denial reports: those
    set Zenoh's logging for the whole process.)"""

    def __init__(self, cfg_path: Path, timeout: float = 60.0):
        from humanpt.runtime.run import load_config, run_router

        cfg = load_config(cfg_path)
        self.port = int(cfg.runtime.listen[0].rsplit(":", 1)[1])
        self.said: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=run_router, args=(cfg,), daemon=True, name="test-router",
                                        kwargs={"stop": self._stop, "say": self.said.append,
                                                "complain": self.said.append})
        self._thread.start()
        deadline = time.monotonic() + timeout
        while True:
            if not self._thread.is_alive():
                raise RuntimeError(f"the router did not start: {self.said}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return
            except OSError:
                assert time.monotonic() < deadline, f"nothing listens on port {self.port} after {timeout:g} s"
                self._stop.wait(0.02)

    def alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=15)


@pytest.fixture(scope="module")
def _module_router(tmp_path_factory):
    """One real router for a test module (in this process: :class:`InProcessRouter`). A
    module's tests run one after the other on one worker (``--dist loadfile``), each
    stopping its processes before the next starts, so they share it (cell ``test``)."""
    r = InProcessRouter(write_config(tmp_path_factory.mktemp("router") / "humanpt.toml", free_port()))
    try:
        yield r
    finally:
        r.stop()


@pytest.fixture
def router(_module_router, tmp_path, procs):
    """A real router on a free port, shared by the tests of a module (cell ``test``: a
    test's processes are stopped, by ``procs``, before the next test starts); returns (port,
    a config path in the test's own directory)."""
    assert _module_router.alive(), f"the module's router stopped: {_module_router.said}"
    return _module_router.port, write_config(tmp_path / "humanpt.toml", _module_router.port)


def zenoh_client(port: int):
    import zenoh

    from humanpt.runtime.bus import zenoh_config
    from humanpt.runtime.config import RuntimeConfig

    rt = RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",))
    return zenoh.open(zenoh_config(rt))


def wait_alive(port: int, *components: str, cell: str = "test", timeout: float = 60.0) -> None:
    """Wait until each of ``components`` has its liveliness token up on the router at
    ``port`` (a Zenoh subscription, no polling): a component declares it last, after its
    subscribers and its params and rig queryables, so ``humanpt param`` reaches it from then
    on. ``timeout`` only bounds a hang (a loaded machine starts a process in seconds)."""
    import queue

    from humanpt.runtime.bus import liveliness_key

    want = {liveliness_key(cell, c): c for c in components}
    seen: queue.Queue = queue.Queue()
    with zenoh_client(port) as s:
        sub = s.liveliness().declare_subscriber(f"humanpt/{cell}/*", lambda smp: seen.put(str(smp.key_expr)),
                                                history=True)
        deadline = time.monotonic() + timeout
        try:
            while want:
                try:
                    want.pop(seen.get(timeout=max(deadline - time.monotonic(), 0.0)), None)
                except queue.Empty:
                    raise AssertionError(f"no liveliness token of {', '.join(want.values())} after {timeout:g} s") \
                        from None
        finally:
            sub.undeclare()


os.environ.setdefault("PYTHONUNBUFFERED", "1")


# -- Hypothesis ------------------------------------------------------------------------------
# Derandomised by default: every run (CI's, a developer's) tries the same examples, so a
# failure seen once is seen again; no example database carries one run into the next.
# HYPOTHESIS_PROFILE=explore draws new examples each run (the seed of a failure is printed).
from hypothesis import settings as _hypothesis_settings  # noqa: E402

_hypothesis_settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
_hypothesis_settings.register_profile("explore", derandomize=False, print_blob=True)
_hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


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


@contextmanager
def in_process_cli():
    """``humanpt.cli.main.main`` in this process, with the process left as it was: main
    sets the switch interval and configures logging for a CLI process; they are restored
    afterwards, and the allocator tuning (which cannot be undone) is skipped. For a fixture
    of module scope (the autouse check below wraps each test, after such a fixture is set
    up, so it cannot see what the fixture leaves changed)."""
    from humanpt.cli.main import main
    from humanpt.runtime import tuning

    root = logging.getLogger()
    interval, level, handlers = sys.getswitchinterval(), root.level, list(root.handlers)
    # Verbs that run until Ctrl-C (echo, topics, ...) install SIGINT/SIGTERM handlers: put
    # pytest's back, or a later Ctrl-C (or xdist's SIGTERM) would only set a stale Event.
    signals = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(tuning, "tune_allocator", lambda: False)
        try:
            yield main
        finally:
            for sig, handler in signals.items():
                signal.signal(sig, handler)
            sys.setswitchinterval(interval)
            root.setLevel(level)
            for h in root.handlers:
                if h not in handlers:
                    root.removeHandler(h)


@pytest.fixture
def cli_main():
    """:func:`in_process_cli` for one test."""
    with in_process_cli() as main:
        yield main


# -- tiers -------------------------------------------------------------------------------------
# Markers (pyproject: --strict-markers): ``live`` tests start processes, routers, ptys, UDP
# sockets or network namespaces; ``twin`` tests run the lock-step twin for seconds; ``root``
# tests need root. ``python -m pytest -m "not live and not twin"`` is the inner loop.
#
# A test is marked here from what it uses: the fixtures in its closure (a fixture of this
# file, or a module's own fixture whose code does one of those things) and the names its
# code and the module's helpers it calls refer to (``run_cli``, ``subprocess``, ``LiveShell``,
# ...). A module whose tests do it some other way says so with ``pytestmark``.

LIVE_FIXTURES = frozenset({"router", "_module_router", "procs"})
# Names that, referred to by a test or by a helper/fixture of its module it calls, start a
# process, a Zenoh session (router or client), a pty or a UDP socket.
LIVE_NAMES = frozenset({"run_cli", "run_measured", "humanpt_cmd", "Procs", "subprocess", "Popen", "zenoh_client", "LiveShell",
                        "InProcessRouter", "wait_alive",
                        "openpty", "pty", "PtyAdapter", "SerialAdapter", "UdpAdapter", "RsiRobotServer", "SOCK_DGRAM", "open_tool_session", "wait_port"})

# Names that run the lock-step twin: a world's clock run forward, or one of the twin's runs
# (a run, an experiment, a calibration or a teach on the twin, the error budget).
TWIN_NAMES = frozenset({"run_for", "run_until", "build_system", "run", "run_world", "run_budget", "run_case",
                        "run_cases", "run_experiment", "run_live", "calibrate_then_teach", "calibrate_camera_on_twin",
                        "calibrate_hand_eye_on_twin", "calibrate_psvs_on_twin", "check_mirrors_on_twin",
                        "calibrate_tip_on_twin"})

TWIN_FLAGS = frozenset({"--twin", "--lockstep"})  # CLI arguments that run the twin


def _twin_names(names: set[str], module_globals: dict) -> bool:
    """Whether ``names`` name a twin run: one of TWIN_NAMES (``run_for``/``run_until``: a
    world's or a Lockstep's clock), or ``run`` when it is humanpt.twin.run's."""
    if names & (TWIN_NAMES - {"run"}):  # a world's clock, or a twin run called by name (teach.calibrate_then_teach)
        return True
    for n in names & {"run"}:
        obj = module_globals.get(n)
        if getattr(obj, "__module__", "").startswith("humanpt.twin"):
            return True
    return False


def _names(code, module_globals: dict, seen: set) -> set[str]:
    """The global names ``code`` (and its nested functions, and the functions of the same
    module it calls, transitively) refers to."""
    if code in seen:
        return set()
    seen.add(code)
    names = set(code.co_names)
    for const in code.co_consts:
        if hasattr(const, "co_names"):
            names |= _names(const, module_globals, seen)
        elif const in TWIN_FLAGS:  # a CLI called with --twin/--lockstep: a twin run
            names.add("run_for")
    for n in list(names):
        obj = module_globals.get(n)
        if callable(obj) and getattr(obj, "__module__", None) == module_globals.get("__name__"):
            fn = getattr(obj, "__wrapped__", obj)
            inner = getattr(fn, "__code__", None)
            if inner is None and isinstance(fn, type):  # a class of the module: its methods
                for m in vars(fn).values():
                    if hasattr(m, "__code__"):
                        names |= _names(m.__code__, module_globals, seen)
            elif inner is not None:
                names |= _names(inner, module_globals, seen)
    return names


def _tiers(item) -> set[str]:
    """The tiers (``live``, ``twin``) ``item`` belongs to by what it uses."""
    info = getattr(item, "_fixtureinfo", None)
    closure = set(info.names_closure) if info else set()
    tiers = {"live"} if closure & LIVE_FIXTURES else set()
    funcs = [getattr(item, "function", None)]
    for name in closure:  # a module's own fixtures (conftest's are judged by name above)
        for fdef in (info.name2fixturedefs.get(name) or ()) if info else ():
            if getattr(fdef.func, "__module__", "") == getattr(item.module, "__name__", None):
                funcs.append(fdef.func)
    g = vars(item.module) if getattr(item, "module", None) else {}
    for fn in funcs:
        code = getattr(getattr(fn, "__wrapped__", fn), "__code__", None)
        if code is None:
            continue
        names = _names(code, g, set())
        if names & LIVE_NAMES or {"zenoh", "open"} <= names:  # zenoh.open: a session, a router
            tiers.add("live")
        if _twin_names(names, g):
            tiers.add("twin")
    return tiers


def pytest_collection_modifyitems(config, items):
    for item in items:
        for tier in _tiers(item):
            if not item.get_closest_marker(tier):
                item.add_marker(getattr(pytest.mark, tier))
        if item.get_closest_marker("root") and os.geteuid() != 0:
            item.add_marker(pytest.mark.skip(reason="needs root"))


# One whole live cell at a time on the machine: a module marked ``cell`` (every component a
# process on a 4-12 ms cycle) holds a machine-wide lock from its first fixture to its end, so
# the other test worker runs other files meanwhile. Beside a second cell on two cores the
# servo lost its target: the ABB demo recorded one point in CI, and beside a second cell's
# tests the filter tracked under half the recording in 8 runs of 9 (beside two CPU hogs, 3
# of 3 tracked). (xdist's --dist loadgroup would do it without waiting, but its groups do not
# reach its scheduler under pytest 9.2: it renames a node through an attribute pytest 9.2 no
# longer reads.)
CELL_LOCK = Path(tempfile.gettempdir()) / f"humanpt-live-cell-{os.getuid()}.lock"


@pytest.fixture(scope="module", autouse=True)
def _one_live_cell(request):
    if request.node.get_closest_marker("cell") is None:
        yield
        return
    import fcntl

    with open(CELL_LOCK, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)  # (released when the file closes, or the worker dies)
        yield


# What a test not marked live started anyway (a process, a Zenoh session, a pty): listed at
# the end of the run, so the inner loop stays what it says.
_UNMARKED_LIVE: dict[str, set[str]] = {}


@pytest.fixture(autouse=True)
def _live_watch(request, monkeypatch):
    if request.node.get_closest_marker("live"):
        yield
        return
    import pty as pty_mod

    import zenoh

    seen = _UNMARKED_LIVE.setdefault(request.node.nodeid, set())

    def watch(owner, attr, what):
        orig = getattr(owner, attr)

        def wrapper(*a, **k):
            seen.add(what)
            return orig(*a, **k)

        monkeypatch.setattr(owner, attr, wrapper)

    orig_popen = subprocess.Popen.__init__

    def popen(self, args, *a, **k):  # a humanpt process (a git query is no live test)
        argv = [args] if isinstance(args, str | os.PathLike) else list(args)
        if argv and Path(str(argv[0])).name != "git":
            seen.add("a process")
        return orig_popen(self, args, *a, **k)

    monkeypatch.setattr(subprocess.Popen, "__init__", popen)
    orig_socket = socket.socket.__init__

    def udp(self, family=-1, type=-1, *a, **k):  # noqa: A002 - socket.socket's own names
        if type != -1 and type & socket.SOCK_DGRAM:
            seen.add("a UDP socket")
        return orig_socket(self, family, type, *a, **k)

    monkeypatch.setattr(socket.socket, "__init__", udp)
    watch(zenoh, "open", "a Zenoh session")
    watch(os, "openpty", "a pty")
    watch(pty_mod, "openpty", "a pty")
    yield
    if not seen:
        del _UNMARKED_LIVE[request.node.nodeid]


def pytest_terminal_summary(terminalreporter):
    if _UNMARKED_LIVE:
        terminalreporter.write_sep("-", "tests not marked live that started one (mark them: tests/conftest.py)")
        for nodeid, what in sorted(_UNMARKED_LIVE.items()):
            terminalreporter.write_line(f"{nodeid}: {', '.join(sorted(what))}")


# -- the order files are handed to the test workers ----------------------------------------
# With ``--dist loadfile`` a worker takes the next file when it runs short; pyproject turns
# xdist's own reordering (most tests per file first) off, and the files are given longest
# first (tests/durations.json: seconds per file, measured), so that the minute-long files do
# not start last and keep one worker busy while the other waits. Files not listed keep their
# order after the listed ones. ``--store-durations`` rewrites the file from the run (today's: the
# last CI's figures for its slowest tests, the others from a run on this machine scaled to CI).
DURATIONS = Path(__file__).with_name("durations.json")


def pytest_addoption(parser):
    parser.addoption("--store-durations", action="store_true",
                     help="write each test file's seconds (setup, call, teardown) to tests/durations.json")


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


class _LongestFilesFirst:
    """A plugin of its own: this file's other modifyitems hook (the tiers) must run before
    pytest's ``-m`` selection, this one after a plugin that shuffles (pytest-randomly): it
    only moves whole files forward."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, items):
        try:
            seconds = json.loads(DURATIONS.read_text())
        except (OSError, ValueError):
            return
        items.sort(key=lambda item: -seconds.get(_file_of(item.nodeid), 0.0))  # stable: a file's own order kept


def pytest_configure(config):
    config.pluginmanager.register(_LongestFilesFirst(), "humanpt-longest-files-first")
    if not hasattr(config, "workerinput") and not config.option.collectonly:
        # Perception's compiled kernels into numba's disk cache once, here, before the
        # workers start: on a fresh clone each worker (and each live perception process
        # started before the cache is written) would compile them itself, 10-20 s each.
        from humanpt.perception import Perception, PerceptionConfig

        Perception(PerceptionConfig()).warm_up()
        Perception(PerceptionConfig(method="paper")).warm_up()


_SECONDS: dict[str, float] = {}


def pytest_runtest_logreport(report):
    _SECONDS[_file_of(report.nodeid)] = _SECONDS.get(_file_of(report.nodeid), 0.0) + report.duration


def pytest_sessionfinish(session):
    if session.config.getoption("store_durations") and not hasattr(session.config, "workerinput") and _SECONDS:
        DURATIONS.write_text(json.dumps({f: round(s, 1) for f, s in sorted(_SECONDS.items(), key=lambda kv: -kv[1])},
                                        indent=0) + "\n")


def run_cli_here(*args: str, cwd: str | Path | None = None, stdin: str | None = None) -> subprocess.CompletedProcess:
    """``humanpt ARGS`` run in this process (:func:`in_process_cli`), its exit status and
    output as :func:`run_cli` gives them: for verbs whose process boundary is not what a test
    checks (a file in, a file or an error out), without a Python start-up per call. ``stdin``:
    what the command reads (an interactive console). Not for a command whose children write to
    its stdout (``humanpt up``: they inherit the file descriptor, which is not redirected)."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    here, stdin_was = os.getcwd(), sys.stdin
    try:
        os.chdir(ROOT if cwd is None else cwd)  # (run_cli's default too)
        if stdin is not None:
            sys.stdin = io.StringIO(stdin)
        with in_process_cli() as main, contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as e:  # argparse's errors and --help
                code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
                if not isinstance(e.code, int | None):
                    print(e.code, file=sys.stderr)
    finally:
        os.chdir(here)
        sys.stdin = stdin_was
    return subprocess.CompletedProcess(["humanpt", *args], code or 0, out.getvalue(), err.getvalue())


@pytest.fixture
def cli():
    """:func:`run_cli_here` as ``cli(*argv, stdin=None) -> (exit status, stdout, stderr)``."""
    def run(*argv: str, stdin: str | None = None) -> tuple[int, str, str]:
        r = run_cli_here(*argv, stdin=stdin, cwd=os.getcwd())
        return r.returncode, r.stdout, r.stderr
    return run
