"""The simulated UR's Dashboard server (port 29999 on a UR) and a program stopped through it:
the replies UR documents ("Dashboard Server, port 29999"), the arm braking on ``stop`` as the
program's stop does (runtime_state STOPPING, then STOPPED; robot_status_bits' "program
running" bit off), ``play`` starting the program from its start (no old target followed);
the gateway reading the stop from RTDE (link_down, the targets held at the arm, link_up when
it plays again, no jump); checked with a client no one here wrote, ur-rtde's
``dashboard_client.DashboardClient``, over real TCP."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.ur import CLOSED, DASHBOARD, RtdeServer, UrRobot, UrSimRobotCore
from humanpt.sim_robot.ur_dashboard import GREETING, UNLOCK_TOO_EARLY, DashboardSession, reply
from tests.ur.test_ur_link import sim_rig  # noqa: F401  (the fixture)

MS = 1_000_000
CYCLE_MS = 8.0
STEP_MM = 0.32  # 40 mm/s at 8 ms


def _target(robot: UrRobot, seq: int, T: np.ndarray) -> None:
    b = robot.b
    robot.inputs.update({f"input_int_register_{b}": seq,
                         **{f"input_double_register_{b + i}": v
                            for i, v in enumerate(rtde.ur_pose_from_transform(T))}})


def _moving_robot() -> tuple[UrRobot, int]:
    """A CB3 (8 ms) whose program follows a target moving 0.32 mm a cycle in +x (40 mm/s) for
    60 cycles: the arm at that speed (the servo's 20 ms lag long settled)."""
    robot = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=CYCLE_MS)
    T = robot.base_T_flange_mm
    seq = 0
    for _ in range(60):
        seq += 1
        T[0, 3] += STEP_MM
        _target(robot, seq, T)
        robot.cycle(seq * 8 * MS)
    return robot, seq


def test_stop_brakes_the_arm_and_play_restarts_the_program_from_its_start():
    robot, seq = _moving_robot()
    dash = DashboardSession(robot, "test")
    p0 = robot.base_T_flange_mm[:3, 3]
    v0 = float(np.linalg.norm(robot._last_step[0])) * 1000.0 / CYCLE_MS
    assert v0 == pytest.approx(40.0, rel=1e-3)
    assert dash.feed(b"stop\n", 0) == b"Stopped\n"
    states, moved = [], []
    for _ in range(8):  # the gateway goes on writing targets 0.32 mm further each cycle
        seq += 1
        T = robot.base_T_flange_mm
        T[0, 3] += STEP_MM
        _target(robot, seq, T)
        robot.cycle(0)
        out = robot.outputs()
        states.append((out["runtime_state"], out["robot_status_bits"]))
        moved.append(float(np.linalg.norm(robot.base_T_flange_mm[:3, 3] - p0)))
    # 1 m/s^2 from 40 mm/s: the speed falls by 8 mm/s a cycle, 0.8, 0.6, 0.4, 0.2 of the last
    # step: 2.0 x 0.32 = 0.64 mm (= v^2 / 2a - v dt / 2), then at rest
    assert moved[3] == pytest.approx(0.64, abs=1e-3) and moved[-1] == moved[3]
    assert states == [(rtde.RUNTIME_STOPPING, 1)] * 4 + [(rtde.RUNTIME_STOPPED, 1)] * 4  # power on, not running
    assert robot.heartbeat == 60 and robot.followed_seq == 60  # the program read no register since
    assert dash.feed(b"programState\nrunning\n", 0) == b"STOPPED humanpt_ur.urp\nProgram running: False\n"
    # Play: the program from its start; the register holds the gateway's last target: not followed
    assert dash.feed(b"play\n", 0) == b"Starting program\n"
    at = robot.base_T_flange_mm
    robot.cycle(0)
    assert robot.program_running and robot.heartbeat == 1 and robot.followed_seq == 0 and robot.stopped
    np.testing.assert_array_equal(robot.base_T_flange_mm, at)
    _target(robot, seq + 1, robot.base_T_flange_mm)  # a newer sequence at the arm: followed
    robot.cycle(0)
    assert not robot.stopped and robot.followed_seq == seq + 1 and robot.counters["program_starts"] == 1
    assert robot.outputs()["robot_status_bits"] == 3
    assert [e.code for e in robot.events if e.code.startswith(("program", "arm"))] == [
        "program_stopped", "arm_at_rest", "program_playing"]


def test_the_dashboard_answers_as_ur_documents():
    robot, _ = _moving_robot()  # an e-Series answers true/false, a CB3 True/False
    e_series = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=2.0)
    assert DashboardSession.greeting() == b"Connected: Universal Robots Dashboard Server\n" == (GREETING + "\n").encode()
    assert [reply(e_series, c, 0) for c in ("running", "isProgramSaved", "robotmode", "safetystatus", "safetymode",
                                             "get loaded program", "PolyscopeVersion", "close safety popup",
                                             "programState")] == [
        "Program running: true", "true humanpt_ur.urp", "Robotmode: RUNNING", "Safetystatus: NORMAL",
        "Safetymode: NORMAL", "Loaded program: humanpt_ur.urp",
        "URSoftware 5.11.0.0 (humanpt's simulated UR)", "closing safety popup", "PLAYING humanpt_ur.urp"]
    assert reply(e_series, "load other.urp", 0) == "File not found: other.urp" and e_series.program_running
    assert reply(e_series, "load /programs/humanpt_ur.urp", 0) == "Loading program: /programs/humanpt_ur.urp"
    assert not e_series.program_running  # loading stops the program
    assert reply(e_series, "pause", 0) == "Failed to execute: pause"  # (not playing)
    assert reply(robot, "pause", 0) == "Pausing program"
    assert reply(robot, "play", 0) == "Failed to execute: play"  # still braking
    for _ in range(5):
        robot.cycle(0)
    assert reply(robot, "programState", 0) == "PAUSED humanpt_ur.urp"
    assert reply(robot, "play", 0) == "Starting program" and robot.counters["program_starts"] == 0  # goes on
    assert reply(robot, "power on", 0) == "could not understand: 'power on'"
    # a protective stop: play refused until unlocked, and unlocking only 5 s after it
    robot.safety_mode, robot.protective_stop_cycle = rtde.SAFETY_MODE_PROTECTIVE_STOP, robot.cycles
    robot.stop_program(0)
    assert reply(robot, "safetystatus", 0) == "Safetystatus: PROTECTIVE_STOP"
    assert reply(robot, "play", 0) == "Failed to execute: play"
    assert reply(robot, "unlock protective stop", 0) == UNLOCK_TOO_EARLY
    robot.cycles += round(5000 / CYCLE_MS)
    assert reply(robot, "unlock protective stop", 0) == "Protective stop releasing"
    assert reply(robot, "play", 0) == "Starting program"


def test_the_sim_robot_core_serves_dashboard_clients_on_its_byte_stream():
    core = UrSimRobotCore.create(SimRobotConfig(protocol="rtde", cycle_period_ns=8_000_000))
    who = DASHBOARD + "127.0.0.1:5000"

    def feed(data: bytes, frame_id: str = who) -> list[tuple[str, bytes]]:
        outs = core._on_rtde(0, pb.SerialChunk(header=pb.Header(frame_id=frame_id), data=data))
        return [(m.header.frame_id, bytes(m.data)) for t, m in outs if t == "serial_tx"]

    assert feed(b"") == [(who, (GREETING + "\n").encode())]  # the connection's mark: greeted
    assert feed(b"runn") == []  # (half a line)
    assert feed(b"ing\nstop\n") == [(who, b"Program running: True\nStopped\n")]
    assert not core.robot.program_running and core.robot.counters["program_stops"] == 1
    assert core.session.sid in core.robot.sessions  # the RTDE clients' sessions untouched
    assert feed(b"quit\n") == [(who, b"Disconnected\n"), (who, b"")]  # answered, then closed
    assert who not in core.dashboards
    assert feed(b"") and feed(b"x" * 5000) == [(who, b"")]  # not a Dashboard client: dropped
    assert core.robot.counters["malformed"] == 1 and "bad_dashboard" in [e.code for e in core.robot.events]
    assert feed(b"", who + CLOSED) == [] and who not in core.dashboards


def test_the_gateway_reads_the_stop_from_rtde_holds_and_comes_back_without_a_jump(sim_rig):  # noqa: F811
    rig, sim = sim_rig, sim_rig.robot.sim
    for _ in range(40):
        rig.cycle_with_command(dp_mm=(0.5, 0.0, 0.0))  # 62.5 mm/s
    dash = DashboardSession(sim, "pendant")
    assert dash.feed(b"stop\n", 0) == b"Stopped\n"
    at_stop = sim.base_T_flange_mm
    for _ in range(30):
        rig.cycle_with_command(dp_mm=(0.5, 0.0, 0.0))  # the controller goes on commanding
    codes = rig.codes()
    downs = [e.text for e in rig.events() if e.code == "link_down"]
    assert len(downs) == 1 and "program stopped" in downs[0]
    rest = sim.base_T_flange_mm
    # braked along its path from 62.5 mm/s at 1 m/s^2 (v^2 / 2a = 1.95 mm), then still
    assert 0.0 < rest[0, 3] - at_stop[0, 3] <= 62.5 ** 2 / 2000.0
    np.testing.assert_allclose(rest[1:3, 3], at_stop[1:3, 3], atol=1e-6)
    # the gateway's targets while stopped: the arm (no old target waits in the registers)
    target = rtde.transform_from_ur_pose([sim.inputs[f"input_double_register_{24 + i}"] for i in range(6)])
    np.testing.assert_allclose(target[:3, 3], rest[:3, 3], atol=1e-6)
    assert dash.feed(b"play\n", 0) == b"Starting program\n"
    track = [sim.base_T_flange_mm[:3, 3]]
    for _ in range(30):
        rig.cycle_with_command(dp_mm=(0.5, 0.0, 0.0))
        track.append(sim.base_T_flange_mm[:3, 3])
    assert rig.codes()[len(codes):].count("link_up") == 1
    assert "plays again" in [e.text for e in rig.events() if e.code == "link_up"][-1]
    steps = np.linalg.norm(np.diff(track, axis=0), axis=1)
    assert steps.max() <= 0.5 + 1e-6  # no jump: never more than the commanded step a cycle
    assert track[-1][0] - track[0][0] > 5.0  # and it moves on
    assert not any(c in ("robot_fault", "fault") for c in rig.codes())


DASHBOARD_CLIENT = r"""
import json, sys
import dashboard_client
d = dashboard_client.DashboardClient("127.0.0.1", int(sys.argv[1]))
d.connect()
out = [d.isConnected(), d.programState(), d.running(), d.robotmode(), d.safetystatus(), d.polyscopeVersion(),
       d.getLoadedProgram(), d.isProgramSaved()]
d.stop()
out += [d.running(), d.programState()]
d.play()
out += [d.running(), d.programState()]
d.closeSafetyPopup()
d.disconnect()
print(json.dumps(out))
"""


def test_ur_rtdes_dashboard_client_stops_and_plays_the_simulated_ur():
    import dashboard_client  # noqa: F401  (ur_rtde is in [test]: a broken install fails, not skips)
    robot = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=2.0)
    server = RtdeServer(robot, "127.0.0.1:0", dashboard="127.0.0.1:0").start()
    try:
        p = subprocess.run([sys.executable, "-c", DASHBOARD_CLIENT, str(server.dashboard_address[1])],
                           capture_output=True, text=True, timeout=120)
    finally:
        server.close()
    assert p.returncode == 0, p.stderr[-2000:]
    got = json.loads(p.stdout.strip().splitlines()[-1])
    assert got == [True, "PLAYING humanpt_ur.urp", True, "Robotmode: RUNNING", "Safetystatus: NORMAL",
                   "5.11.0.0", "Loaded program: humanpt_ur.urp", False,  # (ur-rtde looks for "True": a CB3's)
                   False, "STOPPED humanpt_ur.urp", True, "PLAYING humanpt_ur.urp"]
    assert robot.counters["program_stops"] == 1 and robot.counters["program_starts"] == 1
    assert robot.counters["malformed"] == 0
