"""RSI cycles answered in time in a recorded run (``humanpt demo --link rsi`` prints it).

The simulated RSI controller's own count: every ``<Rob>`` it sent carries ``<Delay D>``,
the late answers so far (none in time before its next cycle: late, lost, wrong IPOC), and
its IPOC (ms). The first and the last ``<Rob>`` in ``sim_robot``'s recording give the
cycles and the late answers between them, read from the datagrams themselves."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from humanpt.rsi.protocol import decode_rob
from humanpt.runtime.recording import read, segments_of
from humanpt.schemas import humanpt_pb2 as pb


@dataclass(frozen=True)
class RsiCycles:
    cycle_ms: int
    cycles: int  # <Rob> cycles from the first recorded to the last
    late: int  # of them answered late or not at all (the robot's <Delay> grew)

    @property
    def on_time_pct(self) -> float:
        return 100.0 * (self.cycles - self.late) / self.cycles if self.cycles else 0.0

    def __str__(self) -> str:
        return (f"RSI at {self.cycle_ms} ms: {self.cycles} cycles, {self.cycles - self.late} answered in time "
                f"({self.on_time_pct:.2f} %), {self.late} late (the simulated robot's <Delay>)")


def rsi_cycles(run_dir: str | Path) -> RsiCycles | None:
    """The run's RSI cycles (None: no RSI sim_robot recording in ``run_dir``)."""
    first = last = None
    cycle_ms = 0
    for path in segments_of(Path(run_dir), "sim_robot"):
        rec = read(path)
        cfg = rec.config()
        if cfg.get("protocol") != "rsi":
            return None
        cycle_ms = int(cfg["cycle_period_ms"])
        for e in rec.outputs:
            if e.topic == "udp_tx":
                rob = decode_rob(pb.SerialChunk.FromString(e.data).data)
                first = first or rob
                last = rob
    if first is None or last is None:
        return None
    # The last <Rob>'s Delay counts the answers judged before it: those to first..last-1.
    return RsiCycles(cycle_ms, (last.ipoc - first.ipoc) // cycle_ms, last.delay - first.delay)
