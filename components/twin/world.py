"""The lock-step world: operator + stand-in robot + sim_camera (+ your cores) on virtual
time in one process, deterministically (:class:`humanpt.runtime.lockstep.Lockstep`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from humanpt.geometry import DEFAULT_DZ_MM, x_from_transform
from humanpt.operator import BUILTIN_SCENARIOS, OperatorConfig, OperatorCore
from humanpt.runtime.config import RecordConfig
from humanpt.runtime.core import Core
from humanpt.runtime.lockstep import Delivered, Lockstep
from humanpt.schemas.convert import from_image, image_stamp_ns
from humanpt.sim_camera import SimCameraConfig, SimCameraCore

from .standin import StandInRobotConfig, StandInRobotCore, viewing_start_flange

__all__ = ["TwinWorld", "build_world", "start_flange_for"]


def start_flange_for(
    operator: OperatorConfig,
    dz_mm: float = DEFAULT_DZ_MM,
    flange_T_camera: np.ndarray | None = None,
) -> np.ndarray:
    """world_T_flange (4, 4), mm, that puts the scenario's first target pose on the camera's
    optical axis at ``dz_mm``, parallel to the camera (the paper's desired point D)."""
    if flange_T_camera is None:
        flange_T_camera = SimCameraConfig().flange_T_camera
    return viewing_start_flange(operator.build_scenario(), dz_mm, flange_T_camera)


class TwinWorld:
    """A built world: ``lockstep`` and its cores (``operator``, ``robot`` - the stand-in,
    None when other robot cores replace it - ``camera``, ``extra``). Run it with :meth:`run_for` / :meth:`run_until`; read what happened with
    :meth:`outputs`, :meth:`images`, :meth:`truths`."""

    def __init__(
        self,
        lockstep: Lockstep,
        operator: OperatorCore,
        robot: StandInRobotCore | None,
        camera: SimCameraCore,
        extra: list[Core],
    ):
        self.lockstep = lockstep
        self.operator = operator
        self.robot = robot
        self.camera = camera
        self.extra = extra

    @property
    def now_ns(self) -> int:
        return self.lockstep.now_ns

    def run_until(self, t_ns: int) -> TwinWorld:
        self.lockstep.run_until(int(t_ns))
        return self

    def run_for(self, seconds: float) -> TwinWorld:
        return self.run_until(self.lockstep.now_ns + round(seconds * 1e9))

    def run_until_event(self, code: str, max_seconds: float, step_s: float = 0.25) -> bool:
        """Run in steps of ``step_s`` of twin time until a component has published an event
        ``code`` (True; the world stops within ``step_s`` after it), or for ``max_seconds``
        (False). Needs ``keep_outputs``."""
        from humanpt.schemas import humanpt_pb2 as pb

        if not self.lockstep.keep_outputs:
            raise RuntimeError("run_until_event reads the outputs: build the world with keep_outputs")
        end_ns = self.lockstep.now_ns + round(max_seconds * 1e9)
        while self.lockstep.now_ns < end_ns:
            seen = len(self.lockstep.outputs)
            self.run_until(min(end_ns, self.lockstep.now_ns + round(step_s * 1e9)))
            for o in self.lockstep.outputs[seen:]:
                if o.topic.endswith("/events") and pb.Event.FromString(o.data).code == code:
                    return True
        return False

    def digest(self) -> str:
        return self.lockstep.digest()

    def outputs(self, topic: str | None = None) -> list[Delivered]:
        return [o for o in self.lockstep.outputs if topic is None or o.topic == topic]

    def images(self) -> list[tuple[int, np.ndarray]]:
        """(capture stamp ns, (H, W) uint8) of every camera image so far."""
        from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

        out = []
        for o in self.outputs("camera/image"):
            msg = RawImage.FromString(o.data)
            out.append((image_stamp_ns(msg), from_image(msg).copy()))
        return out

    def truths(self, topic: str = "sim_camera/truth") -> list[tuple[int, dict[str, np.ndarray]]]:
        """(stamp ns, {field: (4, 4) in mm}) of a Truth topic (``operator/truth``,
        ``sim_robot/truth`` or ``sim_camera/truth``, the truth at each image's capture)."""
        from .evaluate import truths_from

        return truths_from(self.outputs(topic))

    def close(self) -> None:
        self.lockstep.close()

    def __enter__(self) -> TwinWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def build_world(
    scenario: str | OperatorConfig = "static",
    *,
    seed: int = 0,
    sim_camera: SimCameraConfig | None = None,
    robot: StandInRobotConfig | None = None,
    robot_cores: list[Core] | tuple[Core, ...] | None = None,
    extra_cores: list[Core] | tuple[Core, ...] = (),
    dz_mm: float = DEFAULT_DZ_MM,
    run_dir: str | Path | None = None,
    keep_outputs: bool = True,
    start_ns: int = 0,
    latency_ns: int = 0,
    digest: bool = True,
    record: RecordConfig | None = None,
) -> TwinWorld:
    """Assemble operator, stand-in robot and sim_camera (and ``extra_cores``, e.g. a
    perception or a controller) into a :class:`Lockstep`.

    ``scenario``: a built-in name, a scenario file path, or an :class:`OperatorConfig`.
    ``seed`` goes into the operator's and the camera's configs (same seed, same bytes).
    Without ``robot``, the flange starts where the camera sees the scenario's first pose
    on its optical axis at ``dz_mm`` (:func:`start_flange_for`). With ``run_dir`` every core
    is recorded there (``humanpt replay`` replays each), as ``record`` says (default
    ``[record]``'s defaults: a snapshot of each core every 10 s). ``robot_cores`` replaces the
    stand-in robot by other cores (e.g. ``sim_robot`` and ``robot_gateway``, wired with
    ``world.lockstep.connect_serial``); one of them must publish ``sim_robot/truth``.
    """
    if isinstance(scenario, OperatorConfig):
        op_cfg = dataclasses.replace(scenario, seed=seed)
    elif scenario in BUILTIN_SCENARIOS:
        op_cfg = OperatorConfig(scenario=scenario, seed=seed)
    else:
        op_cfg = OperatorConfig(scenario_file=str(scenario), seed=seed)
    cam_cfg = dataclasses.replace(sim_camera or SimCameraConfig(), seed=seed)
    robot_core = None
    if robot_cores is None:
        if robot is None:
            start = start_flange_for(op_cfg, dz_mm, cam_cfg.flange_T_camera)
            robot = StandInRobotConfig(
                start_flange_mm_deg=tuple(float(v) for v in x_from_transform(start))
            )
        robot_core = StandInRobotCore(robot)
        robot_cores = [robot_core]
    operator, camera = OperatorCore(op_cfg), SimCameraCore(cam_cfg)
    extra = list(extra_cores)
    ls = Lockstep(
        [operator, *robot_cores, camera, *extra],
        start_ns=start_ns,
        latency_ns=latency_ns,
        run_dir=run_dir,
        keep_outputs=keep_outputs,
        digest=digest,
        record=record,
    )
    return TwinWorld(ls, operator, robot_core, camera, extra)
