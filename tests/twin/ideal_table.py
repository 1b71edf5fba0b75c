"""Issue 32's ideal-world table (docs/results.md, "Playing back arcs and corners"): the
played torch against the seam as designed on the trapezium, the arc, scurve and arcs80 at
20 and 60 mm/s, seed 0, nominal rig; one row per run, in the doc's columns, plus where the
coverage's largest gap lies and the CPU seconds of the run.

    PYTHONPATH=. python -m tests.twin.ideal_table
"""

from __future__ import annotations

import time

from humanpt.operator.config import OperatorConfig
from humanpt.twin import teach
from humanpt.twin.worlds import World
from tests.twin.test_teach import ARCS80


def main() -> None:
    for name in ("trapezium", "arc", "scurve", "arcs80"):
        for v in (20.0, 60.0):
            t0 = time.process_time()
            op = (OperatorConfig(scenario_text=ARCS80, speed_scale=v / 20.0) if name == "arcs80"
                  else OperatorConfig(scenario=name, speed_mm_s=v))
            res = teach.calibrate_then_teach(op, World.ideal(), 0, stages=(), playback_speed_mm_s=v)
            c, f, pf = res.compared["played"], res.compared["fitted"], res.compared["played_fitted"]
            print(f"| {name} | {v:g} | {c.rms_mm:.3f} / {c.max_mm:.3f} | {100 * c.covered:.1f} % "
                  f"({100 * pf.covered:.1f} %) | {f.rms_mm:.3f} / {f.max_mm:.3f} |  largest gap {c.largest_gap_mm:.1f} mm "
                  f"at {c.gap_from_mm:.1f}-{c.gap_to_mm:.1f} mm of {c.length_mm:.0f}; {len(res.fitted.doubts)} doubts; "
                  f"{time.process_time() - t0:.0f} s CPU", flush=True)


if __name__ == "__main__":
    main()
