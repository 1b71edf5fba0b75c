"""`humanpt param dump/load` against a real pinger (live parameter period_ms, Range 1..60000 ms),
with options among the positionals."""

from __future__ import annotations

import json
import tomllib

from tests.conftest import run_cli, wait_for


def _period(cfg) -> float:
    r = run_cli("param", "pinger", "--config", str(cfg))
    assert r.returncode == 0, r.stdout + r.stderr
    return json.loads(r.stdout[r.stdout.index("{"):])["params"]["period_ms"]


def test_dump_then_load_all_or_nothing(router, procs, tmp_path):
    _, cfg = router
    procs.start("pinger", "--config", str(cfg), "--run-dir", str(tmp_path / "run"))
    wait_for(lambda: run_cli("param", "pinger", "--config", str(cfg), "--timeout", "1").returncode == 0, 30,
             "the pinger's parameters")
    dump = tmp_path / "pinger.toml"
    # options before, between and after the positionals
    r = run_cli("param", "--config", str(cfg), "dump", "pinger", "--timeout", "5", str(dump))
    assert r.returncode == 0, r.stdout + r.stderr
    assert tomllib.loads(dump.read_text()) == {"pinger": {"period_ms": 100.0}}  # PingerConfig's default
    r = run_cli("param", "dump", "pinger", str(dump), "--config", str(cfg))
    assert r.returncode == 2 and "exists; give --overwrite" in r.stderr  # never overwritten silently

    good = tmp_path / "good.toml"
    good.write_text("[pinger]\nperiod_ms = 50.0\n")
    r = run_cli("param", "load", "pinger", str(good), "--config", str(cfg))
    assert r.returncode == 0, r.stdout + r.stderr
    assert _period(cfg) == 50.0

    for text, why in [("period_ms = 0.5\n", "period_ms"),  # below its Range (1 ms)
                      ("period_ms = 80.0\nno_such_key = 1\n", "'no_such_key' not live parameter(s)"),
                      ("[controller]\ngain = 1\n", "has section(s) controller")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        r = run_cli("param", "load", "pinger", str(bad), "--config", str(cfg))
        assert r.returncode == 2 and why in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "nothing set" in r.stderr or "section" in r.stderr
        assert _period(cfg) == 50.0  # nothing set

    # the dump loads back: the value it held
    r = run_cli("param", "load", "--config", str(cfg), "pinger", str(dump))
    assert r.returncode == 0 and _period(cfg) == 100.0, r.stdout + r.stderr
    # KEY=VALUE after an option still sets
    r = run_cli("param", "pinger", "--timeout", "5", "period_ms=70", "--config", str(cfg))
    assert r.returncode == 0 and _period(cfg) == 70.0, r.stdout + r.stderr
