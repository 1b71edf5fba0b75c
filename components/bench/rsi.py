"""``humanpt bench rsi``: the gateway <-> a simulated RSI controller over UDP on loopback.

The simulated controller (humanpt.sim_robot.rsi: its own thread, a monotonic deadline per
4 or 12 ms cycle) sends a ``<Rob>`` per cycle to the gateway's UDP adapter (its own read
thread); the gateway core runs on this thread with its timer ticks, and a scripted
controller answers each robot state at once with the command for the next cycle
(command-ahead, as the controller component does), so the gateway can answer a ``<Rob>``
as soon as it arrives. A cycle is *on time* when the robot had the gateway's answer before
its next cycle boundary. Reported: cycles on time, the reply-latency histogram (robot
send -> valid answer, as the robot sees it), the gateway's per-cycle work (decode, safety
rules, encode: the ``udp_rx`` step plus the command step, wall time, microseconds) p50/p99.
No Zenoh: what the link and the gateway sustain on this machine.
"""

from __future__ import annotations

import math
import queue
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from humanpt.robot_gateway.core import ROBOT_STATE, GatewayCore
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.shell import UdpAdapter
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, vector3
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import RsiRobot, RsiRobotServer


def circle_step(speed_mm_s: float = 20.0, radius_mm: float = 30.0) -> Callable[[int, float], np.ndarray]:
    """A scripted per-cycle step (world mm) going round a circle in the world XY plane at
    ``speed_mm_s``: f(n, cycle_ms) for the n-th command."""

    def step(n: int, cycle_ms: float) -> np.ndarray:
        w = speed_mm_s / radius_mm  # rad/s
        a0, a1 = w * n * cycle_ms / 1000.0, w * (n + 1) * cycle_ms / 1000.0
        return radius_mm * np.array([math.cos(a1) - math.cos(a0), math.sin(a1) - math.sin(a0), 0.0])

    return step


class CommandAhead:
    """The scripted controller: each robot state k is answered with the command for k+1
    (stamped as the controller does: the state's stamp + one cycle)."""

    def __init__(self, cycle_ms: float, step: Callable[[int, float], np.ndarray] | None = None):
        self.cycle_ms = cycle_ms
        self.step = step or circle_step()
        self.seq = 0

    def answer(self, state: pb.RobotState) -> pb.FlangeCommand:
        dp_mm = self.step(self.seq, self.cycle_ms)
        cmd = pb.FlangeCommand(
            header=header(state.header.stamp_ns + round(self.cycle_ms * 1e6), self.seq, "world"),
            cycle=(state.cycle + 1) & 0xFFFFFFFF,
            d_translation_m=vector3(np.asarray(dp_mm) / 1000.0),
            d_rotation_rad=vector3(np.zeros(3)),
            mode=pb.CONTROL_MODE_TRACK,
        )
        self.seq += 1
        return cmd


@dataclass
class RsiRun:
    cycle_ms: float
    cycles: int = 0
    on_time: int = 0
    late: int = 0
    histogram: dict[str, int] = field(default_factory=dict)
    work_us: list[float] = field(default_factory=list)  # gateway per-cycle work
    gateway: dict[str, int] = field(default_factory=dict)
    robot_events: list = field(default_factory=list)
    gateway_events: list = field(default_factory=list)
    overruns: int = 0  # robot cycles that started > 1 ms after their deadline
    stopped: str | None = None
    moved_mm: np.ndarray | None = None  # (3,) where the flange went, base frame
    latency_ms: list[float] = field(default_factory=list)  # robot sends -> the answer arrives, answered cycles

    @property
    def on_time_pct(self) -> float:
        return 100.0 * self.on_time / self.cycles if self.cycles else float("nan")

    def work_pct(self, q: float) -> float:
        return float(np.percentile(self.work_us, q)) if self.work_us else float("nan")

    def latency_pct(self, q: float) -> float:
        return float(np.percentile(self.latency_ms, q)) if self.latency_ms else float("nan")


@dataclass
class _RobotSide:
    """What the simulated controller reports after a run (picklable: it may run in a child
    process)."""

    counters: dict
    histogram: dict
    events: list
    overruns: int
    stopped: str | None
    moved_mm: np.ndarray
    latency_ns: list[int] = field(default_factory=list)


def _run_robot(robot_cfg: SimRobotConfig, gateway: str, cycles: int,
               lose: Callable[[int], bool] | None = None, stop=None) -> _RobotSide:
    sim = RsiRobot(robot_cfg)
    start_mm = sim.base_T_flange_mm[:3, 3].copy()
    server = RsiRobotServer(sim, gateway=gateway, cycles=cycles, lose=lose).start()
    try:
        while server._thread.is_alive():
            server.join(0.1)
            if stop is not None and stop.is_set():
                break
    finally:
        server.stop()
        server.join(2.0)
    return _RobotSide(dict(sim.counters), sim.latency_histogram(), list(sim.events), server.overruns,
                      sim.stopped, sim.base_T_flange_mm[:3, 3] - start_mm, list(sim.latency_ns))


def _robot_process(conn, robot_cfg: SimRobotConfig, gateway: str, cycles: int) -> None:
    """Child process: the simulated controller alone (its own GIL, as a real one is a
    machine of its own); the result goes back through ``conn``."""
    from humanpt.runtime.tuning import tune_process

    tune_process()
    conn.send(_run_robot(robot_cfg, gateway, cycles))
    conn.close()


def serve_gateway(core: GatewayCore, adapter, inbox: queue.SimpleQueue, controller: CommandAhead, run: RsiRun,
                  *, running: Callable[[], bool], poll: Callable[[], None] = lambda: None) -> None:
    """The gateway on this thread, as a link bench runs it (``bench rsi``, ``bench ur``): what
    the link's adapter read (``inbox``: (topic, msg) put by its thread) and the gateway's timer
    ticks go through ``core``; its link's bytes go out through ``adapter``, each robot state is
    answered at once by the scripted ``controller``, its events are kept in ``run``, and the
    wall time of each step of what the adapter read (decode, safety rules, encode, the
    command) in ``run.work_us``. Until ``running()`` is False and the inbox is empty;
    ``poll()`` is called between ticks."""
    tx_topic = core.link.tx_topic
    tick_ns = core.config.tick_period_ns

    def handle(t_ns: int, topic: str, msg) -> None:
        for out_topic, out in core.step(t_ns, topic, msg):
            if out_topic == tx_topic:
                adapter.write(out_topic, out)
            elif out_topic == ROBOT_STATE:
                handle(time.time_ns(), "controller/command", controller.answer(out))
            elif out_topic.endswith("/events"):
                run.gateway_events.append(out)

    next_tick = time.time_ns()
    while running() or not inbox.empty():
        try:
            topic, msg = inbox.get(timeout=max(0.0, (next_tick - time.time_ns()) / 1e9))
        except queue.Empty:
            pass
        else:
            t0 = time.perf_counter_ns()
            handle(time.time_ns(), topic, msg)
            run.work_us.append((time.perf_counter_ns() - t0) / 1e3)
            continue
        now = time.time_ns()
        if now >= next_tick:
            handle(now, "tick", pb.Tick(header=header(now), period_ns=tick_ns))
            next_tick += tick_ns * max(1, (now - next_tick) // tick_ns + 1)
        poll()


def run_rsi(cycle_ms: float = 4.0, cycles: int = 500, *, robot: SimRobotConfig | None = None,
            gateway: RsiConfig | None = None,
            step: Callable[[int, float], np.ndarray] | None = None,
            lose: Callable[[int], bool] | None = None, robot_process: bool = False) -> RsiRun:
    """One round trip run of ``cycles`` robot cycles (blocks ~cycles x cycle_ms); ``step``
    the scripted controller's per-cycle step (default: a 20 mm/s circle), ``lose(n)`` True
    drops the robot's n-th <Rob> (a lost datagram; in-process only). ``robot_process``:
    the simulated controller in a child process (its own interpreter and GIL, as the real
    one is a machine of its own), else a thread of this process."""
    import multiprocessing
    import threading

    gw_cfg = gateway or RsiConfig(udp_bind="127.0.0.1:0", cycle_period_ms=cycle_ms)
    core = GatewayCore(gw_cfg)
    adapter = UdpAdapter(gw_cfg.udp_bind)
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    adapter.start(lambda topic, msg: inbox.put((topic, msg)))
    host, port = adapter.address
    address = f"{host}:{port}"
    robot_cfg = robot or SimRobotConfig(protocol="rsi", cycle_period_ns=gw_cfg.cycle_period_ns)  # the link's cycle
    controller = CommandAhead(cycle_ms, step)
    run = RsiRun(cycle_ms)
    result: list[_RobotSide] = []
    stop = threading.Event()
    if robot_process:
        if lose is not None:
            raise ValueError("lose works with the robot in this process only")
        parent, child = multiprocessing.get_context("spawn").Pipe(duplex=False)
        worker = multiprocessing.get_context("spawn").Process(
            target=_robot_process, args=(child, robot_cfg, address, cycles), daemon=True)
    else:
        worker = threading.Thread(
            target=lambda: result.append(_run_robot(robot_cfg, address, cycles, lose, stop)), daemon=True)

    def poll() -> None:
        if robot_process and parent.poll():
            result.append(parent.recv())

    try:
        worker.start()
        serve_gateway(core, adapter, inbox, controller, run, running=worker.is_alive,
                      poll=poll)
    finally:
        stop.set()
        worker.join(5.0)
        if robot_process:
            if not result and parent.poll(5.0):
                result.append(parent.recv())
            if worker.is_alive():
                worker.terminate()
        adapter.close()
    if not result:
        raise RuntimeError("the simulated RSI controller reported nothing (it failed; see its log)")
    side = result[0]
    run.cycles = side.counters["cycles"]
    run.on_time = side.counters["on_time"]
    run.late = side.counters["late"]
    run.histogram = side.histogram
    run.gateway = dict(core.counters)
    run.robot_events = side.events
    run.overruns = side.overruns
    run.stopped = side.stopped
    run.moved_mm = side.moved_mm
    run.latency_ms = [ns / 1e6 for ns in side.latency_ns]
    return run
