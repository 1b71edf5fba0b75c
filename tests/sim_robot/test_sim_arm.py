"""The simulated robots' one set-up (sim_robot/arm.py, issue 30: "the simulated robots share
one kinematics core and one set-up"; issue 34.4: the UR moves a UR5e, the EGM robot an IRB
1600): the config chooses the arm, every simulator moves the arm its config chooses from the
same start, mounting and speed limit, and the servo's first-order response is the hand
calculation's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from humanpt.geometry.arms import arm_kinematics, arm_model
from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.links.rsi.protocol import RsiCorrection, encode_sen
from humanpt.sim_robot.arm import JointStepError, SimArm, lag_gain
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import SimRobotCore
from humanpt.sim_robot.egm import EgmRobot
from humanpt.sim_robot.rsi import RsiRobot
from humanpt.sim_robot.ur import UrRobot, UrSimRobotCore

MS = 1_000_000


def test_each_link_has_its_arm_unless_the_config_says():
    assert SimRobotConfig().model == "puma762"
    assert SimRobotConfig(protocol="rsi", cycle_period_ns=12 * MS).model == "puma762"
    assert SimRobotConfig(protocol="egm", cycle_period_ns=4 * MS).model == "irb1600"
    assert SimRobotConfig(protocol="rtde", cycle_period_ns=2 * MS).model == "ur5e"
    cfg = SimRobotConfig(protocol="egm", cycle_period_ns=4 * MS)
    assert cfg.start_joints_deg == arm_model("irb1600").home_joints_deg  # the arm's comfortable pose
    assert SimRobotConfig(protocol="egm", cycle_period_ns=4 * MS, model="puma560").model == "puma560"
    with pytest.raises(ValueError, match="RTDE"):
        SimRobotConfig(protocol="rtde", cycle_period_ns=4 * MS)
    with pytest.raises(ValueError, match="link_length_errors_mm.*Puma's.*ur5e"):
        SimRobotConfig(model="ur5e", link_length_errors_mm=(0.0, 1.0, 0.0, 0.0, 0.0))


@pytest.mark.parametrize("model", ["puma762", "ur5e", "irb1600"])
def test_every_simulator_sets_up_the_same_arm(model):
    """The ALTER, RSI, EGM and UR controllers built from one [sim_robot] table hold the same
    arm at the same joints: the forward kinematics of the model's table at its home, mounted
    where the config says (world_T_base)."""
    base = (100.0, -50.0, 900.0, 30.0, 0.0, 180.0)
    home = np.radians(arm_model(model).home_joints_deg)
    want_base = arm_kinematics(model).forward(home)
    want_world = transform_from_x(np.asarray(base)) @ want_base
    alter = SimRobotCore.create(SimRobotConfig(model=model, world_T_base_mm_deg=base))
    rsi = RsiRobot(SimRobotConfig(model=model, protocol="rsi", cycle_period_ns=12 * MS, world_T_base_mm_deg=base))
    egm = EgmRobot.from_config(SimRobotConfig(model=model, protocol="egm", cycle_period_ns=4 * MS,
                                              world_T_base_mm_deg=base))
    ur = UrSimRobotCore.create(SimRobotConfig(model=model, protocol="rtde", cycle_period_ns=2 * MS,
                                              world_T_base_mm_deg=base))
    for arm in (alter.arm, rsi.arm, egm.arm, ur.robot.arm):
        assert isinstance(arm, SimArm) and arm.model == model
        np.testing.assert_array_equal(arm.q_rad, home)
        np.testing.assert_allclose(arm.base_T_flange_mm, want_base, atol=1e-9)
        np.testing.assert_allclose(arm.true_world_T_flange_mm, want_world, atol=1e-9)
    # the joint step a cycle allows: the config's speed limit times the link's cycle
    assert alter.arm.max_joint_step_deg == pytest.approx(250.0 * 0.028)
    assert egm.arm.max_joint_step_deg == pytest.approx(250.0 * 0.004)
    assert ur.robot.arm.max_joint_step_deg == pytest.approx(250.0 * 0.002)


def test_rsi_moves_the_arm_its_config_chooses():
    """An RKorr of 0.5 mm along x moves the UR5e's flange (not the Puma's) by 0.5 mm in the
    base frame: RSI's relative correction through the shared step."""
    robot = RsiRobot(SimRobotConfig(model="ur5e", protocol="rsi", cycle_period_ns=12 * MS))
    p0 = robot.base_T_flange_mm[:3, 3].copy()
    robot.cycle(0)
    robot.receive(encode_sen(RsiCorrection(robot.ipoc, (0.5, 0.0, 0.0, 0.0, 0.0, 0.0))), 1 * MS)
    robot.cycle(12 * MS)
    assert robot.counters["applied"] == 1
    np.testing.assert_allclose(robot.base_T_flange_mm[:3, 3] - p0, (0.5, 0.0, 0.0), atol=1e-9)
    np.testing.assert_allclose(arm_kinematics("ur5e").forward(robot.q_rad), robot.base_T_flange_mm, atol=1e-12)


def test_servo_is_first_order_as_by_hand():
    """EGM's position guidance on the IRB 1600: a target 10 mm away along z is approached
    by the fraction 1 - exp(-4/20) a cycle: after n cycles (1 - alpha)^n x 10 mm remain."""
    arm = SimArm(SimRobotConfig(model="irb1600", protocol="egm", cycle_period_ns=4 * MS))
    target = arm.base_T_flange_mm
    target[2, 3] += 10.0
    alpha = lag_gain(4.0, 20.0)
    assert alpha == pytest.approx(1.0 - math.exp(-0.2))
    for _ in range(5):
        assert arm.servo(target, alpha)
    assert target[2, 3] - arm.base_T_flange_mm[2, 3] == pytest.approx(10.0 * math.exp(-0.2) ** 5, abs=1e-9)
    np.testing.assert_allclose(arm.base_T_flange_mm[:2, 3], target[:2, 3], atol=1e-9)


def test_a_step_beyond_the_joint_speed_limit_is_refused_and_the_arm_stays():
    arm = SimArm(SimRobotConfig(model="ur5e", protocol="rtde", cycle_period_ns=2 * MS))
    q0 = arm.q_rad.copy()
    delta = np.eye(4)
    delta[:3, 3] = (20.0, 0.0, 0.0)  # 20 mm in 2 ms: far beyond 0.5 deg a cycle on some joint
    with pytest.raises(JointStepError, match="needs a joint step of"):
        arm.step(delta, "world")
    np.testing.assert_array_equal(arm.q_rad, q0)


def test_the_simulated_ur_core_serves_rtde_bytes():
    """UrSimRobotCore: a version request on serial_rx is answered on serial_tx (RTDE's 'V'
    reply, accepted); each tick sends the truth of the UR5e's flange."""
    from humanpt.robot_gateway.links.ur import protocol as rtde
    from humanpt.schemas import humanpt_pb2 as pb

    core = SimRobotCore.create(SimRobotConfig(protocol="rtde", cycle_period_ns=2 * MS))
    assert isinstance(core, UrSimRobotCore) and isinstance(core.robot, UrRobot)
    outs = core._on_rtde(0, pb.SerialChunk(data=rtde.encode_version_request()))
    (topic, msg), = outs
    (packet,) = rtde.Framer().feed(msg.data)
    assert topic == "serial_tx" and packet.type == rtde.REQUEST_PROTOCOL_VERSION and packet.payload == b"\x01"
    outs = core._on_cycle(2 * MS, pb.Tick())
    truth = [m for t, m in outs if t == "sim_robot/truth"]
    assert len(truth) == 1
    p = truth[0].world_T_flange.translation
    want = arm_kinematics("ur5e").forward(np.radians(arm_model("ur5e").home_joints_deg))[:3, 3] / 1000.0
    assert (p.x, p.y, p.z) == pytest.approx(tuple(want), abs=1e-12)
