"""``humanpt bench ur``: the gateway <-> the simulated UR controller over RTDE (TCP on loopback).

The simulated controller (:class:`humanpt.sim_robot.ur.RtdeServer`: a monotonic deadline per
2 ms (e-Series, 500 Hz) or 8 ms (CB3, 125 Hz) cycle, humanpt's URScript program running on a
UR5e; by default a process of its own, as a real controller is a machine of its own) sends a
data package every cycle to the gateway's RTDE client (the link's ``TcpClientAdapter``, its
own thread); the gateway core runs on this thread in the loop ``bench rsi`` runs
(:func:`humanpt.bench.rsi.serve_gateway`), and a scripted command-ahead controller answers
each robot state at once. A cycle is *answered in time* when the gateway's answer to its data
package (an input package with the next sequence and target) was read by the robot before its
next data package went out: before the program's next cycle read the registers, as the
program sees it (:class:`~humanpt.sim_robot.ur.RtdeServer`). The run lasts ``seconds`` from the
gateway's first answer; every data package of the gateway's session is counted (the last,
whose cycle had not ended, excepted).
Reported: cycles, answered in time, late (answered later, or never), the answer time
(package sent -> answer read by the robot) p50/p99 and its histogram, the gateway's
per-cycle work, the program's watchdog stops. No Zenoh: what the link and the gateway
sustain on this machine.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass

import numpy as np

from humanpt.bench.rsi import CommandAhead, RsiRun, serve_gateway
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.ur.config import CB3_CYCLE_MS, E_SERIES_CYCLE_MS
from humanpt.robot_gateway.links.ur.shell import TcpClientAdapter
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import latency_histogram
from humanpt.sim_robot.ur import RtdeServer, UrRobot

CYCLES_MS = (CB3_CYCLE_MS, E_SERIES_CYCLE_MS)  # what a UR controller runs RTDE at
START_TIMEOUT_S = 60.0  # the gateway's first answer (a loaded machine starts slowly): bounds a hang


class UrRun(RsiRun):
    """One run's figures, in the shape of ``bench rsi``'s (:class:`RsiRun`); ``stopped`` says
    how often the program's watchdog stopped the arm."""


@dataclass
class _RobotSide:
    """What the simulated controller reports after a run (picklable: it may run in a child process)."""

    packages: int
    in_time: int
    latency_ns: list[int]
    overruns: int
    watchdog_stops: int
    events: list
    moved_mm: np.ndarray
    answered_at_all: bool


def _run_robot(cycle_ms: float, seconds: float, tell_address, stop: threading.Event) -> _RobotSide:
    robot = UrRobot(SimRobotConfig(model="ur5e"), cycle_ms=cycle_ms)
    start_mm = robot.base_T_flange_mm[:3, 3].copy()
    server = RtdeServer(robot, "127.0.0.1:0").start()
    try:
        tell_address("{}:{}".format(*server.address))
        deadline = time.monotonic() + START_TIMEOUT_S
        while not server.answering.wait(0.1) and not stop.is_set() and time.monotonic() < deadline:
            pass  # (the gateway's first answer; a stop from the bench ends the wait)
        answered = server.answering.is_set()
        if answered:
            stop.wait(seconds)
        with server.lock:
            side = _RobotSide(server.answers["packages"], server.answers["answered"],
                              list(server.latency_ns), server.overruns, robot.counters["watchdog_stops"],
                              list(robot.events), robot.base_T_flange_mm[:3, 3] - start_mm, answered)
    finally:
        server.close()
    return side


def _robot_process(conn, cycle_ms: float, seconds: float) -> None:
    """Child process: the simulated controller alone (its own GIL); its address, then its
    result, go back through ``conn``."""
    from humanpt.runtime.tuning import tune_process

    tune_process()
    conn.send(_run_robot(cycle_ms, seconds, conn.send, threading.Event()))
    conn.close()


def run_ur(cycle_ms: float = E_SERIES_CYCLE_MS, seconds: float = 60.0, *, robot_process: bool = True) -> UrRun:
    """One run at ``cycle_ms`` (2 or 8) for ``seconds`` from the gateway's first answer.
    ``robot_process``: the simulated controller in a child process (default), else a thread
    of this process (sharing its GIL)."""
    import multiprocessing

    if cycle_ms not in CYCLES_MS:
        raise ValueError(f"a UR controller runs RTDE at 2 ms (e-Series) or 8 ms (CB3), got {cycle_ms:g}")
    if not seconds > 0:
        raise ValueError(f"seconds must be > 0, got {seconds:g}")
    result: list[_RobotSide] = []
    addresses: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()
    if robot_process:
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe(duplex=False)
        worker = ctx.Process(target=_robot_process, args=(child, cycle_ms, seconds), daemon=True)
    else:
        worker = threading.Thread(
            target=lambda: result.append(_run_robot(cycle_ms, seconds, addresses.put, stop)), daemon=True)
    worker.start()
    adapter = None
    try:
        if robot_process:
            if not parent.poll(START_TIMEOUT_S):
                raise RuntimeError("the simulated UR controller did not start (see its log)")
            address = parent.recv()
        else:
            address = addresses.get(timeout=START_TIMEOUT_S)
        cfg = gateway_config("ur", rtde_address=address, cycle_period_ms=cycle_ms)
        core = GatewayCore(cfg)
        adapter = TcpClientAdapter(cfg.rtde_address)
        inbox: queue.SimpleQueue = queue.SimpleQueue()
        adapter.start(lambda topic, msg: inbox.put((topic, msg)))
        run = UrRun(cycle_ms)

        def poll() -> None:
            if robot_process and not result and parent.poll():
                result.append(parent.recv())

        serve_gateway(core, adapter, inbox, CommandAhead(cycle_ms), run,
                      running=lambda: worker.is_alive() and not result, poll=poll)
    finally:
        stop.set()
        if adapter is not None:
            adapter.close()
        worker.join(10.0)
        if robot_process:
            if not result and parent.poll(5.0):
                result.append(parent.recv())
            if worker.is_alive():
                worker.terminate()
    if not result:
        raise RuntimeError("the simulated UR controller reported nothing (it failed; see its log)")
    side = result[0]
    if not side.answered_at_all:
        raise RuntimeError(f"the gateway never answered the simulated UR within {START_TIMEOUT_S:g} s")
    run.cycles = side.packages
    run.on_time = side.in_time
    run.late = side.packages - side.in_time
    run.latency_ms = [ns / 1e6 for ns in side.latency_ns]
    run.histogram = latency_histogram(side.latency_ns, run.late)
    run.gateway = dict(core.counters)
    run.robot_events = side.events
    run.overruns = side.overruns
    run.stopped = f"watchdog stopped the arm {side.watchdog_stops}x" if side.watchdog_stops else None
    run.moved_mm = side.moved_mm
    return run
