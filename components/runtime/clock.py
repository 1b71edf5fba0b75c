"""Where a live process takes its time from: one place (issue 31 item 5).

Two clocks, each for its own use:

* **monotonic** (``CLOCK_MONOTONIC``): every wait, period and watchdog of the shell and its
  adapters (the tick timer, the RSI adapter's silence watchdog, recording flushes). It never
  steps; NTP slews it as it slews the wall clock.
* **the shared time base** (``CLOCK_REALTIME``, synced by NTP/PTP across the cell's
  machines): every stamp, and the ``t_ns`` a core is given (DESIGN "Time").
  :meth:`Clock.now_ns` is the monotonic clock plus the offset (realtime - monotonic) last
  accepted: between two steps it reads as the wall clock (a slew moves both clocks alike, so
  the offset holds), and it moves by a step only when the live shell accepts one
  (:meth:`Clock.check`, on its worker thread, before an input).

When the wall clock steps (NTP ``makestep``, an operator's ``date -s``, a leap second), the
live shell accepts the step before its next input and gives a core that has a
``clock_step`` port an input saying by how much (``pb.Event`` code ``clock_step``, text the
step in ns): the core moves its watchdogs' times by it (the gateway's STATUS silence, reply
deadline, the link's timers), so a step is neither a silence nor a burst of expiries. The
input is recorded like any other, so a run replays exactly, steps and all. A local input
(serial bytes, a datagram) stamped before the step and taken after it is re-stamped in the
new base by the shell.

Test and operations hook: ``HUMANPT_CLOCK_OFFSET_FILE`` names a file holding a number of
seconds (``+2``, ``-2.5``; a missing or empty file is 0) added to ``CLOCK_REALTIME`` as this
process reads it, re-read every 0.1 s: a test steps one process's wall clock without
stepping the machine's (tests/runtime/test_clock_step.py), the way an NTP step would.
Nothing else reads it.
"""

from __future__ import annotations

import logging
import os
import threading
import time

log = logging.getLogger("humanpt.clock")

OFFSET_FILE_ENV = "HUMANPT_CLOCK_OFFSET_FILE"
# A change of (realtime - monotonic) larger than this is a step (a slew changes both alike,
# so the difference holds to the reading's jitter, microseconds).
STEP_THRESHOLD_NS = 2_000_000
# A reading of both clocks is used when the two monotonic readings around the realtime one
# are this close (a reading pre-empted in the middle is taken again).
_READ_WINDOW_NS = 200_000
_OFFSET_FILE_PERIOD_NS = 100_000_000  # how often the hook's file is read again


class Clock:
    """The time of one live process: :meth:`monotonic_ns` for waits and watchdogs,
    :meth:`now_ns` for stamps (the shared time base), :meth:`check` (the shell's worker
    only) to accept a step of the wall clock."""

    def __init__(self, offset_file: str | None = None):
        self._offset_file = offset_file
        self._injected_ns = 0  # the hook's offset, from offset_file
        self._file_read_at: int | None = None
        self._lock = threading.Lock()
        self.steps: list[int] = []  # the steps accepted so far, in order (ns)
        self.offset_ns = self._measure() or time.time_ns() - time.monotonic_ns()

    @staticmethod
    def monotonic_ns() -> int:
        return time.monotonic_ns()

    def now_ns(self) -> int:
        """Now in the shared time base, as last accepted (any thread)."""
        return time.monotonic_ns() + self.offset_ns

    @property
    def epoch(self) -> int:
        """How many steps were accepted: the base :meth:`now_ns` reads in."""
        return len(self.steps)

    def shift_since(self, epoch: int) -> int:
        """What the steps accepted since ``epoch`` add up to (ns): what moves a stamp taken
        then into the base of now."""
        return sum(self.steps[epoch:])

    def realtime_ns(self) -> int:
        """``CLOCK_REALTIME`` as this process sees it (plus the hook's offset)."""
        return time.time_ns() + self._injected()

    def check(self) -> int:
        """Accept a step of the wall clock since the last accepted one (appended to
        :attr:`steps`; :meth:`now_ns` reads in the new base from here on). Returns
        :attr:`epoch`: a shell gives its core the steps it has not given yet."""
        with self._lock:  # (two shells in one process: one of them accepts a step)
            offset = self._measure()
            if offset is not None and abs(offset - self.offset_ns) > STEP_THRESHOLD_NS:
                self.steps.append(offset - self.offset_ns)
                self.offset_ns = offset
            return self.epoch

    def _measure(self) -> int | None:
        """realtime - monotonic, or None when no reading was close enough to trust."""
        injected = self._injected()
        for _ in range(3):
            m1 = time.monotonic_ns()
            w = time.time_ns()
            m2 = time.monotonic_ns()
            if m2 - m1 <= _READ_WINDOW_NS:
                return w + injected - (m1 + m2) // 2
        return None

    def _injected(self) -> int:
        if self._offset_file is None:
            return 0
        now = time.monotonic_ns()
        if self._file_read_at is not None and now - self._file_read_at < _OFFSET_FILE_PERIOD_NS:
            return self._injected_ns
        self._file_read_at = now
        try:
            with open(self._offset_file) as f:
                text = f.read().strip()
            self._injected_ns = round(float(text) * 1e9) if text else 0
        except FileNotFoundError:
            self._injected_ns = 0
        except (OSError, ValueError) as e:
            log.warning("%s %s: %s; the wall clock is taken as it is", OFFSET_FILE_ENV, self._offset_file, e)
            self._injected_ns = 0
        return self._injected_ns


# The process's clock: the live shell and its adapters take their time from here.
CLOCK = Clock(os.environ.get(OFFSET_FILE_ENV) or None)
