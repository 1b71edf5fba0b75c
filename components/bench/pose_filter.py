"""The pose filter judged against the twin's ground truth (issue 18): how far its estimate
at each measurement's stamp is from where the operator really held the target, how many
measurements it gated out, whether it restarted, and the longest hole in the accepted
measurements. ``python -m humanpt.bench.pose_filter [scenario ...] [--speed 20 60]``
prints a table (lock-step twin, ideal world); the tests use :func:`filter_errors`.
"""

from __future__ import annotations

import argparse
import time
import tomllib
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.transforms import rotation_angle_rad, x_from_transform
from humanpt.geometry.units import to_mm
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose

__all__ = ["FilterErrors", "filter_errors", "run_scenario"]


@dataclass(frozen=True)
class FilterErrors:
    """Errors of the filter's pose at each accepted measurement's stamp (the estimate right
    after that measurement) against the truth at that stamp, from the start of the motion.

    ``err`` (N, 6): x, y, z mm, psi, theta, phi deg (the paper's X, wrapped); ``pos_mm``,
    ``rot_deg`` (N,): the position distance and the rotation angle; ``stamps_ns`` (N,);
    ``full`` (N,): a full pose was measured (else one or two sources: position only, the
    orientation predicted). The orientation statistics are of the full ones."""

    stamps_ns: np.ndarray
    full: np.ndarray
    err: np.ndarray
    pos_mm: np.ndarray
    rot_deg: np.ndarray
    resets: int
    outliers: int
    manoeuvres: int
    max_gap_ms: float  # longest interval between accepted measurements while moving

    def maxe(self) -> np.ndarray:
        """MaxE per coordinate of X (6,), mm and deg; the orientation's of full poses."""
        if not len(self.err):
            return np.full(6, np.nan)
        m = np.abs(self.err).max(axis=0)
        m[3:] = np.abs(self.err[self.full, 3:]).max(axis=0) if self.full.any() else np.nan
        return m

    def row(self) -> str:
        m = self.maxe()
        rot = self.rot_deg[self.full]
        return (f"pos max {self.pos_mm.max():6.3f} rms {np.sqrt(np.mean(self.pos_mm ** 2)):6.3f} mm | "
                f"rot max {rot.max():6.3f} rms {np.sqrt(np.mean(rot ** 2)):6.3f} deg | "
                f"MaxE xyz {m[0]:.3f} {m[1]:.3f} {m[2]:.3f} mm ypr {m[3]:.3f} {m[4]:.3f} {m[5]:.3f} deg | "
                f"resets {self.resets} outliers {self.outliers} manoeuvres {self.manoeuvres} "
                f"gap {self.max_gap_ms:.0f} ms; {np.count_nonzero(~self.full)} position-only")


def filter_errors(world, after_ns: int | None = None) -> FilterErrors:
    """:class:`FilterErrors` of a lock-step world (or a recorded run) after ``after_ns``
    (default: the operator's ``scenario_started``, the start of the motion)."""
    from humanpt.twin.evaluate import scenario_start_ns, truth_at, wrap_deg

    if after_ns is None:
        after_ns = scenario_start_ns(world)
    at: dict[int, np.ndarray] = {}
    full: dict[int, bool] = {}
    for o in world.outputs("pose_filter/tob_state"):
        st = pb.TobState.FromString(o.data)
        # The first state after a measurement carries the filter's pose at its stamp.
        if st.HasField("world_T_tob_at_measurement") and st.measurement_stamp_ns not in at \
                and st.measurement_stamp_ns >= after_ns:
            at[st.measurement_stamp_ns] = to_mm(from_pose(st.world_T_tob_at_measurement))
            full[st.measurement_stamp_ns] = st.status == pb.TOB_STATUS_FULL
    stamps = np.array(sorted(at), dtype=np.int64)
    est = [at[s] for s in stamps]
    truth = truth_at(world, stamps) if len(stamps) else np.zeros((0, 4, 4))
    err = np.array([x_from_transform(e) - x_from_transform(t) for e, t in zip(est, truth, strict=True)]).reshape(-1, 6)
    err[:, 3:] = wrap_deg(err[:, 3:])
    pos = np.array([np.linalg.norm(e[:3, 3] - t[:3, 3]) for e, t in zip(est, truth, strict=True)])
    rot = np.array([np.degrees(rotation_angle_rad(e[:3, :3] @ t[:3, :3].T)) for e, t in zip(est, truth, strict=True)])
    codes = [pb.Event.FromString(o.data).code for o in world.outputs("pose_filter/events")
             if o.t_ns >= after_ns]
    gap = float(np.diff(stamps).max()) * 1e-6 if len(stamps) > 1 else float("nan")
    return FilterErrors(stamps, np.array([full[s] for s in stamps], dtype=bool), err, pos, rot, codes.count("filter_reset"), codes.count("outlier"),
                        codes.count("manoeuvre"), gap)


def run_scenario(scenario, speed_mm_s: float = 0.0, *, seed: int = 0, pose_filter=None, perception=None,
                 robot: str = "puma", world: str = "ideal", tail_s: float = 0.5):
    """The closed loop on the lock-step twin through ``scenario`` (a built-in name, scenario
    text, or an OperatorConfig) at ``speed_mm_s`` (a built-in's; 0: its default), to its end
    plus ``tail_s``; ``robot``: ``puma`` (as ``humanpt demo --lockstep``) or ``standin``;
    ``world``: a :meth:`humanpt.twin.worlds.World.named` spec. Returns the (closed) world."""
    from humanpt.operator import OperatorConfig
    from humanpt.twin.run import SystemConfig, run, scenario_duration_s
    from humanpt.twin.worlds import World

    if isinstance(scenario, OperatorConfig):
        op = scenario
    elif "\n" in scenario:
        op = OperatorConfig(scenario_text=scenario, speed_mm_s=speed_mm_s)
    else:
        op = OperatorConfig(scenario=scenario, speed_mm_s=speed_mm_s)
    base = {k: v for k, v in (("pose_filter", pose_filter), ("perception", perception)) if v is not None}
    cfg = SystemConfig.for_scenario(op, seed, world=World.named(world), **base)
    return run(cfg, robot=robot, duration_s=op.start_delay_s + scenario_duration_s(op) + tail_s).world


def main(argv: list[str] | None = None) -> int:
    from humanpt.operator.scenario import BUILTIN_SCENARIOS

    ap = argparse.ArgumentParser(prog="python -m humanpt.bench.pose_filter", description=__doc__)
    ap.add_argument("scenarios", nargs="*", default=["trapezium", "arc"],
                    help=f"built-in names ({', '.join(BUILTIN_SCENARIOS)}) or scenario files")
    ap.add_argument("--speed", type=float, nargs="+", default=[20.0, 60.0], help="mm/s (built-ins)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--robot", choices=("puma", "standin"), default="puma")
    ap.add_argument("--world", default="ideal", help="ideal, realistic, ideal+SOURCE..., or a world file")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a pose_filter key")
    args = ap.parse_args(argv)
    from humanpt.pose_filter.config import PoseFilterConfig
    from humanpt.runtime.config import build

    table = {}
    for kv in args.set:
        table.update(tomllib.loads(kv))  # key = value, TOML-typed
    cfg = build(PoseFilterConfig, table, source="--set", section="pose_filter") if table else None
    for name in args.scenarios:
        for speed in args.speed:
            t0 = time.perf_counter()
            scen = name if name in BUILTIN_SCENARIOS else open(name).read()
            if scen is not name:
                scen = scen.replace("$SPEED", f"{speed:g}")
            # a file's speed is its $SPEED, substituted above (a built-in's is the operator's)
            w = run_scenario(scen, speed if scen is name else 0.0, seed=args.seed, pose_filter=cfg, robot=args.robot, world=args.world)
            fe = filter_errors(w)
            print(f"{name:10s} {speed:4.0f} mm/s: {fe.row()}  ({time.perf_counter() - t0:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
