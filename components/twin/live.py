"""The whole system on the twin, live: the router, sim_robot behind a pty, robot_gateway,
operator, sim_camera, perception, pose_filter and controller (and viz) as separate
processes over Zenoh, each recording its MCAP in the run directory (``humanpt demo``).

With ``secure=True`` (``humanpt demo --secure``) the run is a cell under mTLS (issue 19):
a throwaway PKI in ``<run_dir>/pki`` (:func:`make_pki`: a CA valid 31 days (over the 30 days under which a certificate in use is warned about), a certificate
per process, the router's, an operator's for the run's own commands and a read-only
tool's), ``[runtime] security = "mtls"``, every process a client of the router (peer mode
is refused under mTLS), the router enforcing the access control generated from the topic
table.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from humanpt.geometry.transforms import invert_transform, transform_from_x, x_from_transform
from humanpt.runtime import config as cfgmod
from humanpt.runtime import launcher
from humanpt.runtime.bus import free_tcp_port, liveliness_key, open_tool_session
from humanpt.runtime.config import to_table
from humanpt.runtime.launcher import wait_listening
from humanpt.runtime.rigfile import write_rig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

from .run import SystemConfig
from .system import abb_link, arm_cores, rsi_link, ur_link
from .world import start_flange_for

__all__ = ["LIVE_COMPONENTS", "OPERATOR_IDENTITY", "LiveControl", "LiveResult", "live_sections", "make_pki",
           "run_live", "write_toml"]

LIVE_COMPONENTS = ("sim_robot", "robot_gateway", "sim_camera", "perception", "pose_filter", "controller", "scene")
SCREEN_COMPONENTS = ("scene", "foxglove_bridge", "viz")  # what the operator's screen shows, outside the loop
PKI_DIR = "pki"                    # under the run directory, with --secure
OPERATOR_IDENTITY = "demo-operator"  # the certificate the run's own session (and its tools) present
TOOL_IDENTITY = "tool"             # a read-only tool's certificate (humanpt topics --as tool)


def make_pki(run_dir: Path, cell: str, components: list[str] | tuple[str, ...]) -> Path:
    """A throwaway PKI for one run in ``run_dir/pki``: a CA valid 31 days (over the 30 days under which a certificate in use is warned about), a certificate
    for the router, each of ``components``, :data:`OPERATOR_IDENTITY` (role operator) and
    :data:`TOOL_IDENTITY` (role tool).  Returns the directory."""
    from humanpt.runtime import security

    d = run_dir / PKI_DIR
    security.init_ca(d, cell, days=31, force=True)
    for name in ("router", *components):
        security.issue(d, name, days=31, force=True)
    security.issue(d, OPERATOR_IDENTITY, role="operator", days=31, force=True)
    security.issue(d, TOOL_IDENTITY, role="tool", days=31, force=True)
    return d


def write_toml(path: Path, sections: dict[str, dict]) -> None:
    """Write {section: {key: value}} (nested tables too) as the run's TOML config."""
    path.write_text("# written by humanpt demo: the configuration of this run\n\n" + cfgmod.dumps_toml(sections))


def robot_table(robot) -> dict:
    """A simulated robot's ``[sim_robot]`` table: its config without the cycle, which the
    launcher gives it from the link's (runtime/cycle.py)."""
    table = to_table(robot)
    table.pop("cycle_period_ns", None)
    return table


def link_cycle_ms(link: str, cycle_ms: float | None) -> float:
    """The cycle period (ms) of ``link`` ("alter": 28; "rsi": ``cycle_ms``, 4 or 12, default
    12; "abb": ``cycle_ms``, 4 or a multiple, default 4; "ur": 2 or 8, default 2); ValueError, one line, for a cycle
    the link does not have."""
    from humanpt.robot_gateway.links.abb.config import EGM_BASE_CYCLE_MS
    from humanpt.robot_gateway.links.rsi.config import RSI_CYCLES_MS

    if link == "alter":
        if cycle_ms not in (None, 28.0):
            raise ValueError(f"--cycle-ms {cycle_ms:g}: the ALTER link runs the Puma's 28 ms cycle (RSI: 4 or 12)")
        return 28.0
    if link == "ur":
        cycle_ms = 2.0 if cycle_ms is None else float(cycle_ms)
        if cycle_ms not in (2.0, 8.0):
            raise ValueError(f"--cycle-ms {cycle_ms:g}: UR RTDE runs at 2 ms (e-Series, 500 Hz) or 8 ms (CB3, 125 Hz)")
        return cycle_ms
    if link == "abb":
        cycle_ms = EGM_BASE_CYCLE_MS if cycle_ms is None else float(cycle_ms)
        n = cycle_ms / EGM_BASE_CYCLE_MS
        if not (n >= 1 and abs(n - round(n)) < 1e-9 and cycle_ms <= 1000):
            raise ValueError(f"--cycle-ms {cycle_ms:g}: ABB EGM runs at {EGM_BASE_CYCLE_MS:g} ms or a multiple "
                             "(EGMActPose \\SampleRate)")
        return cycle_ms
    if link != "rsi":
        raise ValueError(f"no link {link!r} (alter, rsi, abb, ur)")
    cycle_ms = 12.0 if cycle_ms is None else float(cycle_ms)
    if cycle_ms not in RSI_CYCLES_MS:
        raise ValueError(f"--cycle-ms {cycle_ms:g}: RSI runs at {' or '.join(f'{c:g}' for c in RSI_CYCLES_MS)} ms")
    return cycle_ms


def link_sections(sections: dict[str, dict], link: str, cycle_ms: float | None) -> None:
    """Put the robot link in the run's ``sections`` (in place), from this one place: ALTER
    (as written, 28 ms), RSI (``cycle_ms`` 4 or 12, default 12) or ABB EGM (``cycle_ms`` 4 or a
    multiple, default 4) over UDP on loopback, or UR RTDE (``cycle_ms`` 2 or 8, default 2)
    over TCP on loopback (the simulated UR's server at a free port).
    The cycle period goes to the gateway's section only: the cell's one cycle, which the
    launcher gives the simulated controller and the robot states carry to the controller,
    the pose filter and viz (runtime/cycle.py); the gateway's safety fields (speeds, envelope,
    stale commands, world_T_base) carry over from the ALTER gateway's (over UR not the stale
    commands: its bound is ``stale_ms``, a time), the rest are the link's defaults
    (humanpt.robot_gateway.links.rsi.config, .abb.config, .ur.config)."""
    cycle_ms = link_cycle_ms(link, cycle_ms)
    if link == "alter":
        return
    from humanpt.robot_gateway.config import GatewayConfig
    from humanpt.sim_robot.config import SimRobotConfig

    robot = cfgmod.build(SimRobotConfig, sections["sim_robot"], source="demo", section="sim_robot")
    gateway = cfgmod.build(GatewayConfig, sections["robot_gateway"], source="demo", section="robot_gateway")
    if link == "ur":  # the simulated UR's RTDE server on a free loopback port; the gateway connects
        rtde = f"127.0.0.1:{free_tcp_port()}"
        robot, gateway = ur_link(robot, gateway, cycle_ms, rtde)
        robot = dataclasses.replace(robot, rtde_bind=rtde, dashboard_bind=f"127.0.0.1:{free_tcp_port()}")
    else:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            udp = f"127.0.0.1:{s.getsockname()[1]}"  # (free now; the gateway binds it at its start)
        make = abb_link if link == "abb" else rsi_link
        robot, gateway = make(robot, gateway, cycle_ms, udp)
    sections["sim_robot"], sections["robot_gateway"] = robot_table(robot), to_table(gateway)


def live_sections(cfg: SystemConfig, run_dir: Path, port: int,
                  overrides: dict[str, dict] | None = None,
                  secure: bool = False, link: str = "alter",
                  cycle_ms: float | None = None) -> tuple[SystemConfig, dict[str, dict]]:
    """The live run's configs: (cfg as run live, {section: table} of its TOML file). The
    simulated robot (the Puma; the IRB 1600 over ``link`` abb, the UR5e over ur) is mounted so that it starts where the camera sees the target, behind a
    pty in ``run_dir``; the operator holds its start pose 3 s. Perception and pose_filter
    get only the ``overrides`` keys (so the defaults stay theirs).  What the pipeline
    believes is ``cfg.rig``, written by :func:`run_live` as ``rig.toml`` beside the config.
    ``secure``: mTLS with the PKI in ``run_dir/pki`` (:func:`make_pki`), client sessions,
    the run's tools presenting :data:`OPERATOR_IDENTITY`'s certificate."""
    over = overrides or {}
    op, ctl, cam = cfg.operator, cfg.controller, cfg.sim_camera
    start = start_flange_for(op, ctl.dz_mm, cam.flange_T_camera)
    # The link's arm (the Puma over ALTER and RSI, the IRB 1600 over ABB EGM), mounted by the
    # one rule (humanpt.twin.system.arm_cores).
    robot, gateway = arm_cores(start, model={"abb": "irb1600", "ur": "ur5e"}.get(link, "puma762"))
    pty = str(run_dir / "alter.pty")
    start_in_base = invert_transform(transform_from_x(np.asarray(robot.world_T_base_mm_deg))) @ start
    robot = cfg.robot_config("sim_robot", dataclasses.replace(
        robot, pty_link=pty, start_pose_mm_deg=tuple(float(v) for v in x_from_transform(start_in_base))))
    # A pty delivers a STATUS at once (no 38 400 baud line time): its pose is for "now".
    gateway = dataclasses.replace(gateway, port=pty, status_delay_ms=0.0)
    # The operator starts with the rest (its start-up must not fall into the running servo
    # loop: on two cores that delayed ALTER statuses by ~85 ms) and holds the start pose
    # while everything comes up and the servo settles.
    op = dataclasses.replace(op, start_delay_s=3.0)
    sections = {
        "runtime": {"cell": "demo", "connect": [f"tcp/127.0.0.1:{port}"], "listen": [f"tcp/127.0.0.1:{port}"],
                    "run_dir": str(run_dir), "connect_timeout_s": 30.0, "record_thread": True, "mode": "peer",
                    "rig": "rig.toml"},
        "operator": to_table(op), "sim_robot": robot_table(robot), "robot_gateway": to_table(gateway),
        "sim_camera": to_table(cam), "controller": to_table(ctl),
        # Foxglove's frames: the robot base where the gateway puts it.
        "scene": {"world_T_base_mm_deg": list(gateway.world_T_base_mm_deg), "dz_mm": ctl.dz_mm},
        "foxglove_bridge": {"port": free_tcp_port()},  # the operator's screen (loopback; the demo prints it)
    }
    if secure:
        # Peers would link to each other around the router's access control: clients only.
        sections["runtime"].update(mode="client", security="mtls", pki=PKI_DIR, identity=OPERATOR_IDENTITY)
    for name in ("perception", "pose_filter"):
        if over.get(name):
            sections[name] = dict(over[name])
    link_sections(sections, link, cycle_ms)
    return dataclasses.replace(cfg, operator=op), sections


ROUTER_START_TIMEOUT_S = 120.0  # bounds a hang: a router that never listens
# The components' start-up wait is adaptive: it ends when no further component has come up
# for START_STALL_S, or START_STALL_ROUTERS times what the router took to listen (a loaded
# machine starts every process that much slower), whichever is longer (issue 38 item 3).
START_STALL_S = 60.0
START_STALL_ROUTERS = 15.0


def _wait_alive(cfg: cfgmod.ConfigFile, names: tuple[str, ...], stall_s: float, procs) -> str:
    """Wait until every component of ``names`` is up (its liveliness token); "" then, else
    what failed: the processes that exited (name and status), or the components not up when
    none came up for ``stall_s`` (each one that comes up restarts that wait)."""
    t0 = last = time.monotonic()
    seen: set[str] = set()
    with open_tool_session(cfg.runtime, patient=True) as s:
        while True:
            dead = [f"{n} (exit {p.returncode})" for n, p in procs if p.poll() is not None]
            if dead:
                return f"{', '.join(dead)} exited before every component was up"
            alive = {str(r.ok.key_expr).rsplit("/", 1)[-1]
                     for r in s.liveliness().get(liveliness_key(cfg.runtime.cell, "*")) if r.ok is not None}
            now = time.monotonic()
            if set(names) <= alive:
                return ""
            if alive - seen:
                seen |= alive
                last = now
            if now - last > stall_s:
                return (f"{', '.join(sorted(set(names) - alive))} not up after {now - t0:.0f} s (running, but "
                        f"no component came up in the last {stall_s:.0f} s; up: {', '.join(sorted(alive)) or 'none'})")
            time.sleep(0.3)


def _note(log, line: str) -> None:
    """A line of the live twin's own in ``processes.log`` (beside its processes' output)."""
    log.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} live twin: {line}\n")
    log.flush()


def _lower_priority(pid: int) -> None:
    """A lower scheduling priority for a child (POSIX; a no-op elsewhere)."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, 10)
    except (AttributeError, OSError):
        pass


class LiveControl:
    """Handles on a running live twin for a bench or a test: a process stopped on purpose
    (:meth:`kill`) is not counted as a failure of the run, and :meth:`start` starts it
    again with the same command line (its recording then goes on in a new segment)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.procs: list[tuple[str, subprocess.Popen]] = []
        self.argv: dict[str, list[str]] = {}
        self.down: set[str] = set()  # stopped on purpose, not yet started again
        self._log = None

    def _spawn(self, name: str, argv: list[str]) -> subprocess.Popen:
        p = subprocess.Popen(argv, stdout=self._log, stderr=subprocess.STDOUT)
        with self.lock:
            self.argv[name] = argv
            self.procs[:] = [(n, q) for n, q in self.procs if n != name] + [(name, p)]
        return p

    def pid(self, name: str) -> int | None:
        with self.lock:
            return next((p.pid for n, p in self.procs if n == name and p.poll() is None), None)

    def kill(self, name: str, sig: int = signal.SIGKILL, timeout_s: float = 10.0) -> None:
        """Send ``sig`` to ``name``'s process and wait for it to end (KeyError: no such process)."""
        with self.lock:
            p = next(p for n, p in self.procs if n == name)
            self.down.add(name)
        if p.poll() is None:
            p.send_signal(sig)
        p.wait(timeout=timeout_s)

    def start(self, name: str) -> None:
        """Start ``name`` again after :meth:`kill`, with its command line."""
        self._spawn(name, self.argv[name])
        with self.lock:
            self.down.discard(name)

    def dead(self) -> list[tuple[str, int]]:
        """(name, exit status) of each process that ended, less those stopped on purpose."""
        with self.lock:
            return [(n, p.returncode) for n, p in self.procs if n not in self.down and p.poll() is not None]


@dataclass
class LiveResult:
    """A finished live run."""

    config: SystemConfig  # as run live (see live_sections)
    run_dir: Path
    duration_s: float  # scenario time run (from everything up to the stop, less the 1 s before recording)
    wall_s: float  # wall time with start-up and stop
    stop_ns: int  # wall clock (ns) when the processes were told to stop
    failed: list[str] = field(default_factory=list)  # what went wrong; empty: the run went through


def run_live(cfg: SystemConfig, run_dir: str | Path, *, port: int | None = None, viewer: bool = False,
             duration_s: float | None = None, overrides: dict[str, dict] | None = None,
             stop: threading.Event | None = None, on_started: Callable[[list[str]], None] | None = None,
             progress: Callable[[float, float], None] | None = None, secure: bool = False,
             control: LiveControl | None = None, link: str = "alter",
             cycle_ms: float | None = None, screen: bool = True, bridge: bool = True) -> LiveResult:
    """Run ``cfg`` live (:func:`live_sections`; ``port``: the router's, a free one by
    default; ``viewer``: viz too) for ``duration_s`` of scenario (default: start delay +
    scenario + 1.5 s) after everything is up, recording the path from a second after
    that. ``stop`` ends the run early; ``on_started(components)`` once the processes are
    spawned; ``progress(elapsed_s, total_s)`` about five times a second.  ``secure``: under
    mTLS with a throwaway PKI in ``run_dir/pki`` (:func:`make_pki`).  ``control``: filled
    with the processes, to stop and start one on purpose (:class:`LiveControl`).  ``link``,
    ``cycle_ms``: the robot link and its cycle (:func:`link_sections`).  ``screen=False``:
    without the operator's screen (scene, foxglove_bridge: nothing in the loop reads them);
    ``bridge=False``: without the Foxglove bridge alone (what it costs the loop: ``humanpt bench
    bridge``)."""
    run_dir = Path(run_dir)
    port = port or free_tcp_port()
    cfg, sections = live_sections(cfg, run_dir, port, overrides, secure=secure, link=link, cycle_ms=cycle_ms)
    comps = list(LIVE_COMPONENTS) + ["foxglove_bridge"] + (["viz"] if viewer else [])  # the operator's screen
    if not screen:
        comps = [c for c in comps if c not in SCREEN_COMPONENTS]
    if not bridge:
        comps = [c for c in comps if c != "foxglove_bridge"]
    if secure:
        make_pki(run_dir, sections["runtime"]["cell"], comps + ["operator"])
    cfg_path = run_dir / "humanpt.toml"
    write_toml(cfg_path, sections)
    write_rig(run_dir / "rig.toml", cfg.rig, "what the twin's pipeline believes in this run", overwrite=True)
    file_cfg = cfgmod.load(cfg_path)  # fail here, clearly, if the written config does not validate
    file_cfg.rig()
    ctl = control or LiveControl()
    procs = ctl.procs
    stop = stop or threading.Event()
    duration = duration_s or cfg.default_duration_s()
    failed: list[str] = []
    t0 = time.perf_counter()
    with open(run_dir / "processes.log", "w") as log:
        ctl._log = log
        try:
            router = ctl._spawn("router", launcher.argv(launcher.ROUTER, config=cfg_path))
            # The components start once the router listens: started beside it on a loaded
            # machine they starved its start-up past their 30 s connect timeout (issue 29
            # item 15: "cannot reach the router" at load 8-12).
            t_router = time.monotonic()
            why = wait_listening("127.0.0.1", port, ROUTER_START_TIMEOUT_S, alive=lambda: router.poll() is None,
                                 stop=stop)
            router_s = time.monotonic() - t_router
            if why:
                failed.append(f"the router did not listen: {why}; see {run_dir / 'processes.log'}")
                return LiveResult(cfg, run_dir, duration, time.perf_counter() - t0, time.time_ns(), failed)
            _note(log, f"the router listened after {router_s:.1f} s; starting the components")
            for name in comps + ["operator"]:
                p = ctl._spawn(name, launcher.argv(name, config=cfg_path, run_dir=run_dir))
                if name == "operator":
                    # The simulated operator (a stand-in for the human, not part of the
                    # system) runs at a lower priority.
                    _lower_priority(p.pid)
            if on_started is not None:
                on_started(comps)
            t_comps = time.monotonic()
            why = _wait_alive(file_cfg, tuple(comps) + ("operator",),
                              max(START_STALL_S, START_STALL_ROUTERS * router_s), procs)
            _note(log, why or f"all {len(comps) + 1} components up after {time.monotonic() - t_comps:.1f} s")
            if why:
                failed.append(f"the components did not all come up: {why}")
            else:
                _drive(file_cfg, duration, ctl, stop, failed, progress)
        finally:
            stop_ns = time.time_ns()
            with ctl.lock:
                ctl.down.update(n for n, _ in procs)  # from now on an exit is the stop's
                ending = list(procs)
            for _, p in reversed(ending):
                if p.poll() is None:
                    p.send_signal(signal.SIGTERM)
            for _, p in reversed(ending):
                try:
                    p.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    p.kill()
    return LiveResult(cfg, run_dir, duration, time.perf_counter() - t0, stop_ns, failed)


def _drive(file_cfg: cfgmod.ConfigFile, duration: float, ctl: LiveControl, stop: threading.Event, failed: list[str],
           progress: Callable[[float, float], None] | None) -> None:
    """Start the path recording a second after everything is up; watch the processes until
    ``duration`` + 1 s, a stop, or one of them exiting."""
    t_start = time.monotonic()
    with open_tool_session(file_cfg.runtime, patient=True) as s:
        pub = s.declare_publisher("humanpt/demo/console/command")
        recording = False
        while not stop.wait(0.2):
            el = time.monotonic() - t_start
            if progress is not None:
                progress(el, duration + 1.0)
            # Record from a second after everything is up: the operator, which came up
            # with the rest, holds the start pose for start_delay_s, so the path begins
            # with it still whatever the order the processes came up in.
            if not recording and el >= 1.0:
                pub.put(pb.Command(header=header(time.time_ns()), component="controller",
                                   verb="record_start").SerializeToString())
                recording = True
            if el >= duration + 1.0:
                break
            dead = ctl.dead()
            if dead:
                failed += [f"{n} exited with {rc}" for n, rc in dead]
                break
        pub.undeclare()
