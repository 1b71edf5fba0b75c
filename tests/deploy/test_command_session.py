"""The gateway accepts commands only from the controller session it follows (issue 19 item 3).

Real parts: a real router, ``humanpt robot_gateway`` and ``humanpt sim_robot`` as processes
over a real pty; two controller sessions of this test, each a Zenoh client with its own
``controller`` liveliness token. The first commands +0.5 mm along x every cycle; then a
second session (a second controller, or a forger that read the robot states and stamps its
commands right) commands -1 mm along y for the same cycles. Without the router's access
control (plaintext) the gateway itself must not follow it; under mTLS both sessions hold
the controller's certificate (a duplicate or stolen one: the router lets both put, a
non-controller certificate cannot, see tests/security), and the gateway must not follow
it either. It holds the robot while two streams speak (``controller_conflict``), never
moves it along -y, and moves it again with the first session once the second is quiet
(``conflict_cleared``). Its recording replays exactly.
"""

from __future__ import annotations

import queue
import threading

import numpy as np
import pytest
import zenoh

from humanpt.runtime.bus import free_tcp_port, liveliness_key, zenoh_config
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.security import init_ca, issue
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header, vector3
from tests.conftest import InProcessRouter, run_cli_here, wait_for, wait_port, write_config

COMMAND = "humanpt/test/controller/command"


class Controller:
    """One controller session: a token, and an answer to every robot state (a step of
    ``dp_m`` for the state's own cycle, stamped with its stamp, seq counting from
    ``seq0``) while ``speaking`` is set."""

    def __init__(self, rt: RuntimeConfig, dp_m, seq0: int):
        self.session = zenoh.open(zenoh_config(rt, identity="controller"))
        self.token = self.session.liveliness().declare_token(liveliness_key("test", "controller"))
        self.pub = self.session.declare_publisher(COMMAND)
        self.dp_m, self.seq = dp_m, seq0
        self.speaking = threading.Event()
        self.sub = self.session.declare_subscriber("humanpt/test/robot_gateway/robot_state", self._on_state)

    def _on_state(self, sample) -> None:
        if not self.speaking.is_set():
            return
        st = pb.RobotState.FromString(sample.payload.to_bytes())
        cmd = pb.FlangeCommand(header=header(st.header.stamp_ns, self.seq, "world"), cycle=st.cycle,
                               d_translation_m=vector3(self.dp_m), mode=pb.CONTROL_MODE_TRACK)
        self.seq += 1
        self.pub.put(cmd.SerializeToString())

    def close(self) -> None:
        self.speaking.clear()
        self.session.close()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("security", ["none", "mtls"])
def test_a_second_controller_session_holds_the_robot_and_never_moves_it(procs, tmp_path, security, request):
    port = free_tcp_port()
    link = tmp_path / "alter-pty"
    pki = tmp_path / "pki"
    sec = f'security = "{security}"\npki = "{pki}"\n'
    if security == "mtls":
        init_ca(pki, "test")
        for name in ("router", "robot_gateway", "sim_robot", "controller", "tool"):
            issue(pki, name)
    cfg = write_config(tmp_path / "alter.toml", port,
                       extra=sec + f'[sim_robot]\npty_link = "{link}"\n[robot_gateway]\nport = "{link}"\n')
    rt = RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",), security=security, pki=str(pki))
    if security == "none":  # the router's process is not the subject: in this process
        request.addfinalizer(InProcessRouter(cfg).stop)
    else:  # (mTLS with denial reports sets Zenoh's logging for its whole process: its own)
        wait_port(port, proc=procs.start("router", "--config", str(cfg)))
    run = tmp_path / "run"
    gw = procs.start("robot_gateway", "--config", str(cfg), "--run-dir", str(run))
    procs.start("sim_robot", "--config", str(cfg), "--run-dir", str(run))
    truths: list[np.ndarray] = []
    events: queue.Queue = queue.Queue()
    codes: list[str] = []

    def seen(code: str) -> bool:
        while not events.empty():
            codes.append(events.get().code)
        return code in codes

    with zenoh.open(zenoh_config(rt, identity="tool")) as watcher:
        subs = [watcher.declare_subscriber("humanpt/test/sim_robot/truth", lambda s: truths.append(
                    from_pose(pb.Truth.FromString(s.payload.to_bytes()).world_T_flange)[:3, 3] * 1000.0)),
                watcher.declare_subscriber("humanpt/test/robot_gateway/events", lambda s: events.put(
                    pb.Event.FromString(s.payload.to_bytes())))]
        real = Controller(rt, (0.0005, 0.0, 0.0), seq0=1000)  # it has been running a while
        second = Controller(rt, (0.0, -0.001, 0.0), seq0=0)  # a fresh second session
        try:
            real.speaking.set()
            wait_for(lambda: len(truths) >= 60, 30.0, "60 robot cycles")
            x0 = truths[-1][0]
            wait_for(lambda: len(truths) >= 90, 10.0, "30 more cycles")
            assert truths[-1][0] - x0 > 5.0, "the real controller did not move the robot"
            y0 = truths[-1][1]
            # The second session speaks too, for about a second.
            second.speaking.set()
            wait_for(lambda: seen("controller_conflict"), 5.0, "controller_conflict")
            n = len(truths) + 3  # (a correction already on its way may still be applied)
            wait_for(lambda: len(truths) >= n + 25, 5.0, "25 cycles with two streams")
            held = np.array(truths[n:])
            assert np.ptp(held, axis=0).max() < 1e-9, "the robot moved while two command streams spoke"
            second.speaking.clear()
            wait_for(lambda: seen("conflict_cleared"), 5.0, "conflict_cleared")
            m = len(truths)
            wait_for(lambda: len(truths) >= m + 30, 5.0, "30 cycles after the conflict")
            assert truths[-1][0] - truths[m][0] > 5.0, "the real controller did not move the robot again"
            assert min(t[1] for t in truths[n - 3:]) > y0 - 0.005, "the second session's -y step was acted on"
        finally:
            second.close()
            real.close()
            for s in subs:
                s.undeclare()
    out = procs.stop(gw)
    assert gw.returncode == 0, out
    assert codes.count("controller_conflict") >= 1 and "fault" not in codes, codes
    res = run_cli_here("replay", str(run), "--component", "robot_gateway")
    assert res.returncode == 0 and "MATCH" in res.stdout, res.stdout + res.stderr
