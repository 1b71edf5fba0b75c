"""``humanpt calibrate hand-eye``: the camera on the flange (AX = YB).

The robot moves itself through N poses around a fixed target, the PSVS measures the target
at each, and AX = YB gives flange_T_camera, written to the rig's ``[hand_eye]``. Sources:
``--twin`` (the digital twin, ``--world``, ``--seed``), or ``--pairs FILE`` (pairs a live
cell collected: a JSON list of {"world_T_flange": 4x4 mm, "camera_T_target": 4x4 mm}).
The maths is :mod:`humanpt.calibration.handeye`; this module parses and prints."""

from __future__ import annotations

import datetime as _dt
import json
import sys
from pathlib import Path

import numpy as np

from humanpt.cli.calibrate import add_rig_args, add_world_args

__all__ = ["add_parser", "run"]


def add_parser(csub) -> None:
    p = csub.add_parser(
        "hand-eye", help="hand-eye calibration AX = YB: where the camera sits on the flange",
        description="The robot moves itself through --poses safe poses around a fixed target (through the "
        "controller's playback, the gateway's limits; the console's stop ends it), the PSVS measures the target "
        "at each while still, and AX = YB (Zhuang et al. 1994; closed form, then least squares) gives "
        "flange_T_camera with its 1-sigma, written to the rig's [hand_eye]. OpenCV's calibrateRobotWorldHandEye "
        "and calibrateHandEye cross-check it when the installed OpenCV has them.")
    add_rig_args(p)
    p.add_argument("--twin", action="store_true", help="observe the digital twin (its truth is only reported)")
    add_world_args(p)
    p.add_argument("--poses", type=int, default=None, help="poses to plan (default 12; at least 3)")
    p.add_argument("--pairs", default=None, help="solve from a JSON file of collected pairs: "
                   "[{\"world_T_flange\": 4x4 mm, \"camera_T_target\": 4x4 mm}, ...] (what --save-pairs writes)")
    p.add_argument("--live", action="store_true", help="drive a running cell (controller, gateway, robot, "
                   "camera, perception over Zenoh: --config/--cell/--connect); the target must be fixed in view")
    p.add_argument("--save-pairs", default=None, metavar="FILE", help="also write the collected pairs (JSON)")
    p.add_argument("--config", "-c", metavar="FILE", help="--live: the cell's TOML config file")
    p.add_argument("--cell", help="--live: cell name; overrides [runtime] cell")
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="--live: router endpoint (repeatable)")
    p.add_argument("--timeout", type=float, default=600.0, help="--live: give up after this many seconds")


def _fail(msg: str) -> int:
    print(f"humanpt calibrate hand-eye: {msg}", file=sys.stderr)
    return 2


def _load_pairs(path: str) -> tuple[np.ndarray, np.ndarray]:
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


def run(args) -> int:
    from humanpt.calibration.handeye import HandEyeError, apply_to_rig, solve_ax_yb
    from humanpt.geometry.rig import Rig
    from humanpt.runtime.config import ConfigError
    from humanpt.runtime.rigfile import load_rig, write_rig

    if sum((bool(args.twin), bool(args.pairs), bool(args.live))) != 1:
        return _fail("give one of --twin (observe the digital twin), --live (drive a running cell) or "
                     "--pairs FILE (pairs collected before)")
    if args.poses is not None and args.poses < 3:
        return _fail(f"--poses {args.poses}: too few; AX = YB needs at least 3 poses with rotations about two "
                     "non-parallel axes")
    rig_path = Path(args.rig)
    try:
        rig = load_rig(rig_path) if rig_path.exists() else Rig()
    except ConfigError as e:
        return _fail(str(e))
    truth: list[str] = []
    try:
        if args.twin:
            from humanpt.twin.cal_handeye import DEFAULT_POSES, calibrate_hand_eye_on_twin
            from humanpt.twin.worlds import World

            world = World.named(args.world)

            def progress(done: int, planned: int) -> None:
                print(f"\rhand-eye: pose {done}/{planned}", end="", file=sys.stderr, flush=True)

            result, report, truth = calibrate_hand_eye_on_twin(world, rig, args.seed, progress,
                                                               n_poses=args.poses or DEFAULT_POSES,
                                                               pairs_out=args.save_pairs)
            print(file=sys.stderr)
        elif args.live:
            from humanpt.cli.commands import load_cfg

            cfg = load_cfg(args)
            if not rig_path.exists():
                rig = cfg.rig()
            A, B, notes = collect_live(cfg, rig, args.poses or 12, args.timeout)
            _save_pairs(args.save_pairs, A, B)
            result = solve_ax_yb(A, B)
            report = [f"hand-eye on the live cell {cfg.runtime.cell}: {len(A)} poses collected",
                      *(f"  {n}" for n in notes), *result.summary_lines()]
        else:
            A, B = _load_pairs(args.pairs)
            result = solve_ax_yb(A, B)
            report = result.summary_lines()
    except (HandEyeError, ConfigError, ConnectionError) as e:
        print(file=sys.stderr)
        return _fail(str(e))
    print("\n".join(report))
    if truth:
        print("\n".join(truth))
    if args.dry_run:
        print("dry run: the rig is not written")
        return 0
    date = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    new = apply_to_rig(rig, result, date)
    write_rig(rig_path, new, f"hand-eye by humanpt calibrate hand-eye ({date})", overwrite=True)
    print(f"wrote [hand_eye] to {rig_path}" + (f" (the old rig kept as {rig_path.name}.bak)"
                                                if rig_path.with_name(rig_path.name + ".bak").exists() else ""))
    return 0


def _save_pairs(path: str | None, A: np.ndarray, B: np.ndarray) -> None:
    if path:
        Path(path).write_text(json.dumps([{"world_T_flange": a.tolist(), "camera_T_target": b.tolist()}
                                          for a, b in zip(A, B, strict=True)], indent=1))


def collect_live(cfg, rig, n_poses: int, timeout_s: float) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Drive a running cell through the planned poses (console commands to the controller
    over Zenoh, as ``humanpt console`` sends them) and collect the pairs from
    ``robot_gateway/robot_state`` and ``perception/tob``. Ctrl-C or the console's ``stop``
    ends it (the robot is told to hold). Returns (A (n, 4, 4), B (n, 4, 4), notes)."""
    import queue
    import time

    from humanpt.calibration.handeye import HandEyeError, PoseCollector, plan_poses
    from humanpt.controller.config import ControllerConfig
    from humanpt.geometry.transforms import transform_from_x
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

    def mm(T):
        T = np.array(T, dtype=float)
        T[:3, 3] *= 1e3
        return T

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
                start = mm(from_pose(state.world_T_flange))
                first = time.monotonic() if first is None else first
            elif n == "robot_gateway/events" and pb.Event.FromString(data).code == "robot_fault":
                raise HandEyeError(f"the robot is in FAULT ({pb.Event.FromString(data).text}); clear it first")
        from humanpt.calibration.handeye import puma_move_check
        from humanpt.sim_robot.config import SimRobotConfig

        model = cfg.component("sim_robot", SimRobotConfig).model  # the cell's Puma (puma762 unless set)
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
                    collector.on_robot_state(t, mm(from_pose(pb.RobotState.FromString(data).world_T_flange)))
                elif n == "perception/tob":
                    m = pb.TobMeasurement.FromString(data)
                    collector.on_measurement(t, mm(from_pose(m.camera_T_tob)) if m.status == pb.TOB_STATUS_FULL
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
                print(f"\rhand-eye: pose {done}/{len(poses)}", end="", file=sys.stderr, flush=True)
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
