"""``humanpt demo --secure`` (issue 19, acceptance "the demo runs as before"): the live demo
under mTLS with a throwaway PKI in the run directory, every process a client of the
router, which enforces the access control generated from the topic table; the same
report as without, and the path still on the paper's arc."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.bench.summary import latency_and_cycles
from humanpt.controller import pathfile
from humanpt.runtime.recording import IN
from humanpt.runtime.registry import core_class
from humanpt.runtime.runinfo import file_info
from humanpt.twin.live import LIVE_COMPONENTS

pytestmark = [pytest.mark.cell, pytest.mark.timeout(300)]


@pytest.mark.live
def test_the_live_demo_runs_under_mtls(tmp_path, cli):
    run = tmp_path / "live"
    # (6 s of the running loop, counted from everything up: the operator moves along the arc from 3 s)
    # (the demo's shell in this process: the components, and the router, are processes of their own)
    code, out, err = cli("demo", "--secure", "--scenario", "arc", "--duration", "6", "--run-dir", str(run))
    assert code == 0, out + err + (run / "processes.log").read_text()[-3000:]
    assert "mTLS, a throwaway PKI in" in out
    assert "recorded path of G against ground truth" in out
    # As the demo without --secure (test_demo.py): cycles answered on time are a bench figure
    # (humanpt bench), not judged here (issue 31: a loaded machine answers fewer in time).
    res = latency_and_cycles(run)
    print(f"secure demo: {res['on_time']}/{res['cycles']} cycles answered on time")
    assert res["cycles"] > 100 and res["on_time"] > 0, res  # the loop closed
    toml = (run / "humanpt.toml").read_text()
    assert 'security = "mtls"' in toml and 'mode = "client"' in toml and 'mode = "peer"' not in toml
    pki = run / "pki"
    assert pki.stat().st_mode & 0o777 == 0o700
    for name in ("ca", "router", "demo-operator", *LIVE_COMPONENTS, "operator"):
        assert (pki / f"{name}.key").stat().st_mode & 0o777 == 0o600, name
    assert "listening on tls/127.0.0.1" in (run / "processes.log").read_text()
    # Every bus input of every component flowed through the access control
    # (console/command: the run's own record_start reached the controller only).
    for name in LIVE_COMPONENTS:
        info = file_info(run / f"{name}.mcap")
        got = {t for (d, t), ti in info.topics.items() if d == IN and ti.count > 0}
        needs = {p.topic for p in core_class(name).ports if p.on_bus}
        needs -= {"console/command"} if name != "controller" else set()
        # scene takes every component's events: they come only when something happens
        # (from components that run), so: some, not all.
        events = {t for t in needs if t.endswith("/events")}
        assert not events or events & got, f"{name} received no events under mTLS"
        needs -= events
        assert needs <= got, f"{name} never received {sorted(needs - got)} under mTLS"
    # The servo kept the target: the path follows the paper's arc (radius 246 mm).
    path = pathfile.read(sorted((run / "paths").glob("path-*.csv"))[-1])
    assert len(path) > 5
    radius = np.linalg.norm(path.x_g[:, :2] - [147.5, 1378.5], axis=1)
    assert np.all(np.abs(radius - 246.0) < 1.0)


def test_secure_is_for_the_live_demo(tmp_path, cli):
    code, out, err = cli("demo", "--secure", "--lockstep", "--scenario", "arc", "--run-dir", str(tmp_path / "r"))
    assert code != 0 and "--secure is for the live demo" in err
