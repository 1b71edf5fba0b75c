"""Running ALTER cores without Zenoh: a scripted controller and a thread shell.

For tests and ``humanpt bench alter``, not for deployment:

- :class:`ScriptedControllerCore` (``controller``): answers every ``robot_state`` with a
  deterministic ``controller/command`` for that cycle (sinusoidal steps that exceed the
  gateway's limits at their peaks, so clamping is exercised).
- :class:`ThreadShell`: one core, its adapters (serial port, pty) and its tick timer on a
  worker thread, like the live shell but with outputs handed to a callback instead of
  Zenoh; optionally recorded to MCAP exactly as the live shell records.
"""

from __future__ import annotations

import logging
import os
import queue
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from humanpt.runtime.core import Core, Output, Port
from humanpt.runtime.recording import IN, OUT, Recorder
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, vector3

log = logging.getLogger("humanpt.testing.harness")

COMMAND = "controller/command"


@dataclass(frozen=True)
class ScriptedControllerConfig:
    """A scripted command stream: per-cycle steps, a function of the cycle number only.

    step(k) = amplitude * (sin, cos, 0.5 sin) of 2 pi k / period for translation (mm) and
    (0.1 sin, 0.15 cos, sin) for rotation (deg, as a rotation vector; small tilts keep
    the wrist away from its singularity). With the defaults
    (3.5 mm, 2 deg per cycle at the peaks) the gateway's limits (2.8 mm, 1.68 deg) clamp.
    ``mute`` lists [first, last] robot cycles the controller does not answer.
    """

    amplitude_mm: float = 3.5
    amplitude_deg: float = 2.0
    period_cycles: float = 120.0
    frame: Literal["world", "tool"] = "world"
    mute: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        if self.period_cycles <= 0:
            raise ValueError("period_cycles must be > 0")


def scripted_step(cycle: int, cfg: ScriptedControllerConfig) -> tuple[np.ndarray, np.ndarray]:
    """(dp_mm (3,), rv_rad (3,)) the scripted step for ``cycle``."""
    a = 2.0 * np.pi * cycle / cfg.period_cycles
    dp = cfg.amplitude_mm * np.array([np.sin(a), np.cos(1.3 * a), 0.5 * np.sin(0.7 * a)])
    rv = np.radians(
        cfg.amplitude_deg * np.array([0.1 * np.sin(0.9 * a), 0.15 * np.cos(1.1 * a), np.sin(a)])
    )
    return dp, rv


def scripted_command(
    state: pb.RobotState, cfg: ScriptedControllerConfig, seq: int
) -> pb.FlangeCommand:
    dp_mm, rv_rad = scripted_step(state.cycle, cfg)
    return pb.FlangeCommand(
        header=header(state.header.stamp_ns, seq, cfg.frame),
        cycle=state.cycle,
        d_translation_m=vector3(dp_mm / 1000.0),
        d_rotation_rad=vector3(rv_rad),
        mode=pb.CONTROL_MODE_TRACK,
    )


class ScriptedControllerCore(Core):
    name = "controller"
    config_type = ScriptedControllerConfig
    ports = (Port("robot_gateway/robot_state", pb.RobotState, "_on_robot_state"),)

    def _on_robot_state(self, t_ns: int, msg: pb.RobotState) -> list[Output]:
        if any(lo <= msg.cycle <= hi for lo, hi in self.config.mute):
            return []
        cmd = scripted_command(msg, self.config, self._seq[COMMAND])
        self._seq[COMMAND] += 1
        return [(COMMAND, cmd)]


class ThreadShell:
    """A core on a worker thread with its adapters and tick timer; no network.

    ``put(topic, msg)`` feeds an input from any thread (``t_ns`` = wall time when the
    core takes it, as in the live shell); every output goes to ``on_output(topic, msg)``
    (called on the worker thread) unless an adapter takes it. ``lock`` guards the core:
    hold it to read the core's state from another thread.
    """

    def __init__(
        self,
        core: Core,
        adapters: list | None = None,
        *,
        on_output: Callable[[str, object], None] | None = None,
        run_dir: str | Path | None = None,
    ):
        self.core = core
        self.adapters = list(adapters or [])
        self._local_out = {t: a for a in self.adapters for t in a.topics_out}
        self.on_output = on_output
        self.lock = threading.Lock()
        self._q: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.errors = 0
        self._stopped = False
        self.recorder = None
        if run_dir is not None:
            self.recorder = Recorder(
                Path(run_dir) / f"{core.name}.mcap",
                core.recording_metadata("thread", start_time_ns=time.time_ns(), host=socket.gethostname(),
                                        pid=os.getpid()),
            )

    def put(self, topic: str, msg) -> None:
        self._q.put((topic, msg))

    def start(self) -> ThreadShell:
        for a in self.adapters:
            a.start(self.put)
        self._threads = [
            threading.Thread(target=self._work, name=f"{self.core.name}-core", daemon=True)
        ]
        if self.core.tick_period_ns():
            self._threads.append(
                threading.Thread(target=self._ticks, name=f"{self.core.name}-tick", daemon=True)
            )
        for t in self._threads:
            t.start()
        return self

    def _ticks(self) -> None:
        period_s = self.core.tick_period_ns() / 1e9
        next_t = time.monotonic()
        while not self._stop.is_set():
            next_t += period_s
            delay = next_t - time.monotonic()
            if delay < -period_s:  # fell behind by more than a period: skip, do not burst
                next_t = time.monotonic()
                delay = 0.0
            if self._stop.wait(max(delay, 0.0)):
                return
            self._q.put(("tick", None))

    def _work(self) -> None:
        while not self._stop.is_set():
            try:
                topic, msg = self._q.get(timeout=0.05)
            except queue.Empty:
                continue
            t_ns = time.time_ns()
            if topic == "tick":
                msg = pb.Tick(header=header(t_ns), period_ns=self.core.tick_period_ns() or 0)
            with self.lock:
                if self.recorder:
                    self.recorder.write(IN, t_ns, topic, msg)
                try:
                    outs = self.core.step(t_ns, topic, msg)
                except Exception:  # noqa: BLE001 - as in the live shell: log, count, go on
                    self.errors += 1
                    log.exception("%s: core raised on %s", self.core.name, topic)
                    continue
                if self.recorder:
                    for out_topic, out in outs:
                        self.recorder.write(OUT, t_ns, out_topic, out)
            for out_topic, out in outs:
                adapter = self._local_out.get(out_topic)
                if adapter is not None:
                    try:
                        adapter.write(out_topic, out)
                    except Exception:  # noqa: BLE001 - a failing port must not stop the core
                        log.exception("%s: adapter could not write", self.core.name)
                elif self.on_output is not None:
                    self.on_output(out_topic, out)

    def stop(self) -> None:
        """Stop the threads, close the adapters and the recording (idempotent)."""
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        for a in self.adapters:
            try:
                a.close()
            except Exception:  # noqa: BLE001
                log.exception("closing an adapter")
        if self.recorder:
            self.recorder.close()

    def __enter__(self) -> ThreadShell:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
