"""Two cells on one router are isolated from each other (issue 31 item 5b): distinct
``cell`` names, each a robot gateway and a simulated robot (behind its own pty) as
processes; this test is cell ``a``'s controller. Cell ``a``'s robot follows the commands
and takes a console command (ALTER off) sent to cell ``a``; cell ``b``'s never moves and
stays in ALTER, its gateway never receives a command nor sees ``a``'s controller, its
robot never a console command (judged from ``b``'s own recordings, which keep every input
its components took), and every key on the router is one of the two cells'.
"""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.runtime.bus import liveliness_key
from humanpt.runtime.recording import read
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose
from humanpt.testing.harness import ScriptedControllerConfig, scripted_command
from tests.conftest import wait_for, wait_matching, write_config, zenoh_client

CELLS = ("a", "b")


def _start_cell(procs, tmp_path, port: int, cell: str):
    link = tmp_path / f"alter-pty-{cell}"
    cfg = write_config(tmp_path / f"{cell}.toml", port, cell=cell,
                       extra=f'[sim_robot]\npty_link = "{link}"\n[robot_gateway]\nport = "{link}"\n')
    run = tmp_path / f"run-{cell}"
    gw = procs.start("robot_gateway", "--config", str(cfg), "--run-dir", str(run))
    sim = procs.start("sim_robot", "--config", str(cfg), "--run-dir", str(run))
    return run, gw, sim


@pytest.mark.timeout(150)
def test_two_cells_on_one_router_do_not_see_each_other(router, procs, tmp_path):
    port, _ = router
    cells = {c: _start_cell(procs, tmp_path, port, c) for c in CELLS}
    script = ScriptedControllerConfig()
    states: dict[str, list[pb.RobotState]] = {c: [] for c in CELLS}
    truth_mm: dict[str, list[np.ndarray]] = {c: [] for c in CELLS}
    keys: set[str] = set()
    with zenoh_client(port) as s:
        token = s.liveliness().declare_token(liveliness_key("a", "controller"))
        pub = s.declare_publisher("humanpt/a/controller/command")

        def on_state(cell: str):
            def cb(sample):
                st = pb.RobotState.FromString(sample.payload.to_bytes())
                states[cell].append(st)
                if cell == "a":  # cell a's controller only
                    pub.put(scripted_command(st, script, len(states["a"])).SerializeToString())
            return cb

        def on_truth(cell: str):
            return lambda smp: truth_mm[cell].append(
                from_pose(pb.Truth.FromString(smp.payload.to_bytes()).world_T_flange)[:3, 3] * 1000.0)

        subs = [s.declare_subscriber("humanpt/**", lambda smp: keys.add(str(smp.key_expr)))]
        for c in CELLS:
            subs += [s.declare_subscriber(f"humanpt/{c}/robot_gateway/robot_state", on_state(c)),
                     s.declare_subscriber(f"humanpt/{c}/sim_robot/truth", on_truth(c))]
        # Both cells run; cell a's robot is driven until it has moved 5 mm (the script's
        # motion), while cell b's link runs as long with no controller.
        wait_for(lambda: len(states["a"]) >= 20 and len(states["b"]) >= 20, 90.0, "both cells' robot states")
        wait_for(lambda: np.linalg.norm(truth_mm["a"][-1] - truth_mm["a"][0]) > 5.0, 60.0,
                 "cell a's robot moving 5 mm")
        mark = len(states["b"])
        wait_for(lambda: len(states["b"]) >= mark + 20, 60.0, "20 more of cell b's robot states")
        # A console command for cell a's robot (ALTER off): a's robot takes it, b's never hears it.
        sim_events: list[tuple[str, pb.Event]] = []
        subs.append(s.declare_subscriber("humanpt/*/sim_robot/events", lambda smp: sim_events.append(
            (str(smp.key_expr), pb.Event.FromString(smp.payload.to_bytes())))))
        console = s.declare_publisher("humanpt/a/console/command")
        wait_matching(console)
        console.put(pb.Command(header=pb.Header(seq=1), component="sim_robot", verb="alter_off",
                               args_json='{"operator": "test@two-cells"}').SerializeToString())
        wait_for(lambda: any(k.startswith("humanpt/a/") and e.code == "alter_off" for k, e in sim_events), 30.0,
                 "cell a's robot taking ALTER off")
        wait_for(lambda: not states["a"][-1].status.alter_active, 30.0, "cell a's robot state showing ALTER off")
        mark = len(states["b"])
        wait_for(lambda: len(states["b"]) >= mark + 20, 60.0, "20 more of cell b's robot states")
        assert all(st.status.alter_active for st in states["b"]), "cell b's robot left ALTER"
        assert not [k for k, _ in sim_events if not k.startswith("humanpt/a/")], sim_events
        token.undeclare()
        for sub in subs:
            sub.undeclare()
    for c in CELLS:
        run, gw, sim = cells[c]
        for p in (gw, sim):
            out = procs.stop(p)
            assert p.returncode == 0 and "core errors 0" in out, out

    # Cell b's robot stood still to the last (ALTER corrections of exactly zero).
    b = np.array(truth_mm["b"])
    assert len(b) >= 40 and np.ptp(b, axis=0).max() < 1e-9, np.ptp(b, axis=0)
    # Cell b's gateway took no command and never saw a controller; cell a's took them.
    run_b, run_a = cells["b"][0], cells["a"][0]
    rec_b = read(run_b / "robot_gateway.mcap")
    assert rec_b.inputs and not [e for e in rec_b.inputs if e.topic == "controller/command"]
    assert not [e for e in rec_b.inputs if e.topic == "liveliness" and e.decode().alive]
    rec_a = read(run_a / "robot_gateway.mcap")
    assert len([e for e in rec_a.inputs if e.topic == "controller/command"]) >= 20
    assert [e.decode().alive for e in rec_a.inputs if e.topic == "liveliness"][:1] == [True]
    # Every key is one cell's: humanpt/<cell>/<component>/...; the sim robots' states
    # arrive in their own cell only (what each recorded was its own link's bytes).
    assert {k.split("/")[1] for k in keys} == set(CELLS), sorted(keys)[:20]
    # Cell b's robot took no console command; cell a's took the one sent to it.
    assert not [e for e in read(run_b / "sim_robot.mcap").inputs if e.topic == "console/command"]
    assert [e.decode().verb for e in read(run_a / "sim_robot.mcap").inputs if e.topic == "console/command"] \
        == ["alter_off"]
