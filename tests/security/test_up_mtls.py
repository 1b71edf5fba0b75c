"""``humanpt up`` under ``security = "mtls"``: the closed loop on the twin, every process a
client of the router with its own certificate, the router enforcing the generated access
control; nothing the loop needs is refused (issue 19 item 1, "the demo runs as before")."""

from __future__ import annotations

from humanpt.runtime.recording import IN
from humanpt.runtime.registry import PROFILES, core_class
from humanpt.runtime.runinfo import file_info
from humanpt.runtime.security import identities, init_ca, issue
from humanpt.schemas import topics
from tests.conftest import free_port, run_cli, write_config

# Every other bus input must flow: nobody commands or records in this run (console/command,
# controller/path), and events come only when something happens (scene logs them all).
QUIET = {"console/command", "controller/path", *(t for t in topics.TOPICS if t.endswith("/events"))}


def test_the_loop_runs_under_mtls(tmp_path):
    comps = PROFILES["loop"]["components"]
    pki = tmp_path / "certs"
    init_ca(pki, "test")
    for name in ("router", *comps, "tool"):  # tool: what `up` watches the components come up as
        issue(pki, name)
    cfg = write_config(tmp_path / "cell.toml", free_port(), extra='security = "mtls"\npki = "certs"\n')
    run_dir = tmp_path / "run"
    # (3 s of the running loop, counted from every component up: over 100 cycles of 28 ms)
    r = run_cli("up", "--config", str(cfg), "--duration", "3", "--run-dir", str(run_dir), timeout=240)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "mTLS" in r.stdout and "tls/127.0.0.1" in r.stdout
    # --duration is seconds of the running loop, counted from when every component is up
    # (not from their start: under load the start took most of 12 s, and no command came)
    assert f"all {len(comps)} components up after" in r.stdout, r.stdout
    for name in comps:
        info = file_info(run_dir / f"{name}.mcap")
        got = {t for (d, t), ti in info.topics.items() if d == IN and ti.count > 0}
        needs = {p.topic for p in core_class(name).ports if p.on_bus and p.topic not in QUIET}
        assert needs <= got, f"{name} never received {sorted(needs - got)} under mTLS"
    # the controller's commands reached the robot, through the access control
    robot = file_info(run_dir / "standin_robot.mcap")
    assert robot.topics[(IN, "controller/command")].count > 50
    assert {c.name for c in identities(pki)} >= set(comps)
