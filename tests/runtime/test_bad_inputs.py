"""Non-finite and absurd numbers never reach a core's state (issue 14, item 3).

The attack: a NaN measurement passed the pose filter's gate (NaN > threshold is False) and
every later input raised; 1e308 did the same. Every core now drops such an input before it
reaches the handler, with a ``bad_input`` event, and goes on with the next good input.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from google.protobuf.descriptor import FieldDescriptor

from humanpt.geometry.rig import Rig
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.runtime.registry import COMPONENTS, core_class
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.checks import absurd_field
from humanpt.schemas.convert import header, pose

_FLOATS = (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT)


def _poison(msg, value) -> str | None:
    """Set the first float field reachable in ``msg`` (a fresh message) to ``value``; its path."""
    for fd in msg.DESCRIPTOR.fields:
        if fd.type in _FLOATS:
            if fd.is_repeated:
                getattr(msg, fd.name).append(value)
            else:
                setattr(msg, fd.name, value)
            return fd.name
        if fd.type == FieldDescriptor.TYPE_MESSAGE and not fd.is_repeated:
            sub = _poison(getattr(msg, fd.name), value)
            if sub:
                return f"{fd.name}.{sub}"
    return None


@pytest.mark.parametrize("value", [math.nan, math.inf, -1e308, 1.7e305])
def test_absurd_field_finds_the_poisoned_field(value):
    m = pb.TobState()
    path = _poison(m, value)
    assert path is not None and absurd_field(m).startswith(path)
    assert absurd_field(pb.TobState(header=header(5), world_T_tob=pose(np.eye(4)))) is None


PORTS = [(name, p) for name in sorted(COMPONENTS) for p in core_class(name).ports
         if p.topic != "param" and _poison(p.type(), 0.0) is not None]


@pytest.mark.parametrize("name,port", PORTS, ids=[f"{n}:{p.topic}" for n, p in PORTS])
@pytest.mark.parametrize("value", [math.nan, 1e308])
def test_every_core_drops_a_poisoned_input_with_an_event(name, port, value):
    cls = core_class(name)
    core = cls(cls.default_config())
    msg = port.type()
    where = _poison(msg, value)
    outs = core.step(1_000, port.topic, msg)
    events = [m for t, m in outs if t.endswith("/events")]
    assert [e.code for e in events] == ["bad_input"] and len(outs) == 1, outs
    assert where.split(".")[-1] in events[0].text and port.topic in events[0].text
    # A flood is reported at the 1st, 10th, 100th input, not each time.
    reported = sum(len(core.step(1_000, port.topic, msg)) for _ in range(99))
    assert reported == 2


@pytest.mark.parametrize("field", ["translation.z", "rotation.x"])
@pytest.mark.parametrize("value", [math.nan, 1e308])
def test_a_poisoned_measurement_does_not_poison_the_pose_filter(field, value):
    """The attack replayed on the core: good measurements, one poisoned, good ones again;
    nothing raises, the state stays finite and follows the good ones (1e308 in a translation
    raised 'not a proper rotation' at every later input before the check)."""
    core = PoseFilterCore(PoseFilterConfig())
    flange = np.eye(4)

    def robot(k):
        return pb.RobotState(header=header(k * 28_000_000), cycle=k, world_T_flange=pose(flange))

    def measurement(k, z_m):
        T = np.eye(4)
        T[:3, 3] = [0.0, 0.0, z_m]
        return pb.TobMeasurement(header=header(k * 28_000_000 + 1), status=pb.TOB_STATUS_FULL, visible=3,
                                 camera_T_tob=pose(T))

    states = []
    for k in range(1, 40):
        outs = core.step(k * 28_000_000, "robot_gateway/robot_state", robot(k))
        states += [s for t, s in outs if t == "pose_filter/tob_state"]
        m = measurement(k, 0.6)
        if k == 20:
            part, axis = field.split(".")
            setattr(getattr(m.camera_T_tob, part), axis, value)
        outs = core.step(k * 28_000_000 + 2, "perception/tob", m)
        states += [s for t, s in outs if t == "pose_filter/tob_state"]
    assert states, "the filter published nothing"
    last = states[-1]
    assert absurd_field(last) is None
    assert last.status == pb.TOB_STATUS_FULL
    # world_T_tob = world_T_flange (identity) @ flange_T_camera @ camera_T_tob (0, 0, 0.6 m);
    # flange_T_camera is a pure translation by default (x, y, z mm, yaw, pitch, roll = 0).
    fx, fy, fz, *angles = Rig().hand_eye.flange_T_camera_x
    assert list(angles) == [0.0, 0.0, 0.0]
    t = last.world_T_tob.translation
    np.testing.assert_allclose([t.x, t.y, t.z], [fx / 1e3, fy / 1e3, fz / 1e3 + 0.6], atol=1e-4)
