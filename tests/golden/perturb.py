"""Deliberately perturbed cores, for the golden tests only (never in the product).

:func:`perturbed_factory` returns a core factory (as ``replay`` takes) that builds the
recorded core's class, subclassed so that its outputs on one topic are changed from the
``after``-th message on: a field nudged by ``delta``, a message dropped, or an image's
pixel brightened.  :func:`fresh_copy` re-records a component offline with this build.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from humanpt.runtime.recording import IN, OUT, Recorder, read
from humanpt.runtime.replay import build_core, missing_inputs


def _nudge(msg, path: str, delta: float) -> None:
    *parents, last = path.split(".")
    for p in parents:
        msg = getattr(msg, p)
    setattr(msg, last, getattr(msg, last) + delta)


def perturbed_factory(
    topic: str,
    *,
    after: int,
    field: str | None = None,
    delta: float = 0.0,
    drop: bool = False,
    pixel: int | None = None,
    pixels: int = 1,
    dn: int = 1,
):
    """A core factory whose core perturbs message #``after`` (and later ones, unless
    ``drop``: then only that one is dropped) on ``topic``: ``field`` nudged by ``delta``,
    or ``pixels`` image bytes from index ``pixel`` on (every 7th) brightened by ``dn``."""

    def factory(rec):
        base = build_core(rec)

        class Perturbed(type(base)):
            seen = 0

            def step(self, t_ns, in_topic, msg):
                outs = []
                for t, m in super().step(t_ns, in_topic, msg):
                    if t == topic:
                        n = Perturbed.seen
                        Perturbed.seen += 1
                        if drop and n == after:
                            continue
                        if not drop and n >= after:
                            if field is not None:
                                _nudge(m, field, delta)
                            if pixel is not None:
                                data = bytearray(m.data)
                                for k in range(pixel, pixel + 7 * pixels, 7):
                                    data[k] = min(255, data[k] + dn)
                                m.data = bytes(data)
                    outs.append((t, m))
                return outs

        return Perturbed(base.config)

    return factory


def fresh_copy(src: Path, dst: Path) -> Path:
    """``src`` re-recorded offline with this build: the same metadata and inputs, the
    outputs of a fresh core fed them.

    Tests of the golden machinery perturb such a copy, so that they test the machinery and
    pass or fail independently of whether this build still matches the committed reference
    runs (that is test_golden_replay's verdict alone).
    """
    rec = read(src)
    missing_inputs(rec)  # images recorded as references get their pixels: the copy stands alone
    core = build_core(rec)
    dst.parent.mkdir(parents=True, exist_ok=True)
    with Recorder(dst, dict(rec.metadata)) as out:
        for e in rec.inputs:
            msg = e.decode()
            out.write(IN, e.t_ns, e.topic, msg, e.data)
            for topic, m in core.step(e.t_ns, e.topic, msg):
                out.write(OUT, e.t_ns, topic, m)
    return dst


def fresh_run(src_dir: Path, dst_dir: Path) -> Path:
    """A whole reference run directory with every component recording a :func:`fresh_copy`."""
    shutil.copytree(src_dir, dst_dir, ignore=shutil.ignore_patterns("*.mcap"))
    for f in sorted(src_dir.glob("*.mcap")):
        fresh_copy(f, dst_dir / f.name)
    return dst_dir
