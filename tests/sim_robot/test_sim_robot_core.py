"""The sim_robot core on scripted inputs: its cycle, world/tool ALTER, faults, truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry.transforms import transform_from_x, x_from_transform
from humanpt.robot_gateway.links.alter import (
    Correction,
    CorrectionFlags,
    HostEndpoint,
    StatusBits,
    StatusReceived,
    Transmit,
)
from humanpt.robot_gateway.links.alter.messages import NO_FLAGS
from humanpt.runtime.config import ConfigError, build
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import SimRobotCore

MS = 1_000_000
CYCLE_NS = 28 * MS


class SimRig:
    """SimRobotCore <-> a pure HostEndpoint, bytes crossing instantly."""

    def __init__(self, **kw):
        self.sim = SimRobotCore(SimRobotConfig(**kw))
        self.host = HostEndpoint()
        self.t_ns = 0
        self.outs: list = []
        self.statuses = []
        self.connected = True
        self._host(self.host.start(0))
        self.tick()

    def _host(self, events) -> None:
        for e in events:
            if isinstance(e, Transmit) and self.connected:
                self.step("serial_rx", pb.SerialChunk(header=header(self.t_ns), data=e.data))
            elif isinstance(e, StatusReceived):
                self.statuses.append(e.status)

    def step(self, topic, msg) -> list:
        outs = self.sim.step(self.t_ns, topic, msg)
        self.outs += outs
        for t, m in outs:
            if t == "serial_tx" and self.connected:
                self._host(self.host.receive(m.data, self.t_ns))
        return outs

    def tick(self) -> list:
        outs = self.step("tick", pb.Tick(header=header(self.t_ns)))
        self.t_ns += CYCLE_NS
        return outs

    def correct(self, dp_mm=(0, 0, 0), r_deg=(0, 0, 0), flags=NO_FLAGS, cycle=None) -> None:
        c = Correction.from_mm_deg(
            self.statuses[-1].cycle if cycle is None else cycle,
            np.array(dp_mm, float),
            np.array(r_deg, float),
            flags,
        )
        self._host(self.host.send_correction(c, self.t_ns))

    def truths(self) -> list[pb.Truth]:
        return [m for t, m in self.outs if t == "sim_robot/truth"]

    def world_T_flange_mm(self) -> np.ndarray:
        T = from_pose(self.truths()[-1].world_T_flange)
        T[:3, 3] *= 1000.0
        return T

    def codes(self) -> list[str]:
        return [m.code for t, m in self.outs if t == "sim_robot/events"]


def test_each_cycle_sends_status_and_truth_stamped_at_the_cycle():
    rig = SimRig()
    for _ in range(5):
        rig.tick()
    assert [s.cycle for s in rig.statuses] == [
        2,
        3,
        4,
        5,
        6,
    ]  # cycle 1 went out before the link was up
    truths = rig.truths()
    assert [t.header.stamp_ns for t in truths] == [i * CYCLE_NS for i in range(6)]
    assert all(t.header.frame_id == "world" for t in truths)
    s = rig.statuses[-1]
    assert (
        s.bits & StatusBits.ALTER_ACTIVE
        and s.bits & StatusBits.ARM_POWER
        and not s.bits & StatusBits.TOOL_MODE
    )
    np.testing.assert_allclose(s.position_mm, [786.02, 190.0, -295.96], atol=0.01)
    np.testing.assert_allclose(rig.world_T_flange_mm(), rig.sim.base_T_flange_mm, atol=1e-9)


def test_world_mode_moves_the_flange_in_the_base_frame_about_its_origin():
    rig = SimRig()
    rig.tick()
    T0 = rig.sim.base_T_flange_mm
    rig.correct((1.0, -2.0, 0.5), (0.0, 0.0, 1.5))
    rig.tick()
    T1 = rig.sim.base_T_flange_mm
    np.testing.assert_allclose(T1[:3, 3], T0[:3, 3] + [1.0, -2.0, 0.5], atol=1e-9)
    dR = Rotation.from_euler("ZYX", [1.5, 0, 0], degrees=True).as_matrix()
    np.testing.assert_allclose(T1[:3, :3], dR @ T0[:3, :3], atol=1e-9)
    assert rig.sim.counters["applied_on_time"] == 1


def test_tool_mode_applies_the_step_in_the_flange_frame():
    rig = SimRig(alter_mode="tool")
    rig.tick()
    assert rig.statuses[-1].bits & StatusBits.TOOL_MODE
    T0 = rig.sim.base_T_flange_mm
    rig.correct((0.0, 0.0, 2.0), (0.5, 0.0, 0.0))  # 2 mm along the flange z (down)
    rig.tick()
    delta = np.eye(4)  # the step in the flange frame: 0.5 deg about x, 2 mm along z
    delta[:3, :3] = Rotation.from_euler("ZYX", [0.0, 0.0, 0.5], degrees=True).as_matrix()
    delta[:3, 3] = [0.0, 0.0, 2.0]
    np.testing.assert_allclose(rig.sim.base_T_flange_mm, T0 @ delta, atol=1e-9)
    assert rig.sim.base_T_flange_mm[2, 3] == pytest.approx(T0[2, 3] - 2.0)


def test_no_correction_holds_and_flags_correction_missed():
    rig = SimRig()
    rig.tick()
    T0 = rig.sim.base_T_flange_mm
    rig.tick()  # nothing arrived during the cycle
    assert rig.statuses[-1].bits & StatusBits.CORRECTION_MISSED
    assert "correction_missed" in rig.codes()
    np.testing.assert_allclose(rig.sim.base_T_flange_mm, T0)
    rig.correct((1.0, 0, 0))
    rig.tick()
    assert not rig.statuses[-1].bits & StatusBits.CORRECTION_MISSED


def test_the_most_recent_correction_of_a_cycle_wins_and_late_ones_are_applied_late():
    rig = SimRig()
    rig.tick()
    first = rig.statuses[-1].cycle
    rig.tick()  # cycle 'first' got nothing in time
    rig.correct((1.0, 0, 0), cycle=first)  # late (age 1) ...
    rig.correct((0.5, 0, 0))  # ... and the on-time one: the most recent wins
    x0 = rig.sim.base_T_flange_mm[0, 3]
    rig.tick()
    assert rig.sim.base_T_flange_mm[0, 3] == pytest.approx(x0 + 0.5)
    assert rig.sim.counters["overwritten"] == 1


def test_an_unreachable_correction_faults_stops_alter_and_holds_until_alter_on():
    rig = SimRig(max_joint_speed_deg_s=1e5)  # no joint-speed fault: reach is what fails here
    rig.tick()
    rig.correct((300.0, 0, 0))  # (1086, 190, -296) mm: still reachable
    rig.tick()
    assert rig.sim.fault is None
    rig.correct((300.0, 0, 0))  # beyond the reach (about 1.4 m)
    rig.tick()
    assert rig.sim.fault is not None and "unreachable" in rig.sim.fault
    assert "fault" in rig.codes()
    st = rig.statuses[-1]
    assert st.bits & StatusBits.FAULT and not st.bits & StatusBits.ALTER_ACTIVE
    T = rig.sim.base_T_flange_mm
    rig.correct((-1.0, 0, 0))
    rig.tick()
    np.testing.assert_allclose(rig.sim.base_T_flange_mm, T)  # stopped
    assert "correction_ignored" in rig.codes()
    rig.step("console/command", pb.Command(component="sim_robot", verb="alter_on", args_json='{"operator": "test"}'))
    rig.tick()
    assert rig.sim.fault is None and rig.statuses[-1].bits & StatusBits.ALTER_ACTIVE
    rig.correct((-1.0, 0, 0))
    rig.tick()
    assert rig.sim.base_T_flange_mm[0, 3] == pytest.approx(T[0, 3] - 1.0)


def test_a_joint_jump_faults_the_controller():
    rig = SimRig(max_joint_speed_deg_s=10.0)  # 0.28 deg per cycle
    rig.tick()
    rig.correct((0, 0, 0), (0.0, 0.0, 5.0))
    rig.tick()
    assert rig.sim.fault is not None and "joint step" in rig.sim.fault


def test_hold_and_alter_off_flags():
    rig = SimRig()
    rig.tick()
    T = rig.sim.base_T_flange_mm
    rig._host(
        rig.host.send_correction(
            Correction.hold(rig.statuses[-1].cycle, CorrectionFlags.ALTER_OFF), rig.t_ns
        )
    )
    rig.tick()
    np.testing.assert_allclose(rig.sim.base_T_flange_mm, T)
    assert not rig.sim.alter_active and "alter_off" in rig.codes()
    rig.correct((1.0, 0, 0))
    rig.tick()
    np.testing.assert_allclose(rig.sim.base_T_flange_mm, T)
    assert not rig.statuses[-1].bits & StatusBits.CORRECTION_MISSED  # not missed: ALTER is off


def test_world_T_base_places_the_truth_and_puma560_and_start_pose():
    rig = SimRig(
        world_T_base_mm_deg=(1000.0, 0.0, 500.0, 90.0, 0.0, 0.0),
        model="puma560",
        start_pose_mm_deg=(500.0, 150.0, -200.0, 0.0, 0.0, 180.0),
    )
    rig.tick()
    np.testing.assert_allclose(
        x_from_transform(rig.sim.base_T_flange_mm)[:3], [500.0, 150.0, -200.0], atol=1e-6
    )
    expected = transform_from_x(np.array([1000.0, 0, 500, 90, 0, 0])) @ rig.sim.base_T_flange_mm
    np.testing.assert_allclose(rig.world_T_flange_mm(), expected, atol=1e-6)


def test_garbage_and_unknown_console_verbs_never_raise():
    rig = SimRig()
    rig.tick()
    rig.step("serial_rx", pb.SerialChunk(data=bytes(range(256)) * 3))
    rig.step("console/command", pb.Command(component="sim_robot", verb="dance"))
    rig.step("console/command", pb.Command(component="other", verb="alter_off"))
    rig.tick()
    assert "bad_console_command" in rig.codes() and rig.sim.alter_active


@pytest.mark.parametrize(
    "table,needle",
    [
        ({"model": "puma999"}, "is not one of"),
        ({"alter_mode": "joint"}, "is not one of"),
        ({"start_joints_deg": [0, 0, 0, 0, 0, 300]}, "outside the joint limits"),
        ({"start_joints_deg": [0, 0, 0, 0, 0, 400]}, "start_joints_deg[5]: 400.0 is outside its range"),
        ({"start_pose_mm_deg": [5000, 0, 0, 0, 0, 0]}, "not reachable"),
        ({"start_pose_mm_deg": [1, 2, 3]}, "six finite values"),
        ({"cycle_period_ns": 100_000}, "cycle_period_ns"),
    ],
)
def test_config_rejects_bad_values(table, needle):
    with pytest.raises(ConfigError) as e:
        build(SimRobotConfig, table, source="x.toml", section="sim_robot")
    assert needle in str(e.value)
