"""The scene core alone, on scripted inputs: D follows the controller's dz_mm, a long path
costs O(N), a new recording starts a new path, a tilted mirror turns its virtual camera."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanpt.geometry.rig import Rig
from humanpt.scene.config import SceneConfig
from humanpt.scene.core import SceneCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, pose


def _robot_state(stamp_ns: int) -> pb.RobotState:
    return pb.RobotState(header=header(stamp_ns, 0, "world"), world_T_flange=pose(np.eye(4)))


def _frame(outputs, child: str):
    return [t for topic, m in outputs if topic == "scene/transforms" for t in m.transforms
            if t.child_frame_id == child]


def _point(i: int, stamp_ns: int) -> pb.PathPoint:
    T = np.eye(4)
    T[:3, 3] = [i * 1e-3, 0.0, 0.0]
    return pb.PathPoint(header=header(stamp_ns, i, "world"), index=i, world_T_tob=pose(T))


def test_desired_follows_the_controllers_dz():
    core = SceneCore(SceneConfig(dz_mm=600.0))
    (d,) = _frame(core.step(1, "robot_gateway/robot_state", _robot_state(1)), "desired")
    assert d.translation.z == pytest.approx(0.6)
    # What the controller says when its dz_mm changes (runtime.core.Core._on_param).
    ev = pb.Event(header=header(2), severity=pb.SEVERITY_INFO, source="controller", code="param_changed",
                  text="controller: dz_mm = 650.0")
    (log,) = core.step(2, "controller/events", ev)
    assert log[0] == "scene/log" and log[1].name == "controller"
    (d,) = _frame(core.step(3, "robot_gateway/robot_state", _robot_state(int(1e8))), "desired")
    assert d.translation.z == pytest.approx(0.65)


def test_moving_frames_are_sent_at_most_transforms_max_hz():
    """A 4 ms robot link's 250 states a second become at most 60 transform messages."""
    core = SceneCore(SceneConfig(transforms_max_hz=60.0))
    sent = [k for k in range(250) if _frame(core.step(k, "robot_gateway/robot_state",
                                                         _robot_state(k * 4_000_000)), "flange")]
    # Every 5th state (20 ms >= 1/60 s = 16.7 ms; 16 ms < it): 50 in the second.
    assert len(sent) == 50 and sent[:3] == [0, 5, 10]


def test_long_path_is_resent_geometrically_and_ends_whole():
    core = SceneCore(SceneConfig(path_resend_fraction=0.02, seam_strip_points=200))
    core.step(0, "controller/status", pb.ControllerStatus(header=header(0), recording=True))
    n, sent_poses, messages, strips = 3000, 0, 0, {}
    for i in range(n):
        for topic, m in core.step(i + 1, "controller/path", _point(i, i + 1)):
            if topic == "scene/path":
                sent_poses += len(m.poses)
                messages += 1
            elif topic == "scene/entities":
                strips.update((e.id, [p.x for p in e.lines[0].points]) for e in m.entities)
    # Whole path every 2 % of growth: about N / 0.02 poses in all (a geometric series),
    # not N^2 / 2 = 4.5 million.
    assert sent_poses < 1.2 * n / 0.02 and messages < 400
    # Each seam update re-sends one strip of at most 200 points; together the strips draw
    # every point, each strip starting where the one before ended (no gap).
    xs = [strips[f"path1/seam/{k}"] for k in range(len(strips))]
    assert max(map(len, xs)) == 200 and all(a[-1] == b[0] for a, b in zip(xs, xs[1:], strict=False))
    assert [x for s in xs for x in s[1:]] == pytest.approx([i * 1e-3 for i in range(1, n)])
    # Recording stops: the whole path goes out once more.
    out = core.step(n + 1, "controller/status", pb.ControllerStatus(header=header(n + 1), recording=False))
    (path,) = [m for topic, m in out if topic == "scene/path"]
    assert len(path.poses) == n and path.poses[-1].position.x == pytest.approx((n - 1) * 1e-3)


def test_a_new_recording_starts_a_new_path():
    core = SceneCore(SceneConfig())
    for i in range(5):
        core.step(i, "controller/path", _point(i, i))
    out = core.step(10, "controller/path", _point(0, 10))
    (path,) = [m for topic, m in out if topic == "scene/path"]
    assert len(path.poses) == 1 and core.path_number == 2


def test_tilted_mirror_turns_its_virtual_camera():
    rig = Rig()
    rig = dataclasses.replace(rig, psvs=dataclasses.replace(rig.psvs, rotvec_left_deg=(0.0, 0.1, 0.0)))
    core = SceneCore(SceneConfig(), rig)
    out = core.step(1, "robot_gateway/robot_state", _robot_state(1))
    (left,) = _frame(out, "camera_left")
    (right,) = _frame(out, "camera_right")
    q = left.rotation
    assert Rotation.from_quat([q.x, q.y, q.z, q.w]).as_rotvec(degrees=True) == pytest.approx([0.0, 0.1, 0.0])
    assert (right.rotation.x, right.rotation.y, right.rotation.z, right.rotation.w) == (0, 0, 0, 1)


def test_foxglove_layout_names_real_topics_of_the_right_types():
    """docs/foxglove-layout.json: every topic it draws is in the topic table (cell0, the
    lock-step and default cell) with the type the panel reads."""
    import json
    import re
    from pathlib import Path

    from humanpt.scene.layout import layout_text
    from humanpt.schemas import topics

    text = (Path(__file__).parents[2] / "docs" / "foxglove-layout.json").read_text()
    assert text == layout_text("cell0")  # the docs' copy is the package's template, for cell0
    layout = json.loads(text)
    panels = layout["configById"]

    def short(key: str) -> str:
        cell, name = topics.short_from_key(key)
        assert cell == "cell0" and name in topics.TOPICS, key
        return name

    def type_of(key: str) -> str:
        return topics.TOPICS[short(key)].type.DESCRIPTOR.full_name

    image = panels["Image!humanptimage"]["imageMode"]
    assert type_of(image["imageTopic"]) == "foxglove.RawImage"
    assert type_of(image["calibrationTopic"]) == "foxglove.CameraCalibration"
    assert {type_of(k) for k in image["annotations"]} == {"foxglove.ImageAnnotations"}
    assert {type_of(k) for k in panels["3D!humanpt3d"]["topics"]} >= {
        "foxglove.FrameTransforms", "foxglove.PosesInFrame", "foxglove.SceneUpdate"}
    assert type_of(panels["RosOut!humanptlog"]["topicToRender"]) == "foxglove.Log"
    # Plot paths: "<key>".field.field..., each field a field of the topic's message.
    plotted = [p["value"] for k, v in panels.items() if k.startswith("Plot!") for p in v["paths"]]
    assert plotted
    for value in plotted:
        m = re.fullmatch(r'"([^"]+)"((?:\.\w+)+)', value)
        assert m, value
        descriptor = topics.TOPICS[short(m.group(1))].type.DESCRIPTOR
        for name in m.group(2).split(".")[1:]:
            field = descriptor.fields_by_name[name]
            descriptor = field.message_type or descriptor
    # Every panel the mosaic shows is configured, and the other way round.
    shown = re.findall(r"\w+!\w+", json.dumps(layout["layout"]))
    assert sorted(shown) == sorted(panels)


def test_rerun_blueprint_is_written_once_and_verifies(tmp_path):
    import subprocess
    import sys

    from humanpt.scene.rerun_blueprint import main

    out = tmp_path / "run.rbl"
    assert main([str(out), "--cell", "demo"]) == 0 and out.stat().st_size > 0
    before = out.read_bytes()
    assert main([str(out)]) == 1 and out.read_bytes() == before  # never overwritten
    rerun = [sys.executable, "-m", "rerun"]
    r = subprocess.run([*rerun, "rrd", "print", str(out)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    # The overrides name the converted channels' entities of the given cell.
    assert "overrides/humanpt/demo/scene/transforms/visualizers" in r.stdout
    assert "SpatialInformation:target_frame" in r.stdout
