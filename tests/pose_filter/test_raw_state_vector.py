"""Issue 33.5: the paper's raw state vector (step 10's X_WG before the Kalman filter) goes
from the pose filter (TobState.world_T_tob_measured) into each path point with
[controller] record_raw (PathPoint.world_T_tob_raw, and the tip through it)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry.rig import Rig as RigModel
from humanpt.geometry.rig import Tip
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header, pose
from tests.pose_filter.test_pose_filter import TARGET_X, T_m

CYCLE_NS = 28_000_000


def _noisy_run(n=12, seed=0):
    """A still robot and target; each image's camera_T_tob off by ~1 mm, ~1 deg. Returns
    (the filter's states right after each image, the X_WG of each image worked out here)."""
    rng = np.random.default_rng(seed)
    core = PoseFilterCore(PoseFilterConfig(wait_for_robot_ms=0))
    flange = T_m((200, 700, 800, 10, 0, 180))
    world_T_tob = T_m(TARGET_X)
    fTc = core.flange_T_camera_m
    after, want = [], []
    for k in range(n):
        t = k * CYCLE_NS
        core.step(t, "robot_gateway/robot_state", pb.RobotState(header=header(t, k, "world"),
                                                                world_T_flange=pose(flange), cycle=k))
        cTt = np.linalg.inv(flange @ fTc) @ world_T_tob
        cTt[:3, 3] += rng.normal(0, 1e-3, 3)
        cTt[:3, :3] = Rotation.from_rotvec(np.radians(rng.normal(0, 1.0, 3))).as_matrix() @ cTt[:3, :3]
        msg = pb.TobMeasurement(header=header(t + 1000, 0, "camera"), status=pb.TOB_STATUS_FULL,
                                camera_T_tob=pose(cTt))
        outs = core.step(t + 2000, "perception/tob", msg)
        states = [m for tp, m in outs if tp == "pose_filter/tob_state"]
        if states:
            after.append(states[-1])
            want.append(flange @ fTc @ cTt)  # paper step 8-10: X_WG = W_T_F F_T_C C_T_G
    return after, want


def test_the_filter_publishes_each_images_own_world_pose():
    after, want = _noisy_run()
    assert len(after) >= 10
    moved = []
    for st, W in zip(after, want, strict=True):
        assert st.HasField("world_T_tob_measured")
        np.testing.assert_allclose(from_pose(st.world_T_tob_measured), W, atol=1e-12)
        moved.append(np.linalg.norm(from_pose(st.world_T_tob_at_measurement)[:3, 3] - W[:3, 3]))
    # the filter's estimate is not the measurement (it averages the still target)
    assert max(moved) > 5e-5


def test_a_path_point_carries_the_raw_vector_beside_the_filtered_one():
    after, want = _noisy_run(4)
    tip = Tip(tob_t_tip_mm=(0.0, 0.0, -150.0))
    for record_raw in (True, False):
        core = ControllerCore(ControllerConfig(record_raw=record_raw, has_driver=True, start_mode="hold"),
                              RigModel(tip=tip))
        flange = T_m((200, 700, 800, 10, 0, 180))
        core.step(0, "console/command", pb.Command(header=header(0), component="controller", verb="record_start"))
        points = []
        for k, st in enumerate(after):
            t = k * CYCLE_NS
            core.step(t, "robot_gateway/robot_state", pb.RobotState(header=header(t, k, "world"),
                                                                    world_T_flange=pose(flange), cycle=k))
            st.cycle = k
            points += [m for tp, m in core.step(t + 1, "pose_filter/tob_state", st) if tp == "controller/path"]
        assert len(points) >= 2
        differs = []
        for p in points:
            if not record_raw:
                assert not p.HasField("world_T_tob_raw") and not p.HasField("world_T_tip_raw")
                continue
            W = want[[s.measurement_stamp_ns for s in after].index(p.header.stamp_ns)]
            np.testing.assert_allclose(from_pose(p.world_T_tob_raw), W, atol=1e-12)
            tob_T_tip = np.eye(4)
            tob_T_tip[2, 3] = -0.150
            np.testing.assert_allclose(from_pose(p.world_T_tip_raw), W @ tob_T_tip, atol=1e-12)
            differs.append(not np.allclose(from_pose(p.world_T_tob), W, atol=1e-6))
        if record_raw:  # the filtered one beside it is the filter's (it starts on the first image)
            assert any(differs)
