"""The generated access control lets every component publish what it does publish: each
output of a lock-step run of the whole twin (the simulated Puma behind the ALTER link, and
the stand-in robot) against the producing component's put rights. A component that starts
publishing a new key shows here before it is refused on a cell under mTLS."""

from __future__ import annotations

import pytest

from humanpt.runtime.security import component_rights
from humanpt.schemas import topics
from humanpt.twin.system import build_system


@pytest.mark.parametrize("robot", ["puma", "standin"])
def test_every_published_key_is_allowed_to_its_publisher(robot):
    w = build_system("arc", seed=0, robot=robot, digest=False)
    w.run_for(1.5)
    produced = {(d.component, d.topic) for d in w.lockstep.outputs if d.topic in topics.TOPICS}
    robot_side = {"sim_robot", "robot_gateway"} if robot == "puma" else {"standin_robot"}
    assert {c for c, _ in produced} >= {"sim_camera", "perception", "pose_filter", "controller", "operator",
                                        *robot_side}
    refused = sorted((c, t) for c, t in produced
                     if topics.TOPICS[t].key("c") not in component_rights(c, "c").get("put", []))
    assert refused == [], f"the access control would refuse these (component, topic): {refused}"
