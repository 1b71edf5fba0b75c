"""``humanpt report --out docs/results.md``: regenerate the results page
(:mod:`humanpt.bench.report_page` does the work; this parses and prints)."""

from __future__ import annotations

import sys
import time


def report(args) -> int:
    from humanpt.bench import report_page as rp

    if args.list:
        for s in rp.SECTIONS.values():
            print(f"{s.name:14s} {s.command}" + ("" if s.deterministic else "  (--benches; measured)")
                  + ("" if s.default or not s.deterministic else "  (--only; not by default: it takes long)"))
        return 0
    if not args.out:
        print("humanpt report: --out FILE is required (the page to rewrite, e.g. docs/results.md)", file=sys.stderr)
        return 2
    only = [n.strip() for n in args.only.split(",") if n.strip()] if args.only else None
    t0 = time.perf_counter()

    def say(text: str) -> None:
        print(f"  {time.perf_counter() - t0:6.0f} s  {text}", file=sys.stderr, flush=True)

    try:
        done = rp.write_page(args.out, only, args.benches, say)
    except rp.PageError as e:
        print(f"humanpt report: {args.out}: {e}", file=sys.stderr)
        return 2
    print(f"{args.out}: regenerated {', '.join(done)} in {time.perf_counter() - t0:.0f} s")
    return 0
