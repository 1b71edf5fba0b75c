"""Configuration of the scene component (section ``[scene]``).

The rig (hand-eye, PSVS, target, tip) comes from the rig file like every component's;
this section only says what the rig does not: where the robot base is, the desired
point's distance at start (the scene follows the controller's ``dz_mm`` changes), the
camera's frame id, and how often the slow-changing things are re-sent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from humanpt.geometry import DEFAULT_DZ_MM
from humanpt.runtime.config import Deg, Mm, Range, live

__all__ = ["SceneConfig"]


@dataclass(frozen=True)
class SceneConfig:
    """``[scene]`` (README.md of the component has the table)."""

    # The robot base in the world, X = (x, y, z mm, yaw, pitch, roll deg): the same value as
    # [robot_gateway] world_T_base_mm_deg (the twin sets both); only splits world -> flange
    # into world -> base -> flange for the 3D view.
    world_T_base_mm_deg: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (0.0,) * 6
    # Distance of the desired point D from the camera at start; follows the controller's
    # dz_mm (its param_changed events) afterwards.
    dz_mm: Annotated[float, Range(10, 5000, "mm")] = DEFAULT_DZ_MM
    # The frame id of camera/image (foxglove.RawImage.frame_id): CameraCalibration's frame.
    camera_frame: str = "camera"
    # CameraCalibration and the target entity (things that hardly change) go out with the
    # first perception measurement and every Nth after it, so a client that joins late (or
    # seeks in a recording) gets them: at 30 images/s, 30 is once a second.
    republish_every: Annotated[int, Range(1, 100000, "measurements")] = live(
        30, "re-send calibration and target every N perception measurements")
    # The recorded path (scene/path, PosesInFrame: the whole path in each message) is re-sent
    # when it grew by this fraction since it was last sent (at least one point), so a long
    # path costs O(N) bytes, not O(N^2); scene/entities draws every point at once anyway.
    path_resend_fraction: Annotated[float, Range(0.0, 1.0, "")] = 0.02
    # The seam (scene/entities) is drawn as line strips of at most this many points each:
    # an update re-sends only the strip being extended.
    seam_strip_points: Annotated[int, Range(2, 100000, "points")] = 200
    # The operator's true seam (operator/truth, twin only) gets a point when the true tip
    # (else G) moved this far since the last one.
    truth_step_mm: Annotated[float, Range(0.01, 1000, "mm")] = 2.0
    # Moving frames (robot state, the filter's target, the desired flange) are sent at most
    # this often each, by their stamps: a viewer draws 60 Hz, and a 4 ms robot link would
    # otherwise cost ~800 messages a second on a machine that also runs the link's cycle.
    transforms_max_hz: Annotated[float, Range(1, 10000, "Hz")] = live(
        60.0, "moving frames sent at most this often each")

    def __post_init__(self) -> None:
        if len(self.world_T_base_mm_deg) != 6:
            raise ValueError("scene.world_T_base_mm_deg needs six values (x, y, z mm, yaw, pitch, roll deg)")
        if not self.camera_frame:
            raise ValueError("scene.camera_frame must be a frame id (the camera/image frame_id), got ''")
