"""`humanpt param` and `humanpt config` with the gateway over RSI: the process started by
its old name from a config file's old section, its live limits read, made stricter, and a
looser value refused (safety limits only become stricter at run time, DESIGN.md)."""

from __future__ import annotations

import json

from tests.conftest import free_port, wait_alive, write_config

RSI_CELL = """
[alter_gateway]
link = "rsi"
cycle_period_ms = 12.0
udp_bind = "127.0.0.1:{udp}"
max_speed_mm_s = 80.0

[controller]
cycle_period_ms = 12.0

[sim_robot]
cycle_period_ms = 12.0

[viz]
cycle_period_ms = 12.0
"""


def test_param_reads_and_tightens_a_running_rsi_gateway(router, procs, tmp_path, cli_main, capsys):
    port, _ = router
    cfg = write_config(tmp_path / "rsi.toml", port, RSI_CELL.format(udp=free_port()))
    c = ["--config", str(cfg)]

    def call(*argv: str) -> tuple[int, str, str]:
        rc = cli_main(list(argv))
        out = capsys.readouterr()
        return rc, out.out, out.err

    def params(name: str = "robot_gateway") -> dict:
        rc, out, err = call("param", name, *c)
        assert rc == 0, out + err
        return json.loads(out[out.index("{"):])["params"]

    # `config` prints the section under its new name, with the RSI link's fields.
    rc, out, err = call("config", *c)
    assert rc == 0, err
    assert "[robot_gateway]" in out and "[alter_gateway]" not in out
    assert 'link = "rsi"' in out and "udp_bind" in out and "reply_deadline_ms" in out

    procs.start("alter_gateway", *c, "--run-dir", str(tmp_path / "run"))  # the old command
    wait_alive(port, "robot_gateway")  # its params queryable is up before its liveliness token
    p = params("alter_gateway")  # the old name reaches it too
    assert p["max_speed_mm_s"] == 80.0 and p["fault_after_missed"] == 70  # the file's; RSI's default

    rc, out, err = call("param", "robot_gateway", "max_speed_mm_s=50", *c)
    assert rc == 0, out + err
    assert params()["max_speed_mm_s"] == 50.0
    rc, out, err = call("param", "robot_gateway", "max_speed_mm_s=90", *c)  # looser: refused
    assert rc != 0 and "stricter" in (out + err), out + err
    assert params()["max_speed_mm_s"] == 50.0
