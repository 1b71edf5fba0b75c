"""Process-level tuning for humanpt's processes (called once at start by the CLI).

Two things measurably matter on a small machine:

* **glibc's allocator.** Every frame allocates a few MB of temporaries (a 640x480 image,
  its noise, float buffers).  By default glibc serves blocks above its (adaptive) mmap
  threshold with fresh ``mmap`` pages and gives freed heap tops back to the kernel, so each
  frame pays a page fault per 4 KB touched: ~1.4 ms per frame in the lock-step loop.  A
  fixed 32 MB mmap threshold and a 256 MB trim threshold keep those buffers in the heap.
* **the GIL switch interval.** A live shell has a Zenoh callback thread, a worker thread
  and (optionally) a recorder thread.  When one holds the GIL in Python code, another
  waits up to the switch interval (5 ms by default) before it may run: 0.5 ms bounds the
  hand-off that the image-to-command latency pays.

Neither changes results, only timing.  A core on a robot link's hard cycle (``Core.realtime``:
the gateway, the simulated robot, the controller, the pose filter) gets more
(:func:`tune_realtime`): SCHED_FIFO (else a nice value), a shorter switch interval, and the
objects made before the run frozen out of the garbage collector's sight.
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys

log = logging.getLogger("humanpt.tuning")

M_TRIM_THRESHOLD = -1  # glibc <malloc.h>
M_MMAP_THRESHOLD = -3

MMAP_THRESHOLD_BYTES = 32 << 20  # glibc's largest on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX)
TRIM_THRESHOLD_BYTES = 256 << 20
SWITCH_INTERVAL_S = 0.0005


def tune_allocator() -> bool:
    """Keep large per-frame buffers in the heap (glibc only); True when applied."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl, ...): nothing to tune
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    mmap_ok = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
    trim_ok = bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
    if not (mmap_ok and trim_ok):
        log.debug("mallopt refused: mmap threshold %s, trim threshold %s", mmap_ok, trim_ok)
    return mmap_ok and trim_ok


def tune_process() -> None:
    """Both tunings, for a humanpt process (CLI start)."""
    tune_allocator()
    sys.setswitchinterval(SWITCH_INTERVAL_S)


def tune_realtime(core, rt) -> str | None:
    """For a process that runs ``core`` alone (``humanpt <component>``): if the core is on a
    robot link's hard cycle (``Core.realtime``), freeze the objects made so far out of the
    garbage collector's sight (and log collections over SLOW_GC_S), shorten the GIL's switch
    interval to ``rt.realtime_switch_interval_ms``, and ask for SCHED_FIFO at
    ``rt.realtime_fifo_priority``, else nice ``rt.realtime_nice``. Call it before any thread
    starts (they inherit the class). Returns a line saying what was done (None: not a
    realtime core). Process-wide: not for a shell that shares its process (tests, lock-step)."""
    if not core.realtime:
        return None
    # Everything made so far (modules, classes, the core) lives as long as the process: out
    # of the collector's sight, a full collection scans only what the run makes. It took
    # 29-38 ms in each of these processes otherwise (the log said so): a missed 12 ms cycle.
    import gc

    gc.collect()
    gc.freeze()
    _log_slow_collections(core.name)
    sys.setswitchinterval(rt.realtime_switch_interval_ms / 1000.0)
    said = f"GIL switch interval {rt.realtime_switch_interval_ms:g} ms"
    if rt.realtime_fifo_priority > 0:
        # Before any thread starts (zenoh's, the adapters', the recorder's): they inherit it.
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt.realtime_fifo_priority))
            return said + f", SCHED_FIFO priority {rt.realtime_fifo_priority}"
        except (OSError, AttributeError) as e:  # no CAP_SYS_NICE, or not Linux
            said += f", no SCHED_FIFO ({getattr(e, 'strerror', None) or e})"
    if rt.realtime_nice < 0:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, rt.realtime_nice)
            said += f", nice {rt.realtime_nice}"
        except OSError as e:  # no CAP_SYS_NICE: the normal priority, and say so
            said += f", normal priority (nice {rt.realtime_nice} refused: {e.strerror})"
    return said


SLOW_GC_S = 0.005  # a garbage collection longer than this is logged in a realtime process


def _log_slow_collections(name: str) -> None:
    """Log each garbage collection that stops this process longer than SLOW_GC_S: on a 4 ms
    cycle a full collection of a big heap is a missed cycle, and the log says so."""
    import gc
    import time

    started = [0.0]

    def timed(phase: str, info: dict) -> None:
        if phase == "start":
            started[0] = time.perf_counter()
            return
        took = time.perf_counter() - started[0]
        if took > SLOW_GC_S:
            log.warning("%s: garbage collection of generation %d took %.1f ms (%d objects collected)",
                        name, info.get("generation", -1), took * 1e3, info.get("collected", 0))

    gc.callbacks.append(timed)
