"""Gateway + sim_robot + a scripted controller in lock-step, over a serial line with 8N1 byte
timing: the flange path is the integral of the clamped commands; every hold ends in zero."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.runtime.core import Core, Port
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.replay import factory_with, replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header, vector3
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import SimRobotCore
from humanpt.testing.harness import (
    ScriptedControllerConfig,
    ScriptedControllerCore,
    scripted_step,
)
from tests.robot_gateway.oracle import (
    LIMIT_DEG,
    LIMIT_MM,
    assert_wire_correction,
    clamped,
    wire_rotation,
    wire_translation_mm,
)

MS = 1_000_000
CYCLE_NS = 28 * MS


def _run(
    n_cycles=400,
    baud=38_400,
    gw=None,
    sim=None,
    ctl=None,
    run_dir=None,
    actions=(),
    latency_ns=1 * MS,
):
    gateway = GatewayCore(gw or AlterConfig(baud=baud))
    robot = SimRobotCore(sim or SimRobotConfig())
    controller = (
        ctl if isinstance(ctl, Core) else ScriptedControllerCore(ctl or ScriptedControllerConfig())
    )
    ls = Lockstep([robot, gateway, controller], latency_ns=latency_ns, run_dir=run_dir)
    lines = ls.connect_serial("robot_gateway", "sim_robot", baud)
    end = n_cycles * CYCLE_NS
    for t_ns, action in sorted(actions, key=lambda a: a[0]):
        ls.run_until(t_ns)
        action(ls, lines)
    ls.run_until(end)
    ls.close()
    return ls, gateway, robot


def _events(ls, source=None):
    return [
        pb.Event.FromString(o.data)
        for o in ls.outputs
        if o.topic.endswith("/events") and (source is None or o.component == source)
    ]


def _truths(ls) -> list[np.ndarray]:
    out = []
    for o in ls.outputs:
        if o.topic == "sim_robot/truth":
            T = from_pose(pb.Truth.FromString(o.data).world_T_flange)
            T[:3, 3] *= 1000.0
            out.append(T)
    return out


def _integrate(T0: np.ndarray, applied, n_truths: int) -> list[np.ndarray]:
    """World-mode integral: truth i (cycle i + 1) = T0 moved by every correction applied
    at cycle boundaries <= i."""
    by_cycle: dict[int, list] = {}
    for cycle, c in applied:
        by_cycle.setdefault(cycle, []).append(c)
    T = T0.copy()
    out = [T.copy()]
    for i in range(1, n_truths):
        for c in by_cycle.get(i, ()):
            T[:3, :3] = wire_rotation(c).as_matrix() @ T[:3, :3]  # world mode, about the flange
            T[:3, 3] += wire_translation_mm(c)
        out.append(T.copy())
    return out


def test_the_flange_path_is_the_integral_of_the_clamped_commands():
    ls, gw, sim = _run(n_cycles=400)
    cfg = ScriptedControllerConfig()
    # Every status answered on time with its own command; every correction applied on time.
    assert gw.counters["statuses"] >= 395 and gw.counters["fresh"] == gw.counters["statuses"]
    assert gw.counters["zero"] == gw.counters["reused"] == 0
    assert sim.counters["missed"] == 0 and sim.counters["applied_on_time"] == len(gw.sent)
    assert gw.counters["clamped"] > 50  # the script exceeds the limits at its peaks
    # What was sent = the commands, clamped by norm and angle to the limits, rounded.
    for s in gw.sent:
        dp, rv = scripted_step(s.cycle, cfg)
        assert s.correction.echo_cycle == s.cycle
        assert_wire_correction(s.correction, dp, rv, LIMIT_MM, LIMIT_DEG)
    # What was applied = what was sent, in order.
    assert [c for _, c in sim.applied] == [s.correction for s in gw.sent]
    # The flange path = the integral of the applied corrections (exact to float rounding).
    truths = _truths(ls)
    expected = _integrate(truths[0], sim.applied, len(truths))
    for T, E in zip(truths, expected, strict=True):
        np.testing.assert_allclose(T[:3, 3], E[:3, 3], atol=1e-6)
        np.testing.assert_allclose(T[:3, :3], E[:3, :3], atol=1e-9)
    travelled = np.linalg.norm(np.diff([T[:3, 3] for T in truths], axis=0), axis=1)
    assert travelled.max() <= 2.8 + 1e-6 and travelled.sum() > 300.0
    # The gateway's robot state is the truth to the wire resolution (0.01 mm).
    states = [
        pb.RobotState.FromString(o.data)
        for o in ls.outputs
        if o.topic == "robot_gateway/robot_state"
    ]
    assert len(states) >= 395
    for st in states[-50:]:
        T = from_pose(st.world_T_flange)
        np.testing.assert_allclose(
            T[:3, 3] * 1000.0, truths[st.cycle - 1][:3, 3], atol=0.0051 * np.sqrt(3)
        )
    # The events: clamping, rate-limited (about one a second).
    codes = [e.code for e in _events(ls, "robot_gateway")]
    assert set(codes) == {"clamped"} and len(codes) <= 13


def test_byte_timing_makes_the_reply_arrive_within_the_cycle_at_38400_and_late_at_19200():
    ls, gw, sim = _run(n_cycles=100, baud=38_400)
    rx = [o.t_ns for o in ls.outputs if o.topic == "robot_gateway/robot_state"]
    # STATUS takes 41 bytes x 10 bits / 38400 = 10.68 ms on the wire.
    assert {t % CYCLE_NS for t in rx} == {10_677_084}
    ls, gw, sim = _run(n_cycles=200, baud=19_200)
    assert sim.counters["applied_late"] >= 190 and sim.counters["applied_on_time"] == 0
    assert sim.counters["missed"] <= 1  # only before the first correction
    truths = _truths(ls)
    expected = _integrate(truths[0], sim.applied, len(truths))
    np.testing.assert_allclose(truths[-1], expected[-1], atol=1e-6)


def test_tool_mode_robot_follows_world_commands():
    ls, gw, sim = _run(n_cycles=200, sim=SimRobotConfig(alter_mode="tool"))
    cfg = ScriptedControllerConfig()
    truths = _truths(ls)
    by_cycle = {s.cycle: s for s in gw.sent}
    for i in range(5, len(truths) - 1):  # world step of the truth = the clamped world command
        s = by_cycle.get(i)
        if s is None:
            continue
        dp, _ = scripted_step(s.cycle, cfg)
        np.testing.assert_allclose(
            truths[i][:3, 3] - truths[i - 1][:3, 3], clamped(dp, LIMIT_MM), atol=0.02
        )


def test_same_run_twice_is_identical_and_the_recordings_replay(tmp_path):
    a, _, _ = _run(n_cycles=120, run_dir=tmp_path)
    b, _, _ = _run(n_cycles=120)
    assert a.digest() == b.digest()
    for comp in ("robot_gateway", "sim_robot", "controller"):
        res = replay(tmp_path / f"{comp}.mcap", core_factory=factory_with(ScriptedControllerCore))
        # Each answers (nearly) every one of the 120 ALTER cycles.
        assert res.match and res.compared >= 100, res.report()


def test_a_silent_controller_is_reused_then_zero_and_a_long_silence_holds_and_resumes_by_itself():
    # Silent for 5 cycles: 3 reused (velocity hold), 2 zero, no fault.
    ls, gw, sim = _run(n_cycles=150, ctl=ScriptedControllerConfig(mute=((100, 104),)))
    sources = {s.cycle: s.source for s in gw.sent}
    assert [sources[c] for c in range(99, 106)] == [
        "fresh",
        "reused",
        "reused",
        "reused",
        "stale",
        "stale",
        "fresh",
    ]
    codes = [e.code for e in _events(ls, "robot_gateway")]
    assert "stale_command" in codes and "command_resumed" in codes and "fault" not in codes
    truths = _truths(ls)
    # truths[k] follows the correction for cycle k: cycles 103 and 104 got zero, no motion.
    assert np.ptp([T[:3, 3] for T in truths[102:105]], axis=0).max() < 1e-9
    assert np.linalg.norm(truths[102][:3, 3] - truths[101][:3, 3]) > 1.0  # 102 was a reused step

    # Silent for 30 cycles (a partition, a stalled controller): held from the 4th, no
    # fault, ALTER stays on; the controller's commands from cycle 130 on move it again by
    # themselves (issue 19's policy: a silent controller is held, not faulted).
    ls, gw, sim = _run(n_cycles=220, ctl=ScriptedControllerConfig(mute=((100, 129),)))
    gw_codes = [e.code for e in _events(ls, "robot_gateway")]
    sim_codes = [e.code for e in _events(ls, "sim_robot")]
    assert "fault" not in gw_codes and gw_codes.count("controller_silent") == 1
    assert "alter_off" not in sim_codes
    resumed = [e for e in _events(ls, "robot_gateway") if e.code == "command_resumed"]
    assert resumed and "resumed by itself" in resumed[-1].text
    truths = _truths(ls)
    still = [T[:3, 3] for T in truths[103:130]]
    assert np.ptp(still, axis=0).max() < 1e-9  # held while silent
    assert np.linalg.norm(truths[-1][:3, 3] - truths[131][:3, 3]) > 10.0  # moving again


def test_liveliness_loss_holds_at_once_and_return_resumes():
    def gone(ls, lines):
        ls.inject(
            ls.now_ns,
            "robot_gateway",
            "liveliness",
            pb.Liveliness(header=header(ls.now_ns), component="controller", alive=False),
        )

    def back(ls, lines):
        ls.inject(
            ls.now_ns,
            "robot_gateway",
            "liveliness",
            pb.Liveliness(header=header(ls.now_ns), component="controller", alive=True),
        )

    ls, gw, sim = _run(
        n_cycles=200, actions=[(100 * CYCLE_NS + 20 * MS, gone), (150 * CYCLE_NS + 20 * MS, back)]
    )
    sources = {s.cycle: s.source for s in gw.sent}
    # Gone at 100 cycles + 20 ms (cycle 101 was answered at 12.7 ms), back at 150 cycles + 20 ms
    # (cycle 151 was answered at 10.7 ms, still gone).
    assert sources[101] == "fresh" and {sources[c] for c in range(102, 152)} == {"gone"}
    assert {sources[c] for c in range(152, 195)} == {"fresh"}
    truths = _truths(ls)
    assert np.ptp([T[:3, 3] for T in truths[102:152]], axis=0).max() < 1e-9
    codes = [e.code for e in _events(ls, "robot_gateway")]
    assert (
        codes.count("controller_gone") == 1
        and codes.count("controller_back") == 1
        and "fault" not in codes
    )


def test_a_cut_line_is_link_down_on_both_ends_the_robot_holds_and_the_link_recovers():
    def cut(ls, lines):
        for line in lines:
            line.enabled = False

    def mend(ls, lines):
        for line in lines:
            line.enabled = True

    ls, gw, sim = _run(n_cycles=300, actions=[(100 * CYCLE_NS, cut), (150 * CYCLE_NS, mend)])
    gw_codes = [e.code for e in _events(ls, "robot_gateway")]
    sim_codes = [e.code for e in _events(ls, "sim_robot")]
    assert "link_down" in gw_codes and "link_up" in gw_codes
    assert "link_down" in sim_codes and "correction_missed" in sim_codes
    truths = _truths(ls)
    assert np.ptp([T[:3, 3] for T in truths[101:150]], axis=0).max() < 1e-9  # held while cut
    assert gw.fault is None
    late = [s for s in gw.sent if s.cycle > 200]
    assert len(late) > 90 and {s.source for s in late} == {"fresh"}
    expected = _integrate(truths[0], sim.applied, len(truths))
    np.testing.assert_allclose(truths[-1], expected[-1], atol=1e-6)


class _PushOut(Core):
    """A controller that always commands +50 mm per cycle along x (clamped to 2.8)."""

    name = "controller"
    config_type = ScriptedControllerConfig
    ports = (Port("robot_gateway/robot_state", pb.RobotState, "_on_robot_state"),)

    def _on_robot_state(self, t_ns, msg):
        cmd = pb.FlangeCommand(
            header=self.next_header("controller/command", t_ns, "world"),
            cycle=msg.cycle,
            d_translation_m=vector3([0.05, 0.0, 0.0]),
            mode=pb.CONTROL_MODE_TRACK,
        )
        return [("controller/command", cmd)]


def test_pushing_out_of_reach_faults_the_robot_which_stops_and_the_gateway_holds():
    ls, gw, sim = _run(n_cycles=320, ctl=_PushOut(ScriptedControllerConfig()))
    assert sim.fault is not None
    sim_codes = [e.code for e in _events(ls, "sim_robot")]
    gw_codes = [e.code for e in _events(ls, "robot_gateway")]
    assert "fault" in sim_codes and "robot_fault" in gw_codes
    truths = _truths(ls)
    x = [T[0, 3] for T in truths]
    stop = 5 + int(np.argmax(np.diff(x[5:]) < 1e-9)) + 1
    assert 150 < stop < 300 and np.ptp(x[stop:]) < 1e-9
    after = [s.source for s in gw.sent if s.cycle > stop + 2]
    assert len(after) >= 10 and set(after) == {"robot_fault"}


def test_the_envelope_stops_the_flange_at_its_wall():
    x0 = 786.02
    ls, gw, sim = _run(
        n_cycles=120,
        ctl=_PushOut(ScriptedControllerConfig()),
        gw=AlterConfig(envelope_max_mm=(x0 + 100.0, 1600.0, 1600.0)),
    )
    truths = _truths(ls)
    assert truths[-1][0, 3] == pytest.approx(x0 + 100.0, abs=0.02)
    assert "envelope" in [e.code for e in _events(ls, "robot_gateway")]
    assert sim.fault is None


def test_lockstep_serial_line_timing_is_sequential():
    ls, gw, sim = _run(n_cycles=3)
    g2s, s2g = ls._lines[1][0][0], ls._lines[0][0][0]
    assert g2s.src == "robot_gateway" and s2g.src == "sim_robot"
    assert g2s.wire_time_ns(29) == 7_552_084 and g2s.bytes_carried > 0 and s2g.bytes_carried > 0


def test_rotation_integral_uses_world_frame_composition():
    # A sanity check of the helper itself: two rotations about different axes do not commute.
    from humanpt.robot_gateway.links.alter import Correction

    T0 = np.eye(4)
    a = Correction.from_mm_deg(1, np.zeros(3), np.array([1.0, 0, 0]))
    b = Correction.from_mm_deg(2, np.zeros(3), np.array([0, 1.0, 0]))
    out = _integrate(T0, [(1, a), (2, b)], 3)
    Rb = Rotation.from_euler("ZYX", [0, 1.0, 0], degrees=True).as_matrix()
    Ra = Rotation.from_euler("ZYX", [0, 0, 1.0], degrees=True).as_matrix()
    np.testing.assert_allclose(out[2][:3, :3], Rb @ Ra, atol=1e-12)
