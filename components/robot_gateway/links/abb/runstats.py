"""EGM cycles answered in time in a recorded run (``humanpt demo --link abb`` prints it).

EGM itself counts nothing for the sensor (a late ``EgmSensor`` is just an older target), so
this is the simulated controller's count (:class:`humanpt.sim_robot.egm.EgmRobot`'s
``on_time`` / ``late``), redone from ``sim_robot``'s recording by the same rule: a cycle is
answered in time when a well-formed ``EgmSensor`` arrived (the UDP adapter's stamp) within one
cycle of that cycle's ``EgmRobot``. The cycles before the gateway's first answer (the gateway
still starting) are counted apart; the last cycle of the recording is not judged."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from humanpt.robot_gateway.links.abb.protocol import EgmProtocolError, decode_sensor
from humanpt.runtime import cycle
from humanpt.runtime.recording import read, segments_of
from humanpt.schemas import humanpt_pb2 as pb


@dataclass(frozen=True)
class EgmCycles:
    cycle_ms: float
    cycles: int  # EgmRobot cycles judged, from the gateway's first answer on
    late: int  # of them without an EgmSensor within the cycle
    waiting: int = 0  # cycles before the gateway's first answer (not judged, not counted above)

    @property
    def on_time_pct(self) -> float:
        return 100.0 * (self.cycles - self.late) / self.cycles if self.cycles else 0.0

    def __str__(self) -> str:
        return (f"EGM at {self.cycle_ms:g} ms: {self.cycles} cycles, {self.cycles - self.late} answered in time "
                f"({self.on_time_pct:.2f} %), {self.late} late (an EgmSensor within the cycle of its EgmRobot, "
                f"as the simulated controller counts; from the gateway's first answer, {self.waiting} cycles "
                "before it)")


def egm_cycles(run_dir: str | Path) -> EgmCycles | None:
    """The run's EGM cycles (None: no EGM sim_robot recording in ``run_dir``, or no answer)."""
    cycles = late = waiting = 0
    cycle_ns = 0
    answered_ever = False
    sent_ns: int | None = None
    answered = False
    found = False
    for path in segments_of(Path(run_dir), "sim_robot"):
        rec = read(path)
        cfg = rec.config()
        if cfg.get("protocol") != "egm":
            return None
        found = True
        cycle_ns = int(cycle.recorded("sim_robot", cfg)[0]["cycle_period_ns"])
        for e in rec.entries:  # in file order: an input, then what the core made of it
            if e.topic == "udp_rx":
                msg = pb.SerialChunk.FromString(e.data)
                try:
                    decode_sensor(msg.data)
                except EgmProtocolError:
                    continue
                answered_ever = True
                arrived_ns = msg.header.stamp_ns or e.t_ns  # (as the core takes it)
                if sent_ns is not None and not answered and arrived_ns - sent_ns <= cycle_ns:
                    answered = True
            elif e.topic == "udp_tx":
                if sent_ns is not None:  # judge the previous cycle
                    if answered:
                        cycles += 1
                    elif not answered_ever:
                        waiting += 1
                    else:
                        cycles += 1
                        late += 1
                sent_ns = pb.SerialChunk.FromString(e.data).header.stamp_ns
                answered = False
    if not found or not answered_ever:
        return None
    return EgmCycles(cycle_ns / 1e6, cycles, late, waiting)
