"""``humanpt bench alter``: gateway <-> sim_robot over a real pty, in real time.

A cycle k is *served on time* when the gateway answered STATUS k with the controller's
own command for k (fresh, not a reused or zero one) and the robot applied it at the end
of cycle k (not a cycle late). The controller is scripted and answers each robot state
at once: in ``threads`` mode directly (both cores on threads of this process, as
ThreadShells), in ``zenoh`` mode over a router to ``humanpt sim_robot`` and
``humanpt robot_gateway`` child processes (then only the gateway's view is available:
a cycle counts as on time when its robot state reports ``missed_cycles == 0``).

A pty has no baud rate: bytes cross at once, so these figures are what the software
sustains; the ``38400 line`` column says whether a real 38 400 baud line could carry
the cycle (``humanpt.robot_gateway.links.alter.budget``).
"""

from __future__ import annotations

import contextlib
import logging
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.alter.budget import cycle_budget
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.robot_gateway.links.alter.shell import PatientSerialAdapter
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import SimRobotCore
from humanpt.sim_robot.shell import PtyAdapter
from humanpt.testing.harness import ScriptedControllerConfig, ThreadShell, scripted_command


@dataclass
class AlterRun:
    """The result of one run at one cycle period."""

    period_ms: float
    duration_s: float
    cycles: int = 0
    on_time: int = 0
    latency_ms: list[float] = field(default_factory=list)  # STATUS received -> correction sent
    jitter_ms: list[float] = field(default_factory=list)  # |robot cycle interval - period|
    work_us: list[float] = field(default_factory=list)  # the gateway's serial_rx and command steps (threads mode)
    note: str = ""

    @property
    def histogram(self) -> dict[str, int]:
        """Replies per latency bucket (STATUS received -> correction sent, the gateway's
        side), as ``bench rsi``'s, and the missed cycles as ``late``."""
        from humanpt.sim_robot.rsi import latency_histogram

        return latency_histogram([ms * 1e6 for ms in self.latency_ms], self.missed)

    @property
    def missed(self) -> int:
        return self.cycles - self.on_time

    def pct(self, q: float, values: list[float]) -> float:
        return float(np.percentile(values, q)) if values else float("nan")


def gateway_config(period_ms: float, port: str) -> AlterConfig:
    """Gateway settings scaled to the cycle: tick and reply deadline shrink with it."""
    return AlterConfig(
        port=port,
        cycle_period_ms=period_ms,
        tick_ms=min(2.0, period_ms / 4.0),
        reply_deadline_ms=min(6.0, period_ms * 0.4),
    )


def run_threads(period_ms: float, duration_s: float, warmup_s: float = 0.5) -> AlterRun:
    """Both cores on threads of this process, a pty between them, the controller inline."""
    script = ScriptedControllerConfig(amplitude_mm=1.0, amplitude_deg=0.3)
    with tempfile.TemporaryDirectory() as d:
        link = Path(d) / "alter-pty"
        gw = GatewayCore(gateway_config(period_ms, str(link)))
        # The robot runs its link's cycle (runtime/cycle.py).
        sim = SimRobotCore(SimRobotConfig(cycle_period_ns=gw.config.cycle_period_ns, pty_link=str(link)))
        rx_ns: dict[int, int] = {}
        measuring = threading.Event()
        seq = [0]
        gw_shell: ThreadShell

        def on_gateway(topic, msg):
            if topic == "robot_gateway/robot_state":
                rx_ns[msg.cycle] = msg.header.stamp_ns
                seq[0] += 1
                gw_shell.put("controller/command", scripted_command(msg, script, seq[0]))

        truth_ns: list[int] = []

        def on_sim(topic, msg):
            if topic == "sim_robot/truth" and measuring.is_set():
                truth_ns.append(msg.header.stamp_ns)

        work_us: list[float] = []
        gateway_step = gw.step

        def timed_step(t_ns, topic, msg):  # the gateway's work per cycle, as bench rsi measures it
            t0 = time.perf_counter_ns()
            try:
                return gateway_step(t_ns, topic, msg)
            finally:
                if measuring.is_set() and topic in ("serial_rx", "controller/command"):
                    work_us.append((time.perf_counter_ns() - t0) / 1e3)

        gw.step = timed_step
        sim_shell = ThreadShell(sim, [PtyAdapter(link)], on_output=on_sim)
        gw_shell = ThreadShell(gw, [PatientSerialAdapter(str(link), 38_400)], on_output=on_gateway)
        sim_shell.start()
        gw_shell.start()
        try:
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                with gw_shell.lock:
                    if gw.counters["fresh"] > 0:
                        break
                time.sleep(0.01)
            time.sleep(warmup_s)
            with sim_shell.lock:
                first_cycle = sim.cycle + 1
            measuring.set()
            time.sleep(duration_s)
            with sim_shell.lock:
                last_cycle = sim.cycle - 2  # the last two may still be in flight
                applied = list(sim.applied)
                robot_fault = sim.fault
            with gw_shell.lock:
                sent = list(gw.sent)
                gateway_fault = gw.fault
        finally:
            gw_shell.stop()
            sim_shell.stop()
    res = AlterRun(period_ms, duration_s, work_us=work_us)
    res.note = "; ".join(
        f"{who} fault: {why}"
        for who, why in (("robot", robot_fault), ("gateway", gateway_fault))
        if why
    )
    window = range(first_cycle, last_cycle + 1)
    fresh = {s.cycle for s in sent if s.source == "fresh" and s.cycle in window}
    on_time = {c.echo_cycle for at, c in applied if at == c.echo_cycle}
    res.cycles = len(window)
    res.on_time = len(fresh & on_time)
    res.latency_ms = [
        (s.t_ns - rx_ns[s.cycle]) / 1e6 for s in sent if s.cycle in window and s.cycle in rx_ns
    ]
    period_ns = period_ms * 1e6
    res.jitter_ms = [
        abs(b - a - period_ns) / 1e6 for a, b in zip(truth_ns, truth_ns[1:], strict=False)
    ]
    return res


def run_zenoh(period_ms: float, duration_s: float, warmup_s: float = 1.0) -> AlterRun:
    """Router, ``humanpt sim_robot`` and ``humanpt robot_gateway`` as child processes; this
    process is the controller (liveliness token, commands) over Zenoh."""
    import socket

    import zenoh

    from humanpt.runtime import launcher
    from humanpt.runtime.bus import liveliness_key, zenoh_config
    from humanpt.runtime.config import RuntimeConfig
    from humanpt.schemas import humanpt_pb2 as pb

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    script = ScriptedControllerConfig(amplitude_mm=1.0, amplitude_deg=0.3)
    res = AlterRun(period_ms, duration_s)
    with tempfile.TemporaryDirectory() as d:
        link = Path(d) / "alter-pty"
        g = gateway_config(period_ms, str(link))
        cfg = Path(d) / "bench.toml"
        cfg.write_text(
            f'[runtime]\ncell = "bench"\nconnect = ["tcp/127.0.0.1:{port}"]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
            f'run_dir = "{d}/runs"\nrecord = false\n'
            f'[sim_robot]\npty_link = "{link}"\n'
            f'[robot_gateway]\nport = "{link}"\ncycle_period_ms = {period_ms}\ntick_ms = {g.tick_ms}\n'
            f"reply_deadline_ms = {g.reply_deadline_ms}\n"
        )
        children = []
        try:
            quiet = dict(config=cfg, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            router = launcher.spawn(launcher.ROUTER, **quiet)
            children.append(router)
            launcher.wait_listening("127.0.0.1", port, 60.0, alive=lambda: router.poll() is None)  # then the rest
            children += [launcher.spawn(name, **quiet) for name in ("sim_robot", "robot_gateway")]
            rt = RuntimeConfig(cell="bench", connect=(f"tcp/127.0.0.1:{port}",))
            states: list[tuple[int, int]] = []  # (cycle, missed_cycles)
            measuring = threading.Event()
            with zenoh.open(zenoh_config(rt)) as s:
                token = s.liveliness().declare_token(liveliness_key("bench", "controller"))
                pub = s.declare_publisher("humanpt/bench/controller/command")
                seq = [0]

                def on_state(sample):
                    st = pb.RobotState.FromString(sample.payload.to_bytes())
                    seq[0] += 1
                    pub.put(scripted_command(st, script, seq[0]).SerializeToString())
                    if measuring.is_set():
                        states.append((st.cycle, st.missed_cycles))

                faults: list[str] = []

                def on_event(sample):
                    e = pb.Event.FromString(sample.payload.to_bytes())
                    if e.code == "fault" and measuring.is_set():
                        faults.append(f"{e.source} fault: {e.text}")

                sub = s.declare_subscriber("humanpt/bench/robot_gateway/robot_state", on_state)
                ev_sub = s.declare_subscriber("humanpt/bench/*/events", on_event)
                deadline = time.monotonic() + 15.0
                while seq[0] < 5 and time.monotonic() < deadline:
                    time.sleep(0.05)
                time.sleep(warmup_s)
                measuring.set()
                time.sleep(duration_s)
                measuring.clear()
                sub.undeclare()
                ev_sub.undeclare()
                token.undeclare()
                res.note = "; ".join(faults[:2])
            if states:
                # State k's missed_cycles covers cycle k - 1: zero means k - 1 was on time.
                # Cycles whose state never arrived count as missed.
                res.cycles = states[-1][0] - states[0][0]
                res.on_time = sum(1 for _, m in states[1:] if m == 0)
            else:
                res.note = "no robot state arrived"
        finally:
            for p in reversed(children):
                with contextlib.suppress(Exception):
                    p.terminate()
                    p.wait(10)
    return res


def line_capacity(period_ms: float) -> str:
    """Whether a real 38 400 baud line carries a cycle of ``period_ms``: ``same cycle``
    (the reply fits in the same cycle), ``next cycle`` or ``no`` (:mod:`humanpt.robot_gateway.links.alter.budget`)."""
    b = cycle_budget(38_400, round(period_ms * 1e6))
    return "same cycle" if b.same_cycle_reply else ("next cycle" if b.fits else "no")


def shortest_sustained(runs: list[AlterRun]) -> float | None:
    """The shortest period (ms) such that it and every longer one tried ran without a miss
    (``runs[0]``, the long run at 28 ms, is not one of those tried)."""
    best = None
    for r in sorted(runs[1:], key=lambda r: -r.period_ms):
        if r.cycles == 0 or r.missed:
            break
        best = r.period_ms
    return best


def measure_alter(
    duration_s: float = 60.0,
    periods_ms: tuple[float, ...] = (28.0, 16.0, 8.0, 4.0, 2.0),
    search_s: float = 3.0,
    mode: str = "threads",
    progress: Callable[[AlterRun], None] | None = None,
) -> list[AlterRun]:
    """Run at 28 ms for ``duration_s``, then ``search_s`` at each of ``periods_ms``
    (``mode``: ``threads`` or ``zenoh``); ``progress(run)`` after each."""
    run = run_zenoh if mode == "zenoh" else run_threads
    logging.getLogger("humanpt.sim_robot").setLevel(logging.WARNING)  # one pty line per run is noise here
    rows = []
    for period_ms, seconds in ((28.0, duration_s), *((p, search_s) for p in periods_ms)):
        rows.append(run(period_ms, seconds))
        if progress is not None:
            progress(rows[-1])
    return rows
