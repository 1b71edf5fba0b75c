"""The simulated UR checked by a client no one in the project wrote: SDU Robotics' ur-rtde
(PyPI ``ur_rtde``). Its RTDEReceiveInterface connects to port 30004 (it takes no other), sets
up its own recipe (every output it knows), and reads the state: the actual TCP pose must be
the simulator's truth at the timestamp it came with, the modes those of a running program,
the program's heartbeat register advancing.

ur-rtde's Python binding holds the GIL while it waits for the controller, so the client runs
in a process of its own (the simulator's threads run in this one)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import rtde_receive  # noqa: F401  (ur_rtde is in [test]: a broken install fails, not skips)

from humanpt.geometry.arms import arm_kinematics
from humanpt.geometry.transforms import matrix_from_rotvec
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.robot_gateway.links.ur.link import UrLink
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.ur import RtdeServer, UrRobot
from tests.ur.test_ur_link import _session

REGISTER_BASE = 36  # ur-rtde reads output_int_register_36..43 with use_upper_range_registers
CLIENT = r"""
import json, sys
import rtde_receive
r = rtde_receive.RTDEReceiveInterface("127.0.0.1", -1.0, [], False, True)
out = []
last = -1.0
while len(out) < 40:
    ts = r.getTimestamp()
    if ts != last:  # (a new data package)
        last = ts
        sample = [ts, r.getActualTCPPose(), r.getRobotMode(), r.getSafetyMode(), r.getRuntimeState(),
                  r.getOutputIntRegister(36), r.getActualQ()]
        if r.getTimestamp() == ts:  # (each getter reads the latest package: all from one)
            out.append(sample)
r.disconnect()
print(json.dumps(out))
"""

UR5E_FK = arm_kinematics("ur5e").forward


@pytest.fixture
def moving_ur():
    """The simulated e-Series (a UR5e) at 127.0.0.1:30004 following a target 3 mm away (as if
    the gateway had written it), so that the pose changes while ur-rtde reads it."""
    robot = UrRobot(SimRobotConfig(model="ur5e", start_pose_mm_deg=(500.0, -150.0, 300.0, 10.0, 5.0, 170.0)),
                    register_base=REGISTER_BASE, trace_cycles=100_000)
    start = robot.base_T_flange_mm
    target = start.copy()
    target[:3, 3] += (3.0, -2.0, 1.0)
    robot.inputs.update({f"input_int_register_{REGISTER_BASE}": 1})
    robot.inputs.update({f"input_double_register_{REGISTER_BASE + i}": v
                         for i, v in enumerate(rtde.ur_pose_from_transform(target))})
    try:
        server = RtdeServer(robot, "127.0.0.1:30004")
    except OSError as e:
        pytest.fail(f"{e}: ur-rtde needs port 30004 (another simulated UR running?)")
    server.start()
    yield robot, server, start, target
    server.close()


def test_ur_rtde_reads_the_simulated_urs_actual_tcp_pose_as_its_truth(moving_ur):
    robot, server, start, target = moving_ur
    p = subprocess.run([sys.executable, "-c", CLIENT], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    samples = json.loads(p.stdout.strip().splitlines()[-1])
    with server.lock:
        truth = {round(ts * 1000 / robot.cycle_ms): T for ts, T in robot.trace}
    assert len(samples) >= 40
    moved = 0
    for ts, pose, robot_mode, safety_mode, runtime_state, heartbeat, q in samples:
        k = round(ts * 1000 / robot.cycle_ms)
        T = truth[k]  # the pose of the cycle of that timestamp
        np.testing.assert_allclose(pose[:3], T[:3, 3] / 1000.0, atol=1e-12)
        # the rotation vector ur-rtde read is the truth's rotation
        np.testing.assert_allclose(matrix_from_rotvec(np.asarray(pose[3:])), T[:3, :3], atol=1e-12)
        np.testing.assert_allclose(q, robot.kin.inverse(T, np.asarray(q)), atol=1e-6)
        # the arm is the UR5e: the pose ur-rtde read is UR's published DH table at the joints it read
        np.testing.assert_allclose(pose[:3], UR5E_FK(np.asarray(q))[:3, 3] / 1000.0, atol=1e-9)
        assert (robot_mode, safety_mode, runtime_state) == (7, 1, 2)  # RUNNING, NORMAL, PLAYING
        assert heartbeat == k  # +1 every program cycle, from the first
        moved += not np.allclose(T, start)
    assert moved > 0  # the arm moved toward the target while ur-rtde read it
    assert robot.counters["malformed"] == 0


IO_CLIENT = r"""
import rtde_io
io = rtde_io.RTDEIOInterface("127.0.0.1")
ok = [io.setInputIntRegister(20, 1234), io.setInputDoubleRegister(20, 0.25), io.setStandardDigitalOut(3, True)]
io.disconnect()
print(ok)
"""


def test_ur_rtdes_io_interface_writes_the_simulated_urs_inputs_beside_humanpts_session():
    """ur-rtde's RTDEIOInterface sets up its input recipes (lower range registers 18..23, the
    digital outputs) while humanpt's link holds its own (24..30): no IN_USE, and what it writes
    is what the simulated controller has."""
    robot = UrRobot(SimRobotConfig(model="ur5e"))
    with_humanpt, _ = _session(UrLink.from_config(gateway_config("ur")), robot)
    assert with_humanpt.started
    try:
        server = RtdeServer(robot, "127.0.0.1:30004")
    except OSError as e:
        pytest.fail(f"{e}: ur-rtde needs port 30004 (another simulated UR running?)")
    server.start()
    try:
        p = subprocess.run([sys.executable, "-c", IO_CLIENT], capture_output=True, text=True, timeout=120)
    finally:
        server.close()
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip().splitlines()[-1] == "[True, True, True]"
    assert robot.inputs["input_int_register_20"] == 1234 and robot.inputs["input_double_register_20"] == 0.25
    # digital output 3: mask and value bit 3
    assert robot.inputs["standard_digital_output_mask"] == 8 and robot.inputs["standard_digital_output"] == 8
    assert robot.counters["malformed"] == 0
