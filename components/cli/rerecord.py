"""``humanpt runs rerecord``: parses its arguments; the job is :func:`humanpt.twin.rerecord.rerecord`."""

from __future__ import annotations


def rerecord(args) -> int:
    from humanpt.twin.rerecord import rerecord as run

    return run(args.dir, only=args.only, dry_run=args.dry_run, out=args.out, fields=args.fields,
               timeout_s=args.timeout)
