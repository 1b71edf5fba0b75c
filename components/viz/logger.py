"""humanpt messages -> rerun log calls, on a given RecordingStream.

The same :class:`RerunLogger` serves the live view (the viz shell's adapter) and
``humanpt view`` (a recorded run), so both show the same entities under the same
blueprint (``blueprint.py``).  It holds only what drawing needs across messages (the
latest robot poses, the filter's latest state, the path so far); it never raises out of
:meth:`RerunLogger.log` (a message it cannot draw is counted and skipped).

Units: rerun's 3D world is in metres (as the messages); plots read mm, degrees and ms as
the paper's figures do.  Timelines: ``stamp`` is the data's own stamp (image capture,
ALTER cycle), so an image and its detections line up; a duration from the run's start for
virtual-time (lock-step) runs, a wall-clock timestamp otherwise.  ``humanpt view`` adds
``recorded`` (when the producing component made the message); the live view has rerun's
own ``log_time`` (when viz received it).

Entity paths (the blueprint's views are rooted at ``world``, ``image``, ``plots``, ``events``):

=====================================  ================================================
``world``                              robot base frame, z up (ViewCoordinates)
``world/flange``                       world_T_flange (robot_gateway/robot_state), axes
``world/flange/camera``                flange_T_camera (hand-eye), axes
``world/flange/camera/psvs``           the PSVS camera frustum (Pinhole, to d_z)
``world/flange/camera/desired``        the virtual point D (camera_T_desired(d_z)), axes
``world/flange/camera/measured``       camera_T_tob of the last FULL measurement, axes
``world/flange/camera/points``         triangulated source points (camera frame)
``world/tob``                          filtered world_T_tob (pose_filter/tob_state), axes
``world/tob/sources``                  the three light sources A, B, C (TOB frame)
``world/desired_flange``               where the servo wants the flange (controller/status)
``world/path/<n>/g/<k>``               recorded path n (G), strips of ``path_strip_points``
``world/path/<n>/tip/<k>``             the driver tip P's path, when recorded
``world/path/<n>/sigma/<k>``           the recorded point's (tip's, else G's) position
                                       uncertainty: ellipsoids of ``path_sigmas`` standard
                                       deviations, magnified ``path_sigma_magnify`` times;
                                       held-orientation points in HELD_RGB
``world/path/<n>/held/<k>``            points recorded with the orientation held
                                       (one or two sources visible)
``world/truth/tob``, ``.../sources``   twin: the true target (operator/truth)
``world/truth/tip``                    twin: the true driver tip
``world/truth/flange``                 twin: the true flange (sim_robot/truth)
``image``                              the complex image (camera/image)
``image/centers``                      every detected blob centre
``image/pairs``                        right-left pairs (lines), labelled A, B, C when FULL
``image/expected``                     the sources where the filter expected them
``image/desired``                      the sources where they would be with G at D
``image/truth``                        twin: the sources' true positions
``plots/error/*``                      |G - D| (mm), angle (deg); ``true_*``: from the twin's truth
``plots/command/*``                    commanded flange velocity (mm/s, deg/s per axis)
``plots/latency/*``                    capture -> command, robot state -> command (ms)
``plots/tracking/*``                   visible sources, perception quality, missed ALTER cycles
``plots/servo/*``                      field-of-view margin and G's image offset (px), the
                                       commanded fraction of the rotation (controller/status)
``plots/path/*``                       each path point's position sd (mm, largest axis) and
                                       orientation sd (deg), held orientation (1)
``events/<component>``                 events (TextLog), console commands
``status``                             controller mode, recording, path points (TextDocument)
=====================================  ================================================
"""

from __future__ import annotations

import json
import logging
import re
from collections import deque

import numpy as np
import rerun as rr
from scipy.spatial.transform import Rotation

from humanpt.geometry import (
    apply_step,
    camera_T_desired,
    invert_transform,
    project,
    rotation_angle_rad,
)
from humanpt.geometry.frames import NEAREST_HOLD, Backwards, FrameGraph, Repeat, TimedPoses
from humanpt.geometry.rig import Rig
from humanpt.geometry.units import to_m, to_mm
from humanpt.runtime import cycle as cell_cycle
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_image, from_pose, image_stamp_ns
from humanpt.viz.config import VizConfig

log = logging.getLogger("humanpt.viz")

__all__ = ["RerunLogger", "ENTITIES"]

# Colours (RGB): measured orange, filtered/expected cyan, desired green, truth magenta.
MEASURED_RGB = (255, 150, 30)
FILTERED_RGB = (40, 200, 255)
DESIRED_RGB = (60, 220, 90)
TRUTH_RGB = (230, 60, 230)
PATH_RGB = (255, 230, 40)
TIP_RGB = (255, 90, 90)
HELD_RGB = (255, 60, 0)  # path points whose orientation was held, not measured
PAIR_RGB = ((255, 80, 80), (80, 255, 80), (90, 140, 255))

ENTITIES = {
    "flange": "world/flange",
    "camera": "world/flange/camera",
    "frustum": "world/flange/camera/psvs",
    "desired": "world/flange/camera/desired",
    "measured": "world/flange/camera/measured",
    "points": "world/flange/camera/points",
    "tob": "world/tob",
    "sources": "world/tob/sources",
    "desired_flange": "world/desired_flange",
    "path": "world/path",
    "seam": "world/seam",
    "truth_tob": "world/truth/tob",
    "truth_tip": "world/truth/tip",
    "truth_flange": "world/truth/flange",
    "image": "image",
    "centers": "image/centers",
    "pairs": "image/pairs",
    "expected": "image/expected",
    "image_desired": "image/desired",
    "image_truth": "image/truth",
    "error_t": "plots/error/translation_mm",
    "error_r": "plots/error/rotation_deg",
    "true_error_t": "plots/error/true_translation_mm",
    "true_error_r": "plots/error/true_rotation_deg",
    "cmd_v": "plots/command/velocity_mm_s",
    "cmd_w": "plots/command/angular_deg_s",
    "lat_capture": "plots/latency/capture_to_command_ms",
    "lat_state": "plots/latency/state_to_command_ms",
    "visible": "plots/tracking/visible",
    "quality": "plots/tracking/quality",
    "misses": "plots/tracking/missed_cycles",
    "fov_margin": "plots/servo/fov_margin_px",
    "image_error": "plots/servo/image_error_px",
    "rotation_scale": "plots/servo/rotation_scale",
    "path_sd_mm": "plots/path/position_sd_mm",
    "path_sd_deg": "plots/path/orientation_sd_deg",
    "path_held": "plots/path/orientation_held",
    "status": "status",
}

_LEVELS = {
    pb.SEVERITY_DEBUG: "DEBUG",
    pb.SEVERITY_INFO: "INFO",
    pb.SEVERITY_WARNING: "WARN",
    pb.SEVERITY_ERROR: "ERROR",
    pb.SEVERITY_FATAL: "CRITICAL",
}
_DZ_CHANGED = re.compile(r"\bdz_mm = ([-+0-9.eE]+)")
_EPOCH_LIKE_NS = 10**18  # stamps after 2001: wall clock; before: virtual time from 0
_LABELS = ("A", "B", "C")


def _translation(p: pb.Pose) -> list[float]:
    return [p.translation.x, p.translation.y, p.translation.z]


def _transform(p: pb.Pose) -> rr.Transform3D:
    q = [p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w]
    if not any(q):  # an unset rotation is the identity (as schemas.convert reads it)
        q = [0.0, 0.0, 0.0, 1.0]
    return rr.Transform3D(translation=_translation(p), quaternion=q)


def display_lut(gamma: float) -> np.ndarray:
    """(256,) uint8 look-up table of the display transfer: 255 * (v / 255) ** gamma, rounded."""
    return np.rint(255.0 * (np.arange(256) / 255.0) ** gamma).astype(np.uint8)


class RerunLogger:
    """Logs humanpt messages to ``rec`` (a ``rerun.RecordingStream``).

    ``recorded_timeline``: also set the ``recorded`` timeline from each message's ``t_ns``
    (``humanpt view``: when the producing component made it).  Call :meth:`log` with
    every message, in time order; :attr:`counts` says how many per topic were drawn and
    :attr:`errors` how many could not be.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        config: VizConfig | None = None,
        *,
        rig: Rig | None = None,
        recorded_timeline: bool = False,
    ):
        self.rec = rec
        self.config = config or VizConfig()
        self.rig = Rig() if rig is None else rig
        self.recorded_timeline = recorded_timeline
        self.params = self.rig.params()
        self.sources_mm = self.rig.target_model().source_positions_mm  # (3, 3) TOB frame
        self.flange_T_camera = self.rig.hand_eye.flange_T_camera_m()
        self.dz_mm = float(self.config.dz_mm)
        self._display_lut = display_lut(self.config.display_gamma)
        self.counts: dict[str, int] = {}
        self.errors: dict[str, int] = {}
        self._virtual: bool | None = None  # decided by the first stamp
        # The cell's frames (geometry.frames), m: world -> flange from the robot states (the
        # latest 256; an earlier stamp, a restarted robot, starts them again), answered with
        # the state nearest an image's stamp; flange -> camera the rig's hand-eye.
        self.frames = FrameGraph()
        self._robot = self.frames.add_timed(
            "world", "flange", TimedPoses(256, repeat=Repeat.KEEP, backwards=Backwards.RESTART), NEAREST_HOLD)
        self.frames.add_static("flange", "camera", self.flange_T_camera)
        # The link's cycle (ns), from the latest robot state that carries it (runtime/cycle.py).
        self.cycle_period_ns = cell_cycle.FALLBACK_NS
        self._state: pb.TobState | None = None
        self._last_measurement_ns = 0  # image capture stamp of the last command drawn
        self._shown_images: deque[int] = deque(maxlen=64)  # stamps of the images drawn
        self._pending: dict[int, list] = {}  # image stamp -> overlays waiting for their image
        self._path_n = 0
        self._path_g: list[list[float]] = []
        self._path_tip: list[list[float]] = []
        self._path_sigma: list[tuple[list[float], list[float], list[float], bool]] = []  # centre, half sizes, quat
        self._path_held: list[list[float]] = []
        self._last_index = -1
        self._status_text = ""
        self._static_done = False

    # -- the one entry point ----------------------------------------------------------------
    def log(self, topic: str, msg, t_ns: int | None = None) -> None:
        """Draw one message of ``topic`` (a short bus topic, e.g. ``perception/tob``).
        ``t_ns``: when it was made (view) or received (live), ns; used for latencies."""
        handler = _HANDLERS.get(topic)
        if handler is None:
            if topic.endswith("/events"):
                handler = RerunLogger._event
            else:
                return
        try:
            if not self._static_done:
                self._log_static()
            handler(self, topic, msg, t_ns)
            self.counts[topic] = self.counts.get(topic, 0) + 1
        except Exception as e:  # noqa: BLE001 - a view must never take its component down
            n = self.errors[topic] = self.errors.get(topic, 0) + 1
            if n == 1:
                log.warning(
                    "viz: cannot draw a message on %s: %s (further ones are counted)", topic, e
                )

    # -- time ------------------------------------------------------------------------------------
    def _time(self, stamp_ns: int, t_ns: int | None) -> None:
        first = self._virtual is None
        if first:
            self._virtual = stamp_ns < _EPOCH_LIKE_NS
        stamp_ns = int(stamp_ns)
        if self._virtual:
            self.rec.set_time("stamp", duration=np.timedelta64(stamp_ns, "ns"))
        else:
            self.rec.set_time("stamp", timestamp=np.datetime64(stamp_ns, "ns"))
        if self.recorded_timeline and t_ns is not None:
            t_ns = int(t_ns)
            if self._virtual:
                self.rec.set_time("recorded", duration=np.timedelta64(t_ns, "ns"))
            else:
                self.rec.set_time("recorded", timestamp=np.datetime64(t_ns, "ns"))
        if first:
            self._log_desired()

    # -- static scene -----------------------------------------------------------------------------
    def _log_static(self) -> None:
        self._static_done = True
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        F = self.flange_T_camera
        rec.log(
            ENTITIES["camera"],
            rr.Transform3D(translation=F[:3, 3], mat3x3=F[:3, :3]),
            rr.TransformAxes3D(0.03),
            static=True,
        )
        K = self.params.real_camera_matrix
        w, h = self.params.image_size_px
        rec.log(
            ENTITIES["frustum"],
            rr.Pinhole(
                image_from_camera=K,
                resolution=[w, h],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=self.dz_mm * 1e-3,
                color=(180, 180, 180),
            ),
            static=True,
        )
        rec.log(ENTITIES["flange"], rr.TransformAxes3D(0.08), static=True)
        rec.log(ENTITIES["tob"], rr.TransformAxes3D(0.04), static=True)
        rec.log(ENTITIES["truth_tob"], rr.TransformAxes3D(0.03), static=True)
        rec.log(ENTITIES["truth_flange"], rr.TransformAxes3D(0.05), static=True)
        rec.log(ENTITIES["desired_flange"], rr.TransformAxes3D(0.05), static=True)
        src_m = self.sources_mm * 1e-3
        rec.log(
            ENTITIES["sources"],
            rr.Points3D(
                src_m,
                radii=self.rig.target.source_diameter_mm * 0.5e-3,
                colors=FILTERED_RGB,
                labels=list(_LABELS),
            ),
            static=True,
        )
        rec.log(
            f"{ENTITIES['truth_tob']}/sources",
            rr.Points3D(src_m, radii=self.rig.target.source_diameter_mm * 0.5e-3, colors=TRUTH_RGB),
            static=True,
        )
        rec.log(
            ENTITIES["desired"],
            rr.Points3D([[0.0, 0.0, 0.0]], radii=0.004, colors=DESIRED_RGB, labels=["D"]),
            rr.TransformAxes3D(0.03),
            static=True,
        )
        series = {
            "error_t": ("|G - D|", FILTERED_RGB),
            "error_r": ("angle(G, D)", FILTERED_RGB),
            "true_error_t": ("true |G - D|", TRUTH_RGB),
            "true_error_r": ("true angle(G, D)", TRUTH_RGB),
            "lat_capture": ("image capture -> command", MEASURED_RGB),
            "lat_state": ("robot state -> command", FILTERED_RGB),
            "visible": ("visible sources", DESIRED_RGB),
            "quality": ("perception quality", MEASURED_RGB),
            "misses": ("missed ALTER cycles", TIP_RGB),
        }
        for key, (name, rgb) in series.items():
            rec.log(ENTITIES[key], rr.SeriesLines(names=name, colors=rgb), static=True)
        xyz = [(230, 60, 60), (60, 200, 60), (60, 100, 230)]
        rec.log(
            ENTITIES["cmd_v"], rr.SeriesLines(names=["vx", "vy", "vz"], colors=xyz), static=True
        )
        rec.log(
            ENTITIES["cmd_w"], rr.SeriesLines(names=["wx", "wy", "wz"], colors=xyz), static=True
        )

    def _log_desired(self) -> None:
        """D on the camera axis at d_z, and where the sources would be in the image then."""
        self.rec.log(ENTITIES["desired"], rr.Transform3D(translation=[0.0, 0.0, self.dz_mm * 1e-3]))
        uv_r, uv_l = self._project(camera_T_desired(self.dz_mm))
        self.rec.log(
            ENTITIES["image_desired"],
            rr.Points2D(np.vstack([uv_r, uv_l]), radii=2.0, colors=DESIRED_RGB),
        )

    # -- geometry helpers ---------------------------------------------------------------------------
    def _project(self, camera_T_tob_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The sources of a target at ``camera_T_tob_mm`` in the complex image: (uv_R, uv_L), (3, 2) px."""
        p = self.sources_mm @ camera_T_tob_mm[:3, :3].T + camera_T_tob_mm[:3, 3]
        return project(self.params, p)

    @staticmethod
    def _camera_T_tob_mm(world_T_camera_m: np.ndarray, world_T_tob_m: np.ndarray) -> np.ndarray:
        return to_mm(invert_transform(world_T_camera_m) @ world_T_tob_m)

    # -- overlays on the complex image ------------------------------------------------------------
    def _overlay(self, stamp_ns: int, items: list) -> None:
        """Image overlays belong to their image: drawn at its stamp once it is shown (an
        image the core did not forward gets none, so nothing is drawn over the wrong one)."""
        if stamp_ns in self._shown_images:
            for entity, archetype in items:
                self.rec.log(entity, archetype)
        else:
            self._pending.setdefault(stamp_ns, []).extend(items)
            while len(self._pending) > 16:
                self._pending.pop(next(iter(self._pending)))

    # -- handlers -------------------------------------------------------------------------------------
    def _image(self, topic, msg, t_ns) -> None:
        stamp = image_stamp_ns(msg)
        pixels = from_image(msg)
        if pixels.dtype == np.uint8:
            pixels = self._display_lut[pixels]
        self._time(stamp, t_ns)
        if pixels.ndim == 2:
            img = rr.Image(pixels, color_model="L")
        else:
            img = rr.Image(pixels, color_model="BGR" if msg.encoding == "bgr8" else "RGB")
        self.rec.log(ENTITIES["image"], img)
        self._shown_images.append(stamp)
        for entity, archetype in self._pending.pop(stamp, []):
            self.rec.log(entity, archetype)

    def _tob(self, topic, msg: pb.TobMeasurement, t_ns) -> None:
        stamp = msg.header.stamp_ns
        self._time(stamp, t_ns)
        centers = np.array([[c.u, c.v] for c in msg.centers_px], dtype=float).reshape(-1, 2)
        full = msg.status == pb.TOB_STATUS_FULL
        strips, labels, colors = [], [], []
        for i, p in enumerate(msg.pairs):
            if p.right < len(centers) and p.left < len(centers):
                strips.append([centers[p.right], centers[p.left]])
                labels.append(_LABELS[i] if full and i < 3 else str(i + 1))
                colors.append(PAIR_RGB[i % 3])
        items = [
            (ENTITIES["centers"], rr.Points2D(centers, radii=3.0, colors=MEASURED_RGB)),
            (ENTITIES["pairs"], rr.LineStrips2D(strips, colors=colors, labels=labels, radii=0.8)),
        ]
        expected = np.zeros((0, 2))
        world_T_camera = self.frames.lookup("world", "camera", stamp)
        if self._state is not None and world_T_camera is not None:
            world_T_tob = self._state_at(stamp)
            if world_T_tob is not None:
                uv_r, uv_l = self._project(self._camera_T_tob_mm(world_T_camera, world_T_tob))
                expected = np.vstack([uv_r, uv_l])
        items.append((ENTITIES["expected"], rr.Points2D(expected, radii=4.0, colors=FILTERED_RGB)))
        self._overlay(stamp, items)
        # 3D: the measured frame and points, in the camera frame at the capture.
        if full:
            self.rec.log(
                ENTITIES["measured"], _transform(msg.camera_T_tob), rr.TransformAxes3D(0.03)
            )
        else:  # no pose measured: no frame drawn
            self.rec.log(ENTITIES["measured"], rr.Clear(recursive=False))
        pts = np.array([[v.x, v.y, v.z] for v in msg.points_camera_m], dtype=float).reshape(-1, 3)
        self.rec.log(
            ENTITIES["points"],
            rr.Points3D(
                pts,
                radii=0.003,
                colors=MEASURED_RGB,
                labels=list(_LABELS[: len(pts)]) if full else None,
            ),
        )
        self.rec.log(ENTITIES["visible"], rr.Scalars(float(msg.visible)))
        self.rec.log(ENTITIES["quality"], rr.Scalars(float(msg.quality)))

    def _state_at(self, stamp_ns: int) -> np.ndarray | None:
        """The filter's latest state moved to ``stamp_ns`` with its velocities (m)."""
        st = self._state
        if st.status not in (pb.TOB_STATUS_FULL, pb.TOB_STATUS_POSITION_ONLY):
            return None
        T = from_pose(st.world_T_tob)
        dt = (stamp_ns - st.header.stamp_ns) * 1e-9
        v = np.array([st.linear_velocity_m_s.x, st.linear_velocity_m_s.y, st.linear_velocity_m_s.z])
        w = np.array(
            [st.angular_velocity_rad_s.x, st.angular_velocity_rad_s.y, st.angular_velocity_rad_s.z]
        )
        return apply_step(T, v * dt, w * dt)

    def _tob_state(self, topic, msg: pb.TobState, t_ns) -> None:
        self._state = msg
        self._time(msg.header.stamp_ns, t_ns)
        if msg.status in (pb.TOB_STATUS_FULL, pb.TOB_STATUS_POSITION_ONLY):
            self.rec.log(ENTITIES["tob"], _transform(msg.world_T_tob))

    def _robot_state(self, topic, msg: pb.RobotState, t_ns) -> None:
        stamp = msg.header.stamp_ns
        T = from_pose(msg.world_T_flange)
        self._robot.add(stamp, T)
        period_ns = cell_cycle.from_state(msg.cycle_period_ns)
        if period_ns is not None:
            self.cycle_period_ns = period_ns
        self._time(stamp, t_ns)
        self.rec.log(ENTITIES["flange"], _transform(msg.world_T_flange))
        self.rec.log(ENTITIES["misses"], rr.Scalars(float(msg.missed_cycles)))

    def _command(self, topic, msg: pb.FlangeCommand, t_ns) -> None:
        stamp = msg.header.stamp_ns
        self._time(stamp, t_ns)
        per_s = 1e3 / cell_cycle.ms(self.cycle_period_ns)
        d_t = np.array([msg.d_translation_m.x, msg.d_translation_m.y, msg.d_translation_m.z])
        d_r = np.array([msg.d_rotation_rad.x, msg.d_rotation_rad.y, msg.d_rotation_rad.z])
        self.rec.log(ENTITIES["cmd_v"], rr.Scalars(d_t * 1e3 * per_s))
        self.rec.log(ENTITIES["cmd_w"], rr.Scalars(np.degrees(d_r) * per_s))
        if t_ns is not None:
            # A command is for the NEXT cycle (command ahead) and stamped with it, so its own
            # stamp is no start: the robot state it answers is the latest one seen, and the
            # image it uses is its measurement_stamp_ns (the first command using it counts).
            last_state_ns = self._robot.last_ns
            if last_state_ns is not None and t_ns >= last_state_ns:
                self.rec.log(ENTITIES["lat_state"], rr.Scalars((int(t_ns) - last_state_ns) * 1e-6))
            captured = msg.measurement_stamp_ns
            if captured and captured != self._last_measurement_ns and t_ns >= captured:
                self._last_measurement_ns = captured
                self.rec.log(ENTITIES["lat_capture"], rr.Scalars((int(t_ns) - captured) * 1e-6))

    def _status(self, topic, msg: pb.ControllerStatus, t_ns) -> None:
        self._time(msg.header.stamp_ns, t_ns)
        self.rec.log(ENTITIES["error_t"], rr.Scalars(msg.error_translation_m * 1e3))
        self.rec.log(ENTITIES["error_r"], rr.Scalars(float(np.degrees(msg.error_rotation_rad))))
        if msg.HasField("world_T_desired"):
            self.rec.log(ENTITIES["desired_flange"], _transform(msg.world_T_desired))
        if msg.visible:  # the field-of-view figures need a target
            self.rec.log(ENTITIES["fov_margin"], rr.Scalars(msg.fov_margin_px))
            self.rec.log(ENTITIES["image_error"], rr.Scalars(msg.image_error_px))
            self.rec.log(ENTITIES["rotation_scale"], rr.Scalars(msg.rotation_scale))
        mode = pb.ControlMode.Name(msg.mode).removeprefix("CONTROL_MODE_")
        text = (
            f"## {mode}\n\n| | |\n|---|---|\n| visible sources | {msg.visible} |\n"
            f"| recording | {'yes' if msg.recording else 'no'} |\n| path points | {msg.path_points} |\n"
            f"| calibration samples | {msg.calibration_samples} |\n"
            f"| saturated | {'yes' if msg.saturated else 'no'} |\n"
        )
        if text != self._status_text:  # a document per change, not per cycle
            self._status_text = text
            self.rec.log(
                ENTITIES["status"], rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN)
            )

    def _path(self, topic, msg: pb.PathPoint, t_ns) -> None:
        if self._path_n == 0 or msg.index <= self._last_index:
            self._path_n += 1
            self._path_g, self._path_tip, self._path_sigma, self._path_held = [], [], [], []
        self._last_index = msg.index
        self._time(msg.header.stamp_ns, t_ns)
        self._path_g.append(_translation(msg.world_T_tob))
        self._log_strip("g", self._path_g, PATH_RGB)
        if msg.has_tip:
            self._path_tip.append(_translation(msg.world_T_tip))
            self._log_strip("tip", self._path_tip, TIP_RGB)
        self._path_uncertainty(msg)

    def _path_uncertainty(self, msg: pb.PathPoint) -> None:
        """The point's position covariance as an ellipsoid (k sigma, magnified), the held
        orientation as a marker, and both sd's on the plots."""
        at = msg.world_T_tip if msg.has_tip else msg.world_T_tob
        cov = msg.tip_position_covariance_m2 if msg.has_tip else msg.position_covariance_m2
        centre = _translation(at)
        held = bool(msg.orientation_held)
        if len(cov) == 9:
            C = np.asarray(cov, dtype=float).reshape(3, 3)
            evals, evecs = np.linalg.eigh(0.5 * (C + C.T))
            sd = np.sqrt(np.clip(evals, 0.0, None))
            if np.linalg.det(evecs) < 0:  # a proper rotation for the quaternion
                evecs[:, 0] = -evecs[:, 0]
            quat = Rotation.from_matrix(evecs).as_quat().tolist()  # x, y, z, w
            half = (sd * self.config.path_sigmas * self.config.path_sigma_magnify).tolist()
            self._path_sigma.append((centre, half, quat, held))
            self._log_sigma_strip()
            self.rec.log(ENTITIES["path_sd_mm"], rr.Scalars(float(sd.max()) * 1e3))
        if len(msg.rotation_covariance_rad2) == 9:
            R = np.asarray(msg.rotation_covariance_rad2, dtype=float).reshape(3, 3)
            sd_deg = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(0.5 * (R + R.T)).max(), 0.0))))
            self.rec.log(ENTITIES["path_sd_deg"], rr.Scalars(sd_deg))
        self.rec.log(ENTITIES["path_held"], rr.Scalars(1.0 if held else 0.0))
        if held:
            self._path_held.append(centre)
            n = self.config.path_strip_points
            k = (len(self._path_held) - 1) // n
            self.rec.log(f"{ENTITIES['path']}/{self._path_n}/held/{k}",
                         rr.Points3D(self._path_held[k * n:], colors=HELD_RGB, radii=0.003))

    def _log_sigma_strip(self) -> None:
        n = self.config.path_strip_points
        k = (len(self._path_sigma) - 1) // n
        seg = self._path_sigma[k * n:]
        self.rec.log(
            f"{ENTITIES['path']}/{self._path_n}/sigma/{k}",
            rr.Ellipsoids3D(centers=[c for c, _, _, _ in seg], half_sizes=[h for _, h, _, _ in seg],
                            quaternions=[q for _, _, q, _ in seg],
                            colors=[HELD_RGB if held else PATH_RGB for *_, held in seg], line_radii=0.0003),
        )

    def _log_strip(self, which: str, points: list, rgb) -> None:
        n = self.config.path_strip_points
        k = (len(points) - 1) // (n - 1)
        # Strip k holds points k(n-1) .. k(n-1) + n - 1: consecutive strips share an end.
        seg = points[k * (n - 1) :]
        self.rec.log(
            f"{ENTITIES['path']}/{self._path_n}/{which}/{k}",
            rr.LineStrips3D([seg], colors=rgb, radii=0.0008),
            rr.Points3D(seg, colors=rgb, radii=0.0015),
        )

    def _truth(self, topic, msg: pb.Truth, t_ns) -> None:
        stamp = msg.header.stamp_ns
        self._time(stamp, t_ns)
        if topic == "operator/truth":
            self.rec.log(ENTITIES["truth_tob"], _transform(msg.world_T_tob))
            if msg.has_tip:
                self.rec.log(
                    ENTITIES["truth_tip"],
                    rr.Points3D([_translation(msg.world_T_tip)], colors=TRUTH_RGB, radii=0.002),
                )
        elif topic == "sim_robot/truth":
            self.rec.log(ENTITIES["truth_flange"], _transform(msg.world_T_flange))
        elif (
            topic == "sim_camera/truth"
            and msg.HasField("world_T_flange")
            and msg.HasField("world_T_tob")
        ):
            # At each image's capture: the true servo error and the sources' true pixels.
            world_T_flange, world_T_tob = from_pose(msg.world_T_flange), from_pose(msg.world_T_tob)
            world_T_camera = world_T_flange @ self.flange_T_camera
            desired = world_T_camera @ to_m(camera_T_desired(self.dz_mm))
            e_t = np.linalg.norm(world_T_tob[:3, 3] - desired[:3, 3]) * 1e3
            e_r = np.degrees(rotation_angle_rad(world_T_tob[:3, :3] @ desired[:3, :3].T))
            self.rec.log(ENTITIES["true_error_t"], rr.Scalars(e_t))
            self.rec.log(ENTITIES["true_error_r"], rr.Scalars(e_r))
            uv_r, uv_l = self._project(self._camera_T_tob_mm(world_T_camera, world_T_tob))
            self._overlay(
                stamp,
                [
                    (
                        ENTITIES["image_truth"],
                        rr.Points2D(np.vstack([uv_r, uv_l]), radii=1.5, colors=TRUTH_RGB),
                    )
                ],
            )

    def _event(self, topic, msg: pb.Event, t_ns) -> None:
        self._time(msg.header.stamp_ns or (t_ns or 0), t_ns)
        source = msg.source or topic.split("/", 1)[0]
        self.rec.log(
            f"events/{source}",
            rr.TextLog(
                f"{source}: {msg.code}: {msg.text}", level=_LEVELS.get(msg.severity, "INFO")
            ),
        )
        if source == "controller" and msg.code == "param_changed":
            m = _DZ_CHANGED.search(msg.text)
            if m:  # D moved: the 3D point and the desired pixels follow
                self.dz_mm = float(m.group(1))
                self._log_desired()

    def _console(self, topic, msg: pb.Command, t_ns) -> None:
        self._time(msg.header.stamp_ns or (t_ns or 0), t_ns)
        args = f" {msg.args_json}" if msg.args_json and msg.args_json != "{}" else ""
        if len(args) > 200:
            args = (
                f" ({len(json.loads(msg.args_json).get('points', []))} points...)"
                if "points" in args
                else " (...)"
            )
        self.rec.log(
            "events/console",
            rr.TextLog(f"console -> {msg.component or 'all'}: {msg.verb}{args}", level="INFO"),
        )


SEAM_LINE_RGB, SEAM_ARC_RGB, SEAM_CORNER_RGB = (60, 140, 255), (255, 150, 40), (255, 255, 255)


def log_seam(rec: rr.RecordingStream, name: str, strips_mm: list[np.ndarray], kinds: list[str],
             corners_mm: np.ndarray, corner_labels: list[str]) -> None:
    """A fitted seam (``humanpt path fit``) beside the recorded path, static: each segment a
    line strip (``strips_mm``: (k, 3) points in the world frame, mm; lines blue, arcs
    orange) under ``world/seam/<name>/<i>``, the corners as labelled points."""
    base = f"{ENTITIES['seam']}/{name}"
    for i, (pts, kind) in enumerate(zip(strips_mm, kinds, strict=True)):
        rec.log(f"{base}/{i}", rr.LineStrips3D([np.asarray(pts) * 1e-3], radii=0.0006,
                                               colors=SEAM_LINE_RGB if kind == "line" else SEAM_ARC_RGB,
                                               labels=[f"{i} {kind}"]), static=True)
    if len(corners_mm):
        rec.log(f"{base}/corners", rr.Points3D(np.asarray(corners_mm) * 1e-3, radii=0.002, colors=SEAM_CORNER_RGB,
                                               labels=corner_labels), static=True)


_HANDLERS = {
    "camera/image": RerunLogger._image,
    "perception/tob": RerunLogger._tob,
    "pose_filter/tob_state": RerunLogger._tob_state,
    "robot_gateway/robot_state": RerunLogger._robot_state,
    "controller/command": RerunLogger._command,
    "controller/status": RerunLogger._status,
    "controller/path": RerunLogger._path,
    "operator/truth": RerunLogger._truth,
    "sim_robot/truth": RerunLogger._truth,
    "sim_camera/truth": RerunLogger._truth,
    "console/command": RerunLogger._console,
}
