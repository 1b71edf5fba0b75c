"""``humanpt rig init|check|show|diff``: the rig file (what the pipeline believes about
the hardware).  This module parses and prints; :mod:`humanpt.runtime.rigfile` does the work."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from humanpt.geometry.rig import Rig
from humanpt.runtime.rigfile import load_rig, rig_to_table, rig_to_toml, write_rig


def _flat(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in table.items():
        if isinstance(v, dict) and v and k != "sigma":
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def differences(a: Rig, b: Rig) -> list[str]:
    """``key: a -> b`` for every value that differs between two rigs (dotted keys)."""
    fa, fb = _flat(rig_to_table(a)), _flat(rig_to_table(b))
    return [f"{k}: {fa.get(k)!r} -> {fb.get(k)!r}" for k in sorted(set(fa) | set(fb)) if fa.get(k) != fb.get(k)]


def summary(rig: Rig) -> str:
    """A few lines a person reads: the values that matter and how each part was obtained."""
    p, he, t, tip = rig.psvs, rig.hand_eye, rig.target, rig.tip
    lines = [f"rig {rig.name!r} (version {rig.version})",
             f"  psvs      a_u {p.a_u:g}, a_v {p.a_v:g} px, centre ({p.u0:g}, {p.v0:g}) px, "
             f"baseline {p.baseline_mm:g} mm, m {p.m_mm:.4g}, l {p.l_mm:.4g} mm, dist {list(p.dist_coeffs)}",
             f"            views: right rot {list(p.rotvec_right_deg)} deg, left rot {list(p.rotvec_left_deg)} deg",
             f"  hand_eye  flange_T_camera X = {list(he.flange_T_camera_x)} (mm, deg)",
             f"  target    legs {t.leg_mm:g}, base {t.base_mm:g}, sources {t.source_diameter_mm:g} mm",
             f"  tip       tob_t_tip {list(tip.tob_t_tip_mm)} mm",
             f"  obtained: {rig.methods()}"]
    return "\n".join(lines)


def init(args) -> int:
    path = write_rig(args.file, Rig(), "the nominal design values: calibrate (humanpt calibrate) before trusting "
                     "any accuracy figure", overwrite=args.overwrite)
    print(f"humanpt rig: wrote the nominal rig to {path}; name it in [runtime] rig = \"{path}\"")
    return 0


def check(args) -> int:
    rig = load_rig(args.file)
    print(f"{args.file}: OK")
    print(summary(rig))
    return 0


def show(args) -> int:
    if args.file:
        sys.stdout.write(rig_to_toml(load_rig(args.file)))
        return 0
    from humanpt.cli.commands import load_cfg
    from humanpt.runtime.monitor import rigs_in_use

    cfg = load_cfg(args)
    rigs: dict[str, Rig] = rigs_in_use(cfg, args.timeout)
    if not rigs:
        print(f"humanpt rig show: no component answered in cell {cfg.runtime.cell} within {args.timeout:g} s "
              "(is anything running?)", file=sys.stderr)
        return 1
    names = sorted(rigs)
    ref = rigs[names[0]]
    print(summary(ref))
    print(f"  served by: {', '.join(names)}")
    diff = {n: differences(ref, rigs[n]) for n in names[1:]}
    diff = {n: d for n, d in diff.items() if d}
    for n, d in diff.items():
        print(f"  {n} runs with ANOTHER rig than {names[0]}: " + "; ".join(d[:6]) + (" ..." if len(d) > 6 else ""))
    if args.json:
        print(json.dumps({n: rig_to_table(r) for n, r in rigs.items()}, indent=2))
    return 1 if diff else 0


def diff(args) -> int:
    a, b = load_rig(args.a), load_rig(args.b)
    d = differences(a, b)
    for line in d:
        print(line)
    if not d:
        print(f"{args.a} and {args.b}: the same rig")
    return 1 if d else 0


def run(args) -> int:
    fn = {"init": init, "check": check, "show": show, "diff": diff}.get(args.rig_verb)
    if fn is None:
        raise SystemExit("humanpt rig: give an action: init, check, show or diff (humanpt rig --help)")
    if fn is init and Path(args.file).is_dir():
        raise ValueError(f"{args.file}: is a directory; give the rig file's name, e.g. {args.file}/rig.toml")
    return fn(args)
