"""A core's warm-up (issue 37: perception's compiled kernels): a live shell calls it before
the component says it is up; one that fails leaves the component up (the first input does
the work), with a warning; perception's own warm-up measures its synthetic target FULL and
leaves the core as it was (replays never warm up)."""

from __future__ import annotations

import logging
import threading

import numpy as np
import pytest

from humanpt.perception import Perception, PerceptionConfig
from humanpt.perception.core import PerceptionCore
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.live import LiveShell
from humanpt.runtime.selftest import PongerConfig, PongerCore


class _Warming(PongerCore):
    def __init__(self, config, fail: bool):
        super().__init__(config)
        self.fail = fail
        self.warmed = threading.Event()

    def warm_up(self) -> None:
        self.warmed.set()
        if self.fail:
            raise RuntimeError("no compiler here")


@pytest.mark.parametrize("fail", [False, True])
def test_the_live_shell_warms_the_core_up_before_it_is_ready(router, caplog, fail):
    port, _ = router
    core = _Warming(PongerConfig(), fail)
    shell = LiveShell(core, RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",), listen=(), record=False))
    worker = threading.Thread(target=shell.run, daemon=True)
    with caplog.at_level(logging.WARNING, logger="humanpt.live"):
        worker.start()
        try:
            assert shell.ready.wait(30)
            assert core.warmed.is_set()  # before ready (set by the same thread, in order)
        finally:
            shell.stop.set()
            worker.join(10)
    warned = [r.getMessage() for r in caplog.records if "warm-up failed" in r.getMessage()]
    assert (warned == ["ponger: warm-up failed (no compiler here); the first input will do its work"]) == fail, warned


@pytest.mark.parametrize("method", ["weighted", "paper"])
def test_perceptions_warm_up_measures_its_synthetic_target_full(method):
    """The three sources, each seen in both views, paired A, B, C, on the default rig."""
    r = Perception(PerceptionConfig(method=method)).warm_up()
    assert r.match.status == "full" and len(r.blobs) == 6 and len(r.match.pairs) == 3


def test_a_warmed_up_core_measures_as_a_fresh_one():
    """The warm-up leaves the core's state alone: the same images give the same bytes."""
    from humanpt.schemas.convert import image

    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 30, (480, 640), dtype=np.uint8) for _ in range(3)]
    msgs = [image(f, stamp_ns=(k + 1) * 33_000_000, frame_id="camera") for k, f in enumerate(frames)]

    def outputs(warm: bool) -> list[bytes]:
        core = PerceptionCore(PerceptionConfig())
        if warm:
            core.warm_up()
        return [o.SerializeToString() for k, m in enumerate(msgs) for _, o in core.step((k + 1) * 40_000_000,
                                                                                           "camera/image", m)]

    assert outputs(True) == outputs(False) and outputs(False)
