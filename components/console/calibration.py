"""Calibrating a running cell from Python: the live drivers of ``humanpt calibrate camera
--live``, ``humanpt calibrate hand-eye --live`` and ``humanpt calibrate tip --config``
(which parse and print).  They drive the
cell as the console does (console/command, the components' topics); the maths is
:mod:`humanpt.calibration`'s.

    from humanpt.console.calibration import collect_hand_eye_live
    from humanpt.calibration.handeye import solve_ax_yb
    A, B, notes = collect_hand_eye_live(load_config("cell.toml"), rig, n_poses=12)
    result = solve_ax_yb(A, B)
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from humanpt.calibration.camera import (
    CalibrationError,
    CameraCalibration,
    CameraSettings,
    calibrate_view,
    detect_views,
    report_lines,
)

if TYPE_CHECKING:
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.config import ConfigFile


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


# -- camera ---------------------------------------------------------------------------------------
def _mono(msg):
    """A foxglove.RawImage -> (h, w) uint8 grey."""
    import cv2
    import numpy as np

    from humanpt.schemas.convert import from_image

    pixels = np.asarray(from_image(msg))
    if pixels.ndim == 3 and msg.encoding in ("rgb8", "rgba8"):
        pixels = cv2.cvtColor(pixels, cv2.COLOR_RGB2GRAY if pixels.shape[2] == 3 else cv2.COLOR_RGBA2GRAY)
    elif pixels.ndim == 3:
        pixels = cv2.cvtColor(pixels, cv2.COLOR_BGR2GRAY if pixels.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    return np.ascontiguousarray(pixels, dtype=np.uint8)


def calibrate_camera_live(cfg: ConfigFile, rig: Rig, settings: CameraSettings, board, *, view: str = "right",
                          detector: str = "opencv", frame_timeout_s: float = 10.0, save: str | Path | None = None,
                          lines: Iterable[str] | None = None,
                          say: Callable[[str], None] = _stderr) -> tuple[CameraCalibration, list[str], list[str]]:
    """Capture views of ``board`` from the running cell's camera component (``cfg``'s cell)
    and calibrate ``view`` with ``detector``: each line of ``lines`` (default: this process's
    stdin; Enter) or a ``capture`` command on console/command (``humanpt console capture``)
    takes the NEXT frame of camera/image (the board has stopped moving by then), detects the
    board at once and says so; 'q', ``capture --finish`` or the end of the input finishes and
    calibrates.  ``save``: also write each captured frame there (PNG).  Returns (result,
    report lines, [])."""
    import queue
    import threading

    import cv2
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

    from humanpt.runtime.bus import open_tool_session
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas import topics

    if view == "both":
        raise CalibrationError("--live calibrates one view per run: --view right (left mirror covered), "
                               "then --view left")
    if detector == "both":
        raise CalibrationError("--live: one detector (opencv or paper); compare them later on --save'd images")
    key = f"{topics.KEY_PREFIX}/{cfg.runtime.cell}/camera/image"
    cond = threading.Condition()
    state = {"n": 0, "payload": None}

    def on_frame(sample) -> None:
        with cond:
            state["n"] += 1
            state["payload"] = sample.payload.to_bytes()
            cond.notify_all()

    save = Path(save) if save else None
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
    images, dets = [], []
    other = "left" if view == "right" else "right"
    say(f"live: {key}; cover the {other} mirror, hold the board still, Enter (or `humanpt console capture`) "
        "= capture, q (or `humanpt console capture --finish`) = finish")
    # Enter / q at this terminal, or `humanpt console capture [--finish]` from any machine.
    requests: queue.Queue = queue.Queue()
    taken = threading.Event()  # the last request is done: read the next line (one at a time)
    taken.set()

    def read_lines() -> None:
        for line in (sys.stdin if lines is None else lines):
            requests.put(line)
            taken.clear()
            taken.wait()
        requests.put(None)  # the end of the input: finish

    def on_console(sample) -> None:
        try:
            cmd = pb.Command.FromString(sample.payload.to_bytes())
        except Exception:  # noqa: BLE001 - a bad message on the bus is not ours to stop on
            return
        if cmd.component == "calibrate" and cmd.verb in ("capture", "finish"):
            requests.put("q" if cmd.verb == "finish" else "\n")

    with open_tool_session(cfg.runtime) as session:
        sub = session.declare_subscriber(key, on_frame)
        console = session.declare_subscriber(topics.TOPICS["console/command"].key(cfg.runtime.cell), on_console)
        threading.Thread(target=read_lines, name="calibrate-input", daemon=True).start()
        try:
            while True:
                line = requests.get()
                if line is None or line.strip().lower() in ("q", "quit"):
                    break
                with cond:
                    seen = state["n"]
                    if not cond.wait_for(lambda s=seen: state["n"] > s, timeout=frame_timeout_s):
                        raise CalibrationError(f"no frame on {key} within {frame_timeout_s:g} s "
                                               "(is the camera component up?)")
                    payload = state["payload"]
                grey = _mono(RawImage.FromString(payload))
                name = f"live-{len(images):02d}"
                images.append((name, grey))
                d = detect_views([(name, grey)], board, detector)[0]
                dets.append(d)
                if save is not None:
                    cv2.imwrite(str(save / f"{name}.png"), grey)
                say(f"{name}: " + (f"board found ({len(d.image_px)} corners)" if d.image_px is not None
                                   else "no board") + f", edge blur {d.blur_px:.2f} px")
                taken.set()  # this view is done: the next line may be read
        finally:
            sub.undeclare()
            console.undeclare()
    if not images:
        raise CalibrationError("no frames captured (press Enter to capture a view)")
    h, w = images[0][1].shape
    notes = []
    if (w, h) != tuple(rig.psvs.params().image_size_px):  # the rig takes the camera's size (apply_to_rig)
        if view != "right":
            raise CalibrationError(f"camera/image is {w} x {h} px, the rig's camera {rig.psvs.image_width_px} x "
                                   f"{rig.psvs.image_height_px} px: calibrate the right view at the new size first")
        notes.append(f"camera/image is {w} x {h} px, the rig's camera {rig.psvs.image_width_px} x "
                     f"{rig.psvs.image_height_px} px: the calibrated rig will say {w} x {h} px")
    cal = calibrate_view(dets, (w, h), view, settings, detector)
    result = CameraCalibration({view: cal})
    return result, notes + report_lines(result, {view: dets}), []


# -- hand-eye -------------------------------------------------------------------------------------
def load_pairs(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(A (n, 4, 4) world_T_flange, B (n, 4, 4) camera_T_target), mm, of a pairs file
    (:func:`save_pairs`'s JSON); HandEyeError naming the file when it is not one."""
    from humanpt.calibration.handeye import HandEyeError

    p = Path(path)
    if not p.is_file():
        raise HandEyeError(f"{p}: no such pairs file")
    try:
        data = json.loads(p.read_text())
        A = np.array([d["world_T_flange"] for d in data], dtype=float)
        B = np.array([d["camera_T_target"] for d in data], dtype=float)
    except (ValueError, TypeError, KeyError) as e:
        raise HandEyeError(f"{p}: not a JSON list of {{\"world_T_flange\", \"camera_T_target\"}} 4x4 pairs ({e})") \
            from None
    return A, B


def save_pairs(path: str | Path | None, A: np.ndarray, B: np.ndarray) -> None:
    """Write the pairs (A, B) to ``path`` as JSON (nothing for None)."""
    if path:
        Path(path).write_text(json.dumps([{"world_T_flange": a.tolist(), "camera_T_target": b.tolist()}
                                          for a, b in zip(A, B, strict=True)], indent=1))


def collect_hand_eye_live(cfg: ConfigFile, rig: Rig, n_poses: int = 12, timeout_s: float = 600.0,
                          progress: Callable[[int, int], None] | None = None
                          ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Drive a running cell through the planned poses (console commands to the controller
    over Zenoh, as ``humanpt console`` sends them) and collect the pairs from
    ``robot_gateway/robot_state`` and ``perception/tob``. Ctrl-C or the console's ``stop``
    ends it (the robot is told to hold); ``progress(poses done, poses)`` as they are
    collected. Returns (A (n, 4, 4), B (n, 4, 4), notes); HandEyeError when it could not
    collect three poses."""
    import queue
    import time

    from humanpt.calibration.handeye import HandEyeError, PoseCollector, plan_poses
    from humanpt.controller.config import ControllerConfig
    from humanpt.geometry.transforms import transform_from_x
    from humanpt.geometry.units import to_mm
    from humanpt.robot_gateway.config import GatewayConfig
    from humanpt.runtime.bus import open_tool_session
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas import topics
    from humanpt.schemas.convert import from_pose

    ctl = cfg.component("controller", ControllerConfig)
    gw = cfg.component("robot_gateway", GatewayConfig)
    cell = cfg.runtime.cell
    inbox: queue.Queue = queue.Queue()
    session = open_tool_session(cfg.runtime)
    names = ("robot_gateway/robot_state", "perception/tob", "controller/events", "robot_gateway/events")

    def into_inbox(name: str):
        return lambda smp: inbox.put((time.monotonic_ns(), name, smp.payload.to_bytes()))

    subs = [session.declare_subscriber(topics.TOPICS[n].key(cell), into_inbox(n)) for n in names]
    pub = session.declare_publisher(topics.TOPICS["console/command"].key(cell))
    seq = 0

    def send(cmd) -> None:
        nonlocal seq
        seq += 1
        pub.put(pb.Command(header=pb.Header(stamp_ns=time.time_ns(), seq=seq), component="controller",
                           verb=cmd[0], args_json=json.dumps(cmd[1])).SerializeToString())

    collector = None
    try:
        # Plan from where the robot is after a second of states (the servo may still be
        # settling when we connect).
        start, first = None, None
        deadline = time.monotonic() + 5.0
        while first is None or time.monotonic() < first + 1.0:
            try:
                _, n, data = inbox.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                raise HandEyeError(f"no robot state from the gateway in cell {cell} within 5 s (is the cell "
                                   "running, the robot in ALTER?)") from None
            if n == "robot_gateway/robot_state":
                state = pb.RobotState.FromString(data)
                start = to_mm(from_pose(state.world_T_flange))
                first = time.monotonic() if first is None else first
            elif n == "robot_gateway/events" and pb.Event.FromString(data).code == "robot_fault":
                raise HandEyeError(f"the robot is in FAULT ({pb.Event.FromString(data).text}); clear it first")
        from humanpt.calibration.handeye import puma_move_check
        from humanpt.geometry.puma import RobotModelConfig

        # The cell's Puma (puma762 unless [sim_robot] model says otherwise), checked by the
        # product's robot model (geometry.puma), not through the simulator's package.
        model = RobotModelConfig(model=cfg.sections.get("sim_robot", {}).get("model", "puma762")).model.value
        poses, notes = plan_poses(start, rig.hand_eye.flange_T_camera_mm(), ctl.dz_mm, n_poses=n_poses,
                                  envelope_min_mm=gw.envelope_min_mm, envelope_max_mm=gw.envelope_max_mm,
                                  check=puma_move_check(gw.world_T_base_mm_deg, model))
        collector = PoseCollector(poses, transform_from_x(np.asarray(ctl.flange_T_tool_x)))
        send(collector.start(time.monotonic_ns()))
        end = time.monotonic() + timeout_s
        done = 0
        while not collector.done:
            if time.monotonic() > end:
                collector.stop(f"out of time ({timeout_s:g} s)")
                break
            try:
                t, n, data = inbox.get(timeout=0.05)
                if n == "robot_gateway/robot_state":
                    collector.on_robot_state(t, to_mm(from_pose(pb.RobotState.FromString(data).world_T_flange)))
                elif n == "perception/tob":
                    m = pb.TobMeasurement.FromString(data)
                    collector.on_measurement(t, to_mm(from_pose(m.camera_T_tob)) if m.status == pb.TOB_STATUS_FULL
                                             else None)
                elif n == "controller/events":
                    e = pb.Event.FromString(data)
                    collector.on_controller_event(t, e.code, e.text)
                elif pb.Event.FromString(data).code == "robot_fault":
                    collector.end(f"the robot faulted ({pb.Event.FromString(data).text})")
            except queue.Empty:
                pass
            cmd = collector.poll(time.monotonic_ns())
            if cmd is not None:
                send(cmd)
            if collector.progress()[0] != done:
                done = collector.progress()[0]
                if progress is not None:
                    progress(done, len(poses))
    except KeyboardInterrupt:
        if collector is not None:
            collector.stop("interrupted (Ctrl-C)")
    finally:
        if collector is not None:
            send(("hold", {}))  # whatever happened, the robot stays where it is
        for s in subs:
            s.undeclare()
        pub.undeclare()
        session.close()
    if collector.aborted:
        raise HandEyeError(f"collection stopped: {collector.aborted}; nothing written")
    if len(collector.samples) < 3:
        raise HandEyeError(f"too few poses collected: {len(collector.samples)} of {len(collector.poses)} "
                           f"({'; '.join(collector.notes[-3:]) or 'none measured'}); nothing written")
    A = np.array([s.world_T_flange_mm for s in collector.samples])
    B = np.array([s.camera_T_target_mm for s in collector.samples])
    return A, B, notes + collector.notes


# -- the driver's tip ---------------------------------------------------------------------------
def calibrate_tip_live(cfg: ConfigFile, samples: int | None = None, timeout_s: float = 120.0,
                       say: Callable[[str], None] = _stderr):
    """Ask the running controller to calibrate the driver's tip (``samples`` poses, default
    its own) while the operator pivots the target on the needle's tip, and wait up to
    ``timeout_s`` for its result (a TipResult); ValueError when it refuses, fails or says
    nothing."""
    import queue
    import time

    from humanpt.calibration.tip import tip_result_from_event
    from humanpt.schemas import humanpt_pb2 as pb
    from humanpt.schemas import topics

    from .client import Console

    con = Console(cfg)
    try:
        events: queue.Queue = queue.Queue()
        sub = con.session.declare_subscriber(topics.TOPICS["controller/events"].key(cfg.runtime.cell),
                                             lambda s: events.put(s.payload.to_bytes()))
        try:
            if con.command("calibrate", {"samples": samples} if samples else {}) != 0:
                raise ValueError("the controller refused to calibrate")
            say("pivot the target on its needle's tip now (turn it +-20 deg about two axes)")
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                try:
                    ev = pb.Event.FromString(events.get(timeout=1.0))
                except queue.Empty:
                    continue
                if ev.code == "calibration_done":
                    return tip_result_from_event(ev.text)
                if ev.code == "calibration_failed":
                    raise ValueError(f"the controller's calibration failed: {ev.text}")
            raise ValueError(f"no result within {timeout_s:g} s (is the target in view and turning?)")
        finally:
            sub.undeclare()
    finally:
        con.close()
