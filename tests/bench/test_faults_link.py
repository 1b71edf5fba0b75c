"""``humanpt bench faults`` rows of issue 29: the attacks on the robot link (the gateway
killed mid-motion, <Rob> injection, a junk flood and a spoofed IPOC from another UDP port,
a 1795-point seam played), over RSI, against the live twin (router + seven processes, real
UDP sockets), run once in this process for the file (over ALTER: tests/bench/test_faults.py,
from the default run); and the bench's start (issue 29 item 15): it
waits on the router the twin started, and says so with exit status 2 when it never comes.

Asserted: the verdicts (held within the bound, refused, no fault latched, RSI still
running), never rates. Until the fixes of items 1, 5, 6, 7 and 9 (the RSI link, the
controller) are in, the rows show the defects and these tests fail on them (reproduced:
52 mm after the kill, 74/80 answers to the attacker, RSI stopped, a fault latched, a late
command)."""

from __future__ import annotations

import threading

import pytest

from humanpt.bench.faults import open_router_session
from humanpt.runtime.config import load
from humanpt.twin.live import wait_listening
from tests.bench.faults_rows import LINK_ROWS as ROWS
from tests.bench.faults_rows import (
    Bench,
    bench_run,
    kill_within_bound,
    seam_played_or_refused,
    table,
)
from tests.conftest import free_port, write_config

pytestmark = [pytest.mark.live, pytest.mark.cell]  # the bench's twin, routers, UDP sockets


@pytest.fixture(scope="module")
def rsi_bench(tmp_path_factory) -> Bench:
    """``humanpt bench faults --link rsi --only kill,inject,junk,ipoc,bigseam``, in this process."""
    return bench_run(tmp_path_factory.mktemp("faults-rsi") / "run", tuple(ROWS), link="rsi")


@pytest.mark.timeout(600)  # bounds a hang
def test_link_rows_over_rsi(rsi_bench):
    rows = rsi_bench.table
    assert list(rows) == list(ROWS.values()), rows
    assert rsi_bench.leftovers == []
    # Every row judged before any assertion fails: the message names each defect left.
    checks = {
        "kill": lambda: kill_within_bound(rows[ROWS["kill"]], 100.0 * 0.012),  # 100 mm/s x 12 ms
        # Item 5: no answer reaches the attacker (issue: 73 of 80).
        "inject": lambda: _assert(rows[ROWS["inject"]]["note"].startswith("0/80 answers to the attacker")),
        # Item 6: RSI still runs after 3 s of junk (issue: rsi_stopped in 2 of 2 runs).
        "junk": lambda: _assert("RSI still running" in rows[ROWS["junk"]]["note"]),
        # Item 7: one spoofed IPOC + 500 latches no fault (issue: "498 consecutive missed cycles").
        "ipoc": lambda: _assert(rows[ROWS["ipoc"]]["note"].startswith("no fault latched")),
        "bigseam": lambda: seam_played_or_refused(rows[ROWS["bigseam"]]),
    }
    failed = []
    for key, check in checks.items():
        try:
            check()
            assert rows[ROWS[key]]["verdict"] == "ok"
        except AssertionError:
            failed.append(f"{key}: {rows[ROWS[key]]}")
    assert not failed, "\n".join(failed)
    assert rsi_bench.failure == ""  # (the verb's exit status 0 with every verdict ok)


def _assert(ok: bool) -> None:
    assert ok


def test_rows_for_the_other_link_start_no_twin(tmp_path, cli_main, capsys):
    """The verb (in this process: no twin, nothing to spawn) with only rows that need RSI:
    each skipped, no twin started; an unknown row named, exit status 2, no traceback."""
    assert cli_main(["bench", "faults", "--only", "inject,junk,ipoc", "--run-dir", str(tmp_path / "run")]) == 0
    rows = table(capsys.readouterr().out)
    assert [r["verdict"] for r in rows.values()] == ["skipped"] * 3
    assert not (tmp_path / "run" / "humanpt.toml").exists()
    assert cli_main(["bench", "faults", "--only", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "unknown attack(s) nosuch" in err and "Traceback" not in err, err


# -- the bench's start: it waits on the router the twin started (item 15) ------------------------
@pytest.mark.timeout(120)
def test_the_bench_waits_for_a_router_that_comes_late(tmp_path, procs):
    """The router is started only after the bench began to wait for it (as on a loaded
    machine, where the twin's router took longer than a tool's connect timeout): the bench's
    session opens once it listens, instead of "cannot reach the router"."""
    port = free_port()
    # A connect timeout far shorter than the router's start-up (a Python process: ~1 s idle):
    # one patient open, what the bench did, fails ("cannot reach the router").
    cfg = tmp_path / "humanpt.toml"
    cfg.write_text(f'[runtime]\ncell = "test"\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                   f'listen = ["tcp/127.0.0.1:{port}"]\nrun_dir = "{tmp_path / "runs"}"\nconnect_timeout_s = 0.2\n')
    rt = load(cfg).runtime
    got: dict = {}
    ended = threading.Event()

    def bench() -> None:
        try:
            got["session"] = open_router_session(rt, None, tmp_path, 90.0, ended)
        except Exception as e:  # noqa: BLE001 -- reported below
            got["error"] = e

    waiter = threading.Thread(target=bench)
    waiter.start()
    try:
        router = procs.start("router", "--config", str(cfg))
        waiter.join(100)
        assert "error" not in got, got.get("error")
        assert "session" in got
        assert router.poll() is None
    finally:
        ended.set()
        waiter.join(5)
        if "session" in got:
            got["session"].close()


def test_a_router_that_never_listens_is_named_with_its_log(tmp_path):
    port = free_port()
    rt = load(write_config(tmp_path / "humanpt.toml", port)).runtime
    with pytest.raises(RuntimeError, match=rf"router at 127\.0\.0\.1:{port} did not take the bench's session "
                       r"within \d+ s \(load average [\d.]+\): nothing listens .*processes\.log"):
        open_router_session(rt, None, tmp_path, 1.0, threading.Event())
    assert "exited before listening" in wait_listening("127.0.0.1", port, 5.0, alive=lambda: False)
