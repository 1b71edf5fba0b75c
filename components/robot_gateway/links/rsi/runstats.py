"""RSI cycles answered in time in a recorded run (``humanpt demo --link rsi`` prints it).

The simulated RSI controller's own count: every ``<Rob>`` it sent carries ``<Delay D>``,
the late answers so far (none in time before its next cycle: late, lost, wrong IPOC), and
its IPOC (ms). The first ``<Rob>`` after the gateway's first answer and the last one in
``sim_robot``'s recording give the cycles and the late answers between them, read from the
datagrams themselves; the cycles before (the gateway still starting, not judged by the
robot either) are counted apart."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from humanpt.robot_gateway.links.rsi.protocol import decode_rob
from humanpt.runtime import cycle
from humanpt.runtime.recording import read, segments_of
from humanpt.schemas import humanpt_pb2 as pb


@dataclass(frozen=True)
class RsiCycles:
    cycle_ms: int
    cycles: int  # <Rob> cycles from the first recorded to the last
    late: int  # of them answered late or not at all (the robot's <Delay> grew)
    waiting: int = 0  # cycles before the gateway's first answer (not judged, not counted above)

    @property
    def on_time_pct(self) -> float:
        return 100.0 * (self.cycles - self.late) / self.cycles if self.cycles else 0.0

    def __str__(self) -> str:
        return (f"RSI at {self.cycle_ms} ms: {self.cycles} cycles, {self.cycles - self.late} answered in time "
                f"({self.on_time_pct:.2f} %), {self.late} late (the simulated robot's <Delay>; from the gateway's "
                f"first answer, {self.waiting} cycles before it)")


def rsi_cycles(run_dir: str | Path) -> RsiCycles | None:
    """The run's RSI cycles (None: no RSI sim_robot recording in ``run_dir``)."""
    very_first = first = last = None
    answered = False
    cycle_ms = 0
    for path in segments_of(Path(run_dir), "sim_robot"):
        rec = read(path)
        cfg = rec.config()
        if cfg.get("protocol") != "rsi":
            return None
        cycle_ms = int(cycle.recorded("sim_robot", cfg)[0]["cycle_period_ns"] // 1_000_000)  # (old runs: mapped)
        for e in rec.entries:  # in file order: an input, then what the core made of it
            if e.topic == "udp_rx":
                answered = True
            elif e.topic == "udp_tx":
                rob = decode_rob(pb.SerialChunk.FromString(e.data).data)
                very_first = very_first or rob
                if answered:
                    first = first or rob
                    last = rob
    if first is None or last is None:
        return None
    # The last <Rob>'s Delay counts the answers judged before it: those to first..last-1.
    return RsiCycles(cycle_ms, (last.ipoc - first.ipoc) // cycle_ms, last.delay - first.delay,
                     (first.ipoc - very_first.ipoc) // cycle_ms)
