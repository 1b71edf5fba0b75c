"""The simulated EGM controller's count of cycles answered in time (what `humanpt demo --link
abb` prints), and its communication timeout as the sim_robot component runs it (from the
sensor's first answer: the RAPID program is started once humanpt is up)."""

from __future__ import annotations

from humanpt.robot_gateway.links.abb.protocol import EgmTarget, decode_robot, encode_sensor
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.egm import EgmRobot

MS = 1_000_000


def _answer(robot_msg: bytes) -> bytes:
    st = decode_robot(robot_msg)
    return encode_sensor(EgmTarget(st.seqno, st.tm_ms, st.pos_mm, st.quat_wxyz))


def test_cycles_answered_in_time_late_and_waiting():
    r = EgmRobot.from_config(SimRobotConfig(protocol="egm", cycle_period_ns=4 * MS))
    m = r.cycle(0)  # cycle 1: no answer (the sensor not up yet): waiting
    m = r.cycle(4 * MS)  # cycle 2: answered after 0.5 ms: in time
    r.receive(_answer(m), int(4.5 * MS))
    m = r.cycle(8 * MS)  # cycle 3: answered after 3.9 ms: in time
    r.receive(_answer(m), 8 * MS, arrived_ns=int(11.9 * MS))
    m = r.cycle(12 * MS)  # cycle 4: nothing: late
    m = r.cycle(16 * MS)  # cycle 5: answered after 4.5 ms: late
    r.receive(_answer(m), int(20.5 * MS))
    m = r.cycle(20 * MS)  # cycle 6: handled by a busy process 3.5 ms late, but it arrived after 1 ms
    r.receive(_answer(m), int(23.5 * MS), arrived_ns=21 * MS)
    r.cycle(24 * MS)
    r.finish(26 * MS)  # cycle 7: not answered: late
    assert {k: r.counters[k] for k in ("cycles", "waiting", "on_time", "late")} == \
        {"cycles": 7, "waiting": 1, "on_time": 3, "late": 3}
    hist = r.latency_histogram()  # 0.5, 3.9 and 1 ms; the late ones
    assert (hist["<=0.5 ms"], hist["<=1 ms"], hist["<=4 ms"], hist["late"]) == (1, 1, 1, 3)


def test_the_component_s_timeout_runs_from_the_sensor_s_first_answer():
    r = EgmRobot.from_config(SimRobotConfig(protocol="egm", cycle_period_ns=4 * MS, egm_comm_timeout_s=0.1))
    for k in range(100):  # 0.4 s without a sensor: still waiting, still sending
        m = r.cycle(k * 4 * MS)
        assert m is not None
    r.receive(_answer(m), 400 * MS)
    assert r.cycle(404 * MS) is not None and r.cycle(500 * MS) is not None  # 0.1 s since the answer: not over
    assert r.cycle(501 * MS) is None and "no EgmSensor for 0.101 s" in r.stopped
    # (the pure core's default: counted from the start, as the link's tests use it)
    r0 = EgmRobot(SimRobotConfig(), comm_timeout_s=0.1)
    assert r0.cycle(0) is not None and r0.cycle(101 * MS) is None
