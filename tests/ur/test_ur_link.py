"""The gateway over UR RTDE against the simulated controller's RTDE session (the real codec
on both ends, in memory): the set-up, the targets in the input registers, the arm following
them, the program's watchdog; malformed and foreign bytes refused."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.robot_gateway.link import CycleReceived, LinkError, LinkUp, Transmit
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.robot_gateway.links.ur.link import UrLink
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.ur import UrRobot
from tests.robot_gateway import rig as rigmod
from tests.robot_gateway.test_one_rule_set import run_rule_set

MS = 1_000_000


def test_the_rule_sets_answers_are_targets_in_the_input_registers():
    rig = run_rule_set("ur")
    got = rig.corrections
    seqs = [v["input_int_register_24"] for _, v in got]
    assert seqs == list(range(1, 15))  # one new sequence number per cycle, holds too
    x_m = {c: v["input_double_register_24"] for c, v in got}
    # The start x is 786 mm; +0.5 mm, +0.5 mm, then +0.5 mm pulled back to the 1 mm lead.
    assert x_m[1] == pytest.approx(0.7865, abs=1e-12)
    assert x_m[2] == pytest.approx(0.7870, abs=1e-12)
    assert x_m[3] == pytest.approx(0.7870, abs=1e-12)
    assert x_m[8] == x_m[7]  # a hold (cycle 8: stale) repeats the target
    for _, v in got:  # never more than the 1 mm lead from the fed-back pose (the start: the rig's arm stays)
        p = np.array([v[f"input_double_register_{24 + i}"] for i in range(3)]) * 1000.0
        assert np.linalg.norm(p - rigmod.START_X[:3]) <= 1.0 + 1e-9


class SimUr:
    """The rig's robot side made of the simulated controller: its arm moves (the rig's pose is
    not used), its cycle runs once per status."""

    fields: dict = {}

    def __init__(self, config):
        self.sim = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=config.cycle_period_ms, trace_cycles=1000)
        self.session = self.sim.connect()
        self.t_ns = 0

    def begin(self, t_ns):
        return [b""]

    def send(self, cycle, base_T_flange_mm, bits, t_ns):
        out = self.sim.cycle(t_ns)
        return [out[self.session.sid]] if self.session.sid in out else []

    def take(self, data, t_ns):
        before = self.sim.counters["input_packages"]
        back = self.session.feed(data, t_ns)
        return ([back] if back else []), ([(0, None)] if self.sim.counters["input_packages"] > before else [])


@pytest.fixture
def sim_rig(monkeypatch):
    monkeypatch.setitem(rigmod.ROBOTS, "ur", SimUr)
    cfg = gateway_config("ur", cycle_period_ms=8.0, tick_ms=2.0, reply_deadline_ms=2.0)
    return rigmod.Rig(cfg)


def test_the_arm_follows_the_controllers_steps_and_stops_when_the_gateway_goes_silent(sim_rig):
    rig, sim = sim_rig, sim_rig.robot.sim
    assert sim.controller_version[0] == 3  # 8 ms: the CB3's 125 Hz
    start = sim.base_T_flange_mm
    for _ in range(40):
        rig.cycle_with_command(dp_mm=(0.5, 0.0, 0.0))
    for _ in range(60):
        rig.cycle_with_command(mode=pb.CONTROL_MODE_HOLD)
    assert rig.gw.link.counters["sessions"] == 1 and "link_error" not in rig.codes()
    # 40 x 0.5 mm = 20 mm in +x; the servo's lag (62.5 mm/s x 20 ms = 1.25 mm) is under the
    # 5 mm lead, so the target was never pulled back; 60 holds bring the arm onto it.
    moved = sim.base_T_flange_mm[:3, 3] - start[:3, 3]
    np.testing.assert_allclose(moved, (20.0, 0.0, 0.0), atol=1e-3)
    np.testing.assert_allclose(sim.base_T_flange_mm[:3, :3], start[:3, :3], atol=1e-9)
    assert sim.counters["watchdog_stops"] == 0 and not sim.stopped
    # The gateway goes silent (a cut cable): the program's watchdog stops the arm after 25 cycles.
    rig.robot_connected = False
    at = sim.base_T_flange_mm
    for k in range(1, 30):
        sim.cycle(k * 8 * MS)
        # (cycle 1 takes the gateway's last answer; 2..26 are the 25 cycles without a new one)
        assert sim.stopped == (k >= 26)
    assert sim.counters["watchdog_stops"] == 1
    np.testing.assert_allclose(sim.base_T_flange_mm, at, atol=1e-9)
    # An old target (the start, 20 mm away) with a newer sequence: not followed.
    seq = sim._last_seq
    sim.inputs.update({"input_int_register_24": seq + 1,
                       **{f"input_double_register_{24 + i}": v for i, v in
                          enumerate(rtde.ur_pose_from_transform(start))}})
    for _ in range(10):
        sim.cycle(0)
    assert sim.stopped and sim.counters["refused_resumes"] == 1
    np.testing.assert_allclose(sim.base_T_flange_mm, at, atol=1e-9)
    # A target 1 mm from the arm with a newer sequence: followed again.
    near = at.copy()
    near[0, 3] += 1.0
    sim.inputs.update({"input_int_register_24": seq + 2,
                       **{f"input_double_register_{24 + i}": v for i, v in
                          enumerate(rtde.ur_pose_from_transform(near))}})
    sim.cycle(0)
    assert not sim.stopped and sim.counters["moved"] > 0


def _session(link: UrLink, sim: UrRobot):
    """The link's set-up against the simulated controller's session: the link's events."""
    session = sim.connect()
    events = link.receive(b"", 0)
    while True:
        sent = b"".join(e.data for e in events if isinstance(e, Transmit))
        if not sent:
            return session, events
        back = session.feed(sent, 0)
        events = link.receive(back, 0) if back else []


def test_the_link_sets_up_outputs_and_inputs_and_reads_the_state():
    link = UrLink.from_config(gateway_config("ur"))
    sim = UrRobot(SimRobotConfig(model="ur5e"))
    session, _ = _session(link, sim)
    assert session.started and session.outputs.names == link.outputs and session.every == 1
    assert sim.input_owner == dict.fromkeys(link.inputs, session.sid)
    events = link.receive(sim.cycle(2 * MS)[session.sid], 2 * MS)
    assert isinstance(events[0], LinkUp)
    st = events[1].state
    assert st.cycle == 1 and st.corrections_on and st.arm_power and not st.fault
    np.testing.assert_allclose(st.base_T_flange_mm, sim.base_T_flange_mm, atol=1e-9)


def test_registers_another_client_holds_refuse_the_session():
    sim = UrRobot(SimRobotConfig(model="ur5e"))
    _session(UrLink.from_config(gateway_config("ur")), sim)
    second = UrLink.from_config(gateway_config("ur"))
    session, events = _session(second, sim)
    assert not session.started and not second.is_running
    (err,) = [e for e in events if isinstance(e, LinkError)]
    assert "IN_USE" in err.text and "input_int_register_24" in err.text


def test_a_cb3_is_refused_a_500_hz_cycle():
    sim = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=8.0)
    link = UrLink.from_config(gateway_config("ur", cycle_period_ms=2.0))
    _, events = _session(link, sim)
    (err,) = [e for e in events if isinstance(e, LinkError)]
    assert "CB3" in err.text and "125 Hz" in err.text


@pytest.mark.parametrize("junk, what", [
    (b"\xff\xff\x00\x01", "size 65535"),  # not RTDE's header
    (b"\x00\x04Z\x00", "type 90"),  # not an RTDE packet type
])
def test_foreign_bytes_are_refused_and_the_stream_continues(junk, what):
    link = UrLink.from_config(gateway_config("ur"))
    sim = UrRobot(SimRobotConfig(model="ur5e"))
    session, _ = _session(link, sim)
    link.receive(sim.cycle(2 * MS)[session.sid], 2 * MS)
    events = link.receive(junk + sim.cycle(4 * MS)[session.sid], 4 * MS)
    errors = [e.text for e in events if isinstance(e, LinkError)]
    assert len(errors) == 1 and what in errors[0]
    assert [e.state.cycle for e in events if isinstance(e, CycleReceived)] == [2]


def test_a_data_package_with_a_pose_that_is_not_a_number_is_dropped():
    link = UrLink.from_config(gateway_config("ur"))
    sim = UrRobot(SimRobotConfig(model="ur5e"))
    session, _ = _session(link, sim)
    values = sim.outputs()
    values["actual_TCP_pose"] = (float("nan"),) * 6
    events = link.receive(session.outputs.encode({n: values[n] for n in session.outputs.names}), 0)
    assert not any(isinstance(e, CycleReceived) for e in events)
    assert "6 finite numbers" in [e for e in events if isinstance(e, LinkError)][0].text


def test_a_cycle_that_does_not_advance_is_dropped():
    link = UrLink.from_config(gateway_config("ur"))
    sim = UrRobot(SimRobotConfig(model="ur5e"))
    session, _ = _session(link, sim)
    first = sim.cycle(2 * MS)[session.sid]
    link.receive(first, 2 * MS)
    events = link.receive(first, 4 * MS)  # the same timestamp again (replayed)
    assert not any(isinstance(e, CycleReceived) for e in events)
    assert "not after the last" in events[0].text


def test_corrections_are_off_when_the_program_stops_or_its_heartbeat_stalls():
    link = UrLink.from_config(gateway_config("ur", heartbeat_cycles=3))
    sim = UrRobot(SimRobotConfig(model="ur5e"))
    session, _ = _session(link, sim)

    def state(heartbeat=None, **over):
        sim.cycles += 1
        values = sim.outputs()
        values.update(over)
        if heartbeat is not None:
            values["output_int_register_24"] = heartbeat
        data = session.outputs.encode({n: values[n] for n in session.outputs.names})
        return [e.state for e in link.receive(data, 0) if isinstance(e, CycleReceived)][0]

    assert state(heartbeat=1).corrections_on
    # the heartbeat stuck at 1: cycles 2 and 3 are within 3 cycles of its last change, 4 is not
    assert [state(heartbeat=1).corrections_on for _ in range(3)] == [True, True, False]
    assert state(heartbeat=2).corrections_on  # it advances again
    assert not state(heartbeat=3, runtime_state=rtde.RUNTIME_STOPPED).corrections_on  # Stop pressed
    st = state(heartbeat=4, safety_mode=rtde.SAFETY_MODE_PROTECTIVE_STOP, robot_mode=5)
    assert st.fault and not st.arm_power


def test_states_read_together_keep_the_controllers_own_times():
    """A TCP read holding several data packages (a stalled stream delivered at once, as at
    500 Hz on a busy host): each robot state is stamped at the read's time less its age by
    the controller's timestamps (2 ms apart at 500 Hz), not all at the read's time, which the
    pose filter took for a clock standing still (35 robot_clock_resets in a live 2 ms demo)."""
    rig = rigmod.Rig(link="ur")
    rig.advance(2 * MS)
    rig.status()  # the session's first state (LinkUp)
    before = len(rig.states())
    k = rig.cycle
    packages = b"".join(chunk for c in (k + 1, k + 2, k + 3)
                        for chunk in rig.robot.send(c, rig.base_T_flange, rig.bits, rig.t_ns))
    rig.cycle = k + 3
    rig.t_ns += 7 * MS  # they arrive together, 1 ms after the newest was sampled
    rig.from_robot(packages)
    stamps = [s.header.stamp_ns for s in rig.states()[before:]]
    delay = round(rig.gw.config.status_delay_ms * 1e6)
    assert stamps == [rig.t_ns - delay - 4 * MS, rig.t_ns - delay - 2 * MS, rig.t_ns - delay]
    # one package per read ages nothing (every link's states as before)
    events = UrLink.from_config(gateway_config("ur")).receive(b"", 0)
    assert all(getattr(e, "age_ns", 0) == 0 for e in events)
