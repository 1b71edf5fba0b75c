"""scene core: humanpt messages in, Foxglove's own message types out.

Pure (DESIGN.md's contract): messages in, messages out, time only from the inputs, so the
scene recording replays exactly.  It never reads camera/image (that would record every
image once more): the image overlays take the stamp of perception/tob, which is the
image's capture stamp, and the camera's frame id from the config.

Frames (foxglove.FrameTransform parent -> child; a_T_b is the pose of b in a):

==================  ==================  =================================================
parent              child               source
==================  ==================  =================================================
``world``           ``base``            config ``world_T_base_mm_deg`` (the gateway's)
``base``            ``flange``          robot_gateway/robot_state (world_T_flange)
``flange``          ``camera``          rig: hand-eye flange_T_camera
``camera``          ``camera_right``    rig: PSVS virtual camera 1 (O1, mirror rotation)
``camera``          ``camera_left``     rig: PSVS virtual camera 2 (O2, mirror rotation)
``camera``          ``desired``         the desired point D: camera_T_desired(dz_mm)
``world``           ``flange_desired``  controller/status world_T_desired
``world``           ``tob``             pose_filter/tob_state world_T_tob
``tob``             ``tip``             rig: the driver tip tob_T_tip
==================  ==================  =================================================

``camera`` is an optical frame (x right, y down, z along the optical axis), as Foxglove's
CameraCalibration expects; the name is ``camera_frame`` of the config.

The fixed frames, the latest robot flange and D are held in the cell's frame graph
(:mod:`humanpt.geometry.frames`, world -> base, world -> flange, flange -> camera ->
camera_right / camera_left / desired), from which each published ``parent_T_child`` is
looked up (``base_T_flange = inverse(world_T_base) @ world_T_flange``); the filter's, the
controller's and the rig's tip frames go out as their messages carry them.
"""

from __future__ import annotations

import functools
import math
import re

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CircleAnnotation_pb2 import CircleAnnotation
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp

from humanpt.geometry import camera_T_desired, make_transform, transform_from_x
from humanpt.geometry.frames import NEAREST_HOLD, Backwards, FrameGraph, Repeat, TimedPoses
from humanpt.geometry.rig import Rig
from humanpt.geometry.units import to_m
from humanpt.runtime.core import Core, Output, Port
from humanpt.scene.config import SceneConfig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.convert import from_pose, pose

__all__ = ["SceneCore", "EVENT_TOPICS", "FRAMES"]

T_TRANSFORMS = "scene/transforms"
T_PATH = "scene/path"
T_PATH_POINTS = "scene/path_points"
T_ANNOTATIONS = "scene/annotations"
T_CALIBRATION = "scene/calibration"
T_LOG = "scene/log"
T_ENTITIES = "scene/entities"

WORLD, BASE, FLANGE, TOB, TIP = "world", "base", "flange", "tob", "tip"
CAMERA_RIGHT, CAMERA_LEFT, DESIRED, FLANGE_DESIRED = "camera_right", "camera_left", "desired", "flange_desired"
# Every frame id the scene publishes ("camera" is the config's camera_frame).
FRAMES = (WORLD, BASE, FLANGE, "camera", CAMERA_RIGHT, CAMERA_LEFT, DESIRED, FLANGE_DESIRED, TOB, TIP)

# Every component's events become foxglove.Log lines (not the scene's own: it would log
# what it logs).
EVENT_TOPICS: tuple[str, ...] = tuple(
    t for t in topics.TOPICS if t.endswith("/events") and not t.startswith("scene/"))

_LEVEL = {
    pb.SEVERITY_UNSPECIFIED: Log.UNKNOWN,
    pb.SEVERITY_DEBUG: Log.DEBUG,
    pb.SEVERITY_INFO: Log.INFO,
    pb.SEVERITY_WARNING: Log.WARNING,
    pb.SEVERITY_ERROR: Log.ERROR,
    pb.SEVERITY_FATAL: Log.FATAL,
}
_DZ_CHANGED = re.compile(r"\bdz_mm = ([-+0-9.eE]+)")
_LABELS = ("A", "B", "C")
_XYZ_FLOAT32 = [PackedElementField(name=n, offset=4 * i, type=PackedElementField.FLOAT32) for i, n in enumerate("xyz")]


def _rgba(r: float, g: float, b: float, a: float = 1.0) -> Color:
    return Color(r=r, g=g, b=b, a=a)


# Colours as in the rerun view: measured orange, filtered cyan, path yellow, truth magenta.
MEASURED = _rgba(1.0, 0.59, 0.12)
FILTERED = _rgba(0.16, 0.78, 1.0)
PATH = _rgba(1.0, 0.9, 0.16)
TRUTH = _rgba(0.9, 0.24, 0.9)
PAIR = (_rgba(1.0, 0.31, 0.31), _rgba(0.31, 1.0, 0.31), _rgba(0.35, 0.55, 1.0))
WHITE = _rgba(1.0, 1.0, 1.0)
SHADE = _rgba(0.0, 0.0, 0.0, 0.5)


def timestamp(stamp_ns: int) -> Timestamp:
    """A google.protobuf.Timestamp of ``stamp_ns`` (ns of the shared time base)."""
    s, ns = divmod(int(stamp_ns), 1_000_000_000)
    return Timestamp(seconds=s, nanos=ns)


def _identity() -> Pose:
    """The identity pose, every field set (an unset position is no zero to every reader)."""
    return Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def _fox_pose(p: pb.Pose) -> Pose:
    t, q = p.translation, p.rotation
    return Pose(position=Vector3(x=t.x, y=t.y, z=t.z), orientation=Quaternion(x=q.x, y=q.y, z=q.z, w=q.w))


def _transform(stamp_ns: int, parent: str, child: str, parent_T_child: pb.Pose) -> FrameTransform:
    """One foxglove.FrameTransform: the pose of ``child`` in ``parent`` (metres)."""
    t, q = parent_T_child.translation, parent_T_child.rotation
    return FrameTransform(timestamp=timestamp(stamp_ns), parent_frame_id=parent, child_frame_id=child,
                          translation=Vector3(x=t.x, y=t.y, z=t.z),
                          rotation=Quaternion(x=q.x, y=q.y, z=q.z, w=q.w))


class SceneCore(Core):
    """humanpt topics -> foxglove.FrameTransforms, PosesInFrame, ImageAnnotations,
    CameraCalibration, Log and SceneUpdate (module docstring: frames; README.md: topics)."""

    name = "scene"
    config_type = SceneConfig
    uses_rig = True
    ports = (
        Port("robot_gateway/robot_state", pb.RobotState, "_on_robot_state"),
        Port("pose_filter/tob_state", pb.TobState, "_on_tob_state"),
        Port("controller/status", pb.ControllerStatus, "_on_status"),
        Port("controller/path", pb.PathPoint, "_on_path"),
        Port("perception/tob", pb.TobMeasurement, "_on_tob"),
        Port("operator/truth", pb.Truth, "_on_truth"),
        *(Port(t, pb.Event, "_on_event") for t in EVENT_TOPICS),
    )

    def __init__(self, config: SceneConfig, rig: Rig | None = None):
        super().__init__(config, rig=rig if rig is not None else Rig())
        rig = self.rig
        params = rig.params()
        self._params = params
        # The cell's frames (geometry.frames), metres: the module docstring's table down to D.
        # world -> flange holds the latest robot state; base -> flange is looked up through it.
        camera = config.camera_frame
        self.frames = FrameGraph(WORLD)
        self.frames.add_static(WORLD, BASE, to_m(transform_from_x(np.asarray(config.world_T_base_mm_deg, dtype=float))))
        self._flange = self.frames.add_timed(
            WORLD, FLANGE, TimedPoses(1, repeat=Repeat.REPLACE, backwards=Backwards.RESTART), NEAREST_HOLD)
        self.frames.add_static(FLANGE, camera, rig.hand_eye.flange_T_camera_m())
        for child, cam in ((CAMERA_RIGHT, params.right_camera), (CAMERA_LEFT, params.left_camera)):
            self.frames.add_static(camera, child, make_transform(np.asarray(cam.camera_R_virtual, dtype=float),
                                                                 np.asarray(cam.centre_mm, dtype=float) * 1e-3))
        self._set_dz(float(config.dz_mm))
        # Rig-fixed transforms, as messages once.
        self._rig_poses: list[tuple[str, str, pb.Pose]] = [
            (parent, child, pose(self.frames.lookup(parent, child)))
            for parent, child in ((WORLD, BASE), (FLANGE, camera), (camera, CAMERA_RIGHT), (camera, CAMERA_LEFT))]
        self._tob_T_tip = pose(to_m(rig.tip.tob_T_tip_mm()))
        self._sources_m = np.asarray(rig.target_model().source_positions_mm, dtype=float) * 1e-3  # (3, 3) TOB
        self.measurements = 0
        # The recorded path (controller/path) in world, as PathPoints; paths counted from 1.
        self.path: list[pb.PathPoint] = []
        self.path_number = 0
        self._path_sent = 0  # points in the last scene/path
        self._recording = False
        # The operator's true seam (operator/truth): world points (m), truth_step_mm apart.
        self.truth_seam: list[tuple[float, float, float]] = []
        self._sent_tf_ns: dict[str, int] = {}  # moving frame source -> stamp last sent

    def _set_dz(self, dz_mm: float) -> None:
        """The desired point D at ``dz_mm`` on the camera's axis (camera -> desired)."""
        self.dz_mm = dz_mm
        self.frames.add_static(self.config.camera_frame, DESIRED, to_m(camera_T_desired(dz_mm)))

    def _tf_due(self, source: str, stamp_ns: int) -> bool:
        """Whether ``source``'s frames at ``stamp_ns`` go out (transforms_max_hz, by stamp)."""
        last = self._sent_tf_ns.get(source)
        if last is not None and 0 <= stamp_ns - last < 1e9 / self.config.transforms_max_hz:
            return False
        self._sent_tf_ns[source] = stamp_ns
        return True

    def on_config_changed(self, old: SceneConfig, new: SceneConfig) -> None:
        if new.dz_mm != old.dz_mm:
            self._set_dz(float(new.dz_mm))

    # -- transforms -----------------------------------------------------------------------------
    def _on_robot_state(self, t_ns: int, msg: pb.RobotState) -> list[Output]:
        """world -> base -> flange at the cycle's stamp, with the rig's fixed frames and D."""
        stamp = msg.header.stamp_ns
        if not self._tf_due("robot", stamp):
            return []
        self._flange.add(stamp, from_pose(msg.world_T_flange))
        frames, camera = self.frames, self.config.camera_frame
        out = [_transform(stamp, parent, child, p) for parent, child, p in self._rig_poses]
        out.append(_transform(stamp, BASE, FLANGE, pose(frames.lookup(BASE, FLANGE, stamp))))
        out.append(_transform(stamp, camera, DESIRED, pose(frames.lookup(camera, DESIRED))))
        return [(T_TRANSFORMS, FrameTransforms(transforms=out))]

    def _on_tob_state(self, t_ns: int, msg: pb.TobState) -> list[Output]:
        """world -> tob (the filter's estimate at its stamp) and tob -> tip."""
        if not msg.HasField("world_T_tob"):
            return []
        stamp = msg.header.stamp_ns
        if not self._tf_due("tob", stamp):
            return []
        return [(T_TRANSFORMS, FrameTransforms(transforms=[
            _transform(stamp, WORLD, TOB, msg.world_T_tob), _transform(stamp, TOB, TIP, self._tob_T_tip)]))]

    def _on_status(self, t_ns: int, msg: pb.ControllerStatus) -> list[Output]:
        """world -> flange_desired; the last path once recording stops."""
        out: list[Output] = []
        if msg.HasField("world_T_desired") and self._tf_due("desired", msg.header.stamp_ns):
            out.append((T_TRANSFORMS, FrameTransforms(transforms=[
                _transform(msg.header.stamp_ns, WORLD, FLANGE_DESIRED, msg.world_T_desired)])))
        if self._recording and not msg.recording and self._path_sent < len(self.path):
            out += self._path_messages()
        self._recording = msg.recording
        return out

    # -- the recorded path -------------------------------------------------------------------------
    def _on_path(self, t_ns: int, msg: pb.PathPoint) -> list[Output]:
        """A new recorded point: the path (PosesInFrame, now and then) and the seam strip."""
        if msg.index == 0 or not self.path or msg.index <= self.path[-1].index:
            self.path, self._path_sent = [], 0  # the controller started a new path
            self.path_number += 1
        self.path.append(msg)
        out: list[Output] = []
        grown = len(self.path) - self._path_sent
        if grown >= max(1, math.ceil(self._path_sent * self.config.path_resend_fraction)):
            out += self._path_messages()
        n = self.config.seam_strip_points
        k = max(0, len(self.path) - 2) // (n - 1)  # strip k: points k(n-1) .. k(n-1) + n-1 (ends shared)
        strip = self.path[k * (n - 1):]
        points = [self._seam_point(p) for p in strip]
        if len(points) >= 2:
            out.append(self._entities(msg.header.stamp_ns, [self._line(
                f"path{self.path_number}/seam/{k}", msg.header.stamp_ns, points, PATH, 0.003)]))
        return out

    @staticmethod
    def _path_pose(p: pb.PathPoint) -> pb.Pose:
        """What a path point records: the driver tip when it has one, else G."""
        return p.world_T_tip if p.has_tip else p.world_T_tob

    def _seam_point(self, p: pb.PathPoint) -> Point3:
        t = self._path_pose(p).translation
        return Point3(x=t.x, y=t.y, z=t.z)

    def _path_messages(self) -> list[Output]:
        """The whole path as poses (scene/path) and as points (scene/path_points: rerun's
        MCAP import draws a PointCloud as Points3D, a PosesInFrame only as poses)."""
        self._path_sent = len(self.path)
        ts = timestamp(self.path[-1].header.stamp_ns)
        poses = [self._path_pose(p) for p in self.path]
        xyz = np.array([[p.translation.x, p.translation.y, p.translation.z] for p in poses], dtype="<f4")
        return [(T_PATH, PosesInFrame(timestamp=ts, frame_id=WORLD, poses=[_fox_pose(p) for p in poses])),
                (T_PATH_POINTS, PointCloud(timestamp=ts, frame_id=WORLD, pose=_identity(),
                                           point_stride=12, fields=_XYZ_FLOAT32, data=xyz.tobytes()))]

    def _on_truth(self, t_ns: int, msg: pb.Truth) -> list[Output]:
        """The operator's true seam (the true tip, else G) as world line strips."""
        if not (msg.HasField("world_T_tob") or msg.has_tip):
            return []
        t = (msg.world_T_tip if msg.has_tip else msg.world_T_tob).translation
        p = (t.x, t.y, t.z)
        if self.truth_seam and math.dist(p, self.truth_seam[-1]) < self.config.truth_step_mm * 1e-3:
            return []
        self.truth_seam.append(p)
        n = self.config.seam_strip_points
        k = max(0, len(self.truth_seam) - 2) // (n - 1)
        strip = [Point3(x=x, y=y, z=z) for x, y, z in self.truth_seam[k * (n - 1):]]
        if len(strip) < 2:
            return []
        return [self._entities(msg.header.stamp_ns, [self._line(f"truth/seam/{k}", msg.header.stamp_ns, strip,
                                                                 TRUTH, 0.002)])]

    # -- the image ---------------------------------------------------------------------------------
    def _on_tob(self, t_ns: int, msg: pb.TobMeasurement) -> list[Output]:
        """Overlays for the image the measurement is about (same stamp: capture), and now and
        then the camera's calibration and the target entity."""
        stamp = msg.header.stamp_ns
        ts = timestamp(stamp)
        centres = [Point2(x=c.u, y=c.v) for c in msg.centers_px]
        ann = ImageAnnotations(timestamp=ts)
        for c in centres:
            ann.circles.append(CircleAnnotation(timestamp=ts, position=c, diameter=10.0, thickness=1.5,
                                                outline_color=MEASURED, fill_color=_rgba(0, 0, 0, 0)))
        full = msg.status == pb.TOB_STATUS_FULL
        for i, pair in enumerate(msg.pairs):
            if pair.right >= len(centres) or pair.left >= len(centres):
                continue
            colour = PAIR[i % 3]
            right, left = centres[pair.right], centres[pair.left]
            ann.points.append(PointsAnnotation(timestamp=ts, type=PointsAnnotation.LINE_LIST, points=[right, left],
                                               outline_color=colour, thickness=1.0))
            name = _LABELS[i] if full and i < 3 else str(i + 1)
            for side, at in (("R", right), ("L", left)):
                ann.texts.append(TextAnnotation(timestamp=ts, position=Point2(x=at.x + 7.0, y=at.y - 7.0),
                                                text=f"{name} {side}", font_size=12.0, text_color=colour,
                                                background_color=SHADE))
        out: list[Output] = [(T_ANNOTATIONS, ann)]
        if self.measurements % self.config.republish_every == 0:
            out += [self._calibration(stamp), self._target(stamp)]
        self.measurements += 1
        return out

    def _calibration(self, stamp_ns: int) -> Output:
        """foxglove.CameraCalibration of the real camera (plumb_bob = OpenCV k1 k2 p1 p2 k3).
        The complex image holds two virtual views; both share these intrinsics and the
        lens, and their centres are the camera_right / camera_left frames."""
        p = self._params
        K = p.real_camera_matrix
        w, h = p.image_size_px
        P = np.hstack([K, np.zeros((3, 1))])
        return (T_CALIBRATION, CameraCalibration(
            timestamp=timestamp(stamp_ns), frame_id=self.config.camera_frame, width=w, height=h,
            distortion_model="plumb_bob", D=list(p.dist_coeffs), K=K.ravel().tolist(),
            R=np.eye(3).ravel().tolist(), P=P.ravel().tolist()))

    def _target(self, stamp_ns: int) -> Output:
        """The target triangle in its own frame (``tob``: Foxglove moves it with the frame)."""
        ts = timestamp(stamp_ns)
        d_m = self.rig.target.source_diameter_mm * 1e-3
        ent = SceneEntity(timestamp=ts, frame_id=TOB, id="target", frame_locked=True)
        corners = [Point3(x=x, y=y, z=z) for x, y, z in self._sources_m.tolist()]
        for label, c in zip(_LABELS, corners, strict=True):
            ent.spheres.append(SpherePrimitive(pose=Pose(position=Vector3(x=c.x, y=c.y, z=c.z),
                                                         orientation=Quaternion(w=1.0)),
                                               size=Vector3(x=d_m, y=d_m, z=d_m), color=FILTERED))
            ent.texts.append(TextPrimitive(pose=Pose(position=Vector3(x=c.x, y=c.y, z=c.z + 0.01),
                                                     orientation=Quaternion(w=1.0)),
                                           billboard=True, font_size=14.0, scale_invariant=True, color=WHITE,
                                           text=label))
        ent.lines.append(LinePrimitive(type=LinePrimitive.LINE_LOOP, pose=_identity(),
                                       thickness=0.002, points=corners, color=FILTERED))
        return (T_ENTITIES, SceneUpdate(entities=[ent]))

    # -- entities ----------------------------------------------------------------------------------
    @staticmethod
    def _line(entity_id: str, stamp_ns: int, points: list[Point3], colour: Color, thickness_m: float) -> SceneEntity:
        ent = SceneEntity(timestamp=timestamp(stamp_ns), frame_id=WORLD, id=entity_id, frame_locked=False)
        ent.lines.append(LinePrimitive(type=LinePrimitive.LINE_STRIP, pose=_identity(),
                                       thickness=thickness_m, points=points, color=colour))
        return ent

    @staticmethod
    def _entities(stamp_ns: int, entities: list[SceneEntity]) -> Output:
        return (T_ENTITIES, SceneUpdate(entities=entities))

    # -- events -> log -----------------------------------------------------------------------------
    def _bind(self, port: Port):
        if port.handler == "_on_event":  # the component is in the topic (a Log line's name)
            return functools.partial(self._on_event, port.topic.split("/")[0])
        return super()._bind(port)

    def _on_event(self, component: str, t_ns: int, msg: pb.Event) -> list[Output]:
        """One foxglove.Log line per event; the controller's dz_mm changes move D."""
        if component == "controller" and msg.code == "param_changed":
            m = _DZ_CHANGED.search(msg.text)
            if m:
                self._set_dz(float(m.group(1)))
        text = f"{msg.code}: {msg.text}" if msg.code else msg.text
        return [(T_LOG, Log(timestamp=timestamp(msg.header.stamp_ns), level=_LEVEL.get(msg.severity, Log.UNKNOWN),
                            message=text, name=component))]
