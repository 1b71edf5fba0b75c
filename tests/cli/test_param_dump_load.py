"""`humanpt param dump/load` against a real pinger (live parameter period_ms, Range 1..60000 ms),
with options among the positionals.  The CLI runs in this process (cli_main): a dozen calls."""

from __future__ import annotations

import json
import tomllib

from tests.conftest import wait_alive


def test_dump_then_load_all_or_nothing(router, procs, tmp_path, cli_main, capsys):
    port, cfg = router
    c = ["--config", str(cfg)]

    def call(*argv: str) -> tuple[int, str, str]:
        rc = cli_main(list(argv))
        out = capsys.readouterr()
        return rc, out.out, out.err

    def period() -> float:
        rc, out, err = call("param", "pinger", *c)
        assert rc == 0, out + err
        return json.loads(out[out.index("{"):])["params"]["period_ms"]

    procs.start("pinger", *c, "--run-dir", str(tmp_path / "run"))
    wait_alive(port, "pinger")  # its params queryable is up before its liveliness token
    dump = tmp_path / "pinger.toml"
    # options before, between and after the positionals
    rc, out, err = call("param", *c, "dump", "pinger", "--timeout", "5", str(dump))
    assert rc == 0, out + err
    assert tomllib.loads(dump.read_text()) == {"pinger": {"period_ms": 100.0}}  # PingerConfig's default
    rc, _, err = call("param", "dump", "pinger", str(dump), *c)
    assert rc == 2 and "exists; give --overwrite" in err  # never overwritten silently

    good = tmp_path / "good.toml"
    good.write_text("[pinger]\nperiod_ms = 50.0\n")
    rc, out, err = call("param", "load", "pinger", str(good), *c)
    assert rc == 0, out + err
    assert period() == 50.0

    for text, why in [("period_ms = 0.5\n", "period_ms"),  # below its Range (1 ms)
                      ("period_ms = 80.0\nno_such_key = 1\n", "'no_such_key' not live parameter(s)"),
                      ("[controller]\ngain = 1\n", "has section(s) controller")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        rc, _, err = call("param", "load", "pinger", str(bad), *c)
        assert rc == 2 and why in err and len(err.strip().splitlines()) == 1, err
        assert "nothing set" in err or "section" in err
        assert period() == 50.0  # nothing set

    # the dump loads back: the value it held
    rc, out, err = call("param", "load", *c, "pinger", str(dump))
    assert rc == 0 and period() == 100.0, out + err
    # KEY=VALUE after an option still sets
    rc, out, err = call("param", "pinger", "--timeout", "5", "period_ms=70", *c)
    assert rc == 0 and period() == 70.0, out + err


def test_load_rolls_back_when_the_component_refuses_one(router, procs, tmp_path, cli_main, capsys):
    """robot_gateway's safety limits may only become stricter at run time (the component
    checks against the values it started with): a file tightening one and loosening another
    leaves both as they were."""
    port, cfg = router
    with open(cfg, "a") as f:
        f.write('\n[robot_gateway]\nport = "loop://"\n')  # pyserial's loopback: no robot needed
    c = ["--config", str(cfg)]

    def params() -> dict:
        assert cli_main(["param", "robot_gateway", *c, "--timeout", "1"]) == 0
        out = capsys.readouterr().out
        return json.loads(out[out.index("{"):])["params"]

    procs.start("robot_gateway", *c, "--run-dir", str(tmp_path / "run"))
    wait_alive(port, "robot_gateway")
    before = params()
    f = tmp_path / "limits.toml"
    f.write_text(f"[robot_gateway]\nstale_cycles = {before['stale_cycles'] - 1}\n"
                 f"max_speed_mm_s = {before['max_speed_mm_s'] * 2}\n")
    assert cli_main(["param", "load", "robot_gateway", str(f), *c]) == 1
    err = capsys.readouterr().err
    rejected = [ln for ln in err.splitlines() if ln.startswith("REJECTED")]
    assert len(rejected) == 1 and "max_speed_mm_s" in rejected[0], err  # stale_cycles was set ...
    assert "refused 1 of 2; the others were set back" in err, err  # ... and set back
    assert params() == before
