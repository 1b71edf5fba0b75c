"""Lock-step determinism and replay: run A == run B; replay of a run reproduces it; a
perturbed core is caught with the divergence named."""

from __future__ import annotations

import pytest

from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.recording import read
from humanpt.runtime.replay import build_core, replay
from humanpt.runtime.selftest import PingerConfig, PingerCore, PongerConfig, PongerCore
from humanpt.schemas import humanpt_pb2 as pb


def _run(run_dir=None, end_s=2.0, chunk_size=256 * 1024):
    with Lockstep([PingerCore(PingerConfig(period_ms=20)), PongerCore(PongerConfig())], run_dir=run_dir,
                  chunk_size=chunk_size) as ls:
        ls.set_param(500_000_000, "ponger", "prefix", '"PONG"')
        ls.set_param(700_000_000, "pinger", "period_ms", "10")
        ls.set_param(800_000_000, "pinger", "period_ms", "-3")  # rejected, as an event
        ls.run_until(int(end_s * 1e9))
    return ls


def test_same_run_twice_is_byte_identical():
    a, b = _run(), _run()
    assert a.digest() == b.digest()
    assert [o.data for o in a.outputs] == [o.data for o in b.outputs]
    assert len(a.outputs) > 150


def test_params_change_behaviour_and_bad_ones_are_rejected():
    ls = _run()
    pongs = [pb.Event.FromString(o.data).text for o in ls.outputs if o.topic == "ponger/pong"]
    assert pongs[0].startswith("pong ") and pongs[-1].startswith("PONG ")
    events = [pb.Event.FromString(o.data) for o in ls.outputs if o.topic.endswith("/events")]
    assert [e.code for e in events] == ["param_changed", "param_changed", "param_rejected"]
    assert "period_ms" in events[-1].text and "-3" in events[-1].text  # names the key and the refused value
    pings = [o.t_ns for o in ls.outputs if o.topic == "pinger/ping"]
    gaps = {b - a for a, b in zip(pings, pings[1:], strict=False)}
    assert gaps == {20_000_000, 10_000_000}


def test_lockstep_recordings_replay_exactly(tmp_path):
    _run(tmp_path)
    for comp in ("pinger", "ponger"):
        res = replay(tmp_path / f"{comp}.mcap")
        assert res.match, res.report()
        # A ping per 20 ms then 10 ms over 2 s (pinger), a pong per ping (ponger): > 100 each.
        assert res.compared == res.recorded_outputs == res.replayed_outputs > 100


class _Perturbed(PongerCore):
    def _on_ping(self, t_ns, msg):
        outs = super()._on_ping(t_ns, msg)
        if self.pings == 42:
            outs[0][1].header.stamp_ns += 7
        return outs


def test_a_perturbed_core_is_caught_with_the_field_named(tmp_path):
    _run(tmp_path)

    def factory(rec):
        core = build_core(rec)
        return _Perturbed(core.config)

    res = replay(tmp_path / "ponger.mcap", core_factory=factory)
    assert not res.match
    report = res.report()
    assert "MISMATCH" in report and "header.stamp_ns" in report and "(by +7)" in report
    div = res.divergence
    assert div.recorded[1] == "ponger/pong"
    # The divergence is at the 42nd pong (outputs before it include the param events).
    recorded = read(tmp_path / "ponger.mcap").outputs
    assert recorded[div.index].decode().text.endswith("(#42)")


def test_truncated_recording_replays_up_to_the_truncation(tmp_path):
    """Compared up to the damage, and said so, but never a match (issue 29)."""
    _run(tmp_path, end_s=20.0, chunk_size=2048)
    data = (tmp_path / "ponger.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    res = replay(cut)
    assert res.truncated and res.incomplete and not res.match and res.exit_code == 4, res.report()
    assert 0 < res.compared == res.recorded_outputs < len(read(tmp_path / "ponger.mcap").outputs)
    assert f"{res.compared} compared" in res.report() and "INCOMPLETE" in res.report()


def test_a_recording_cut_before_its_first_output_is_no_match(tmp_path):
    """Inputs survive but no recorded output does: nothing compared, not a match."""
    _run(tmp_path, end_s=2.0, chunk_size=2048)
    rec = read(tmp_path / "ponger.mcap")
    data = (tmp_path / "ponger.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    # Cut back until the file reads up to its first output but not that output.
    for end in range(len(data), 0, -64):
        cut.write_bytes(data[:end])
        got = read(cut)
        if got.entries and not got.outputs:
            break
    else:
        pytest.fail("no cut leaves inputs without outputs")
    assert got.inputs and rec.outputs
    res = replay(cut)
    assert not res.match and res.nothing_compared and res.compared == 0, res.report()
    assert "NOTHING COMPARED" in res.report()


def test_a_run_without_digest_says_so_and_runs_the_same():
    def run(digest):
        ls = Lockstep([PingerCore(PingerConfig(period_ms=20)), PongerCore(PongerConfig())], digest=digest)
        ls.run_until(1_000_000_000)
        return ls

    plain, hashed = run(False), run(True)
    assert [o.data for o in plain.outputs] == [o.data for o in hashed.outputs] and plain.outputs
    with pytest.raises(RuntimeError, match="digest=False"):
        plain.digest()


class _Costly(PongerCore):
    """A ponger that uses 2 ms of its thread's CPU on every input (a spin on thread_time)."""

    def step(self, t_ns, topic, msg):
        import time

        end = time.thread_time() + 0.002
        while time.thread_time() < end:
            pass
        return super().step(t_ns, topic, msg)


def test_the_loops_cpu_is_accounted_to_each_core_and_the_outputs_do_not_change(tmp_path):
    """Issue 37.4 (the lock-step loop's shares): with accounting on, the core that spends 2 ms
    of CPU per input is charged at least that per input it took (by construction), the rest
    of the loop's parts are named, and the outputs are the same bytes as without it."""
    def run(account, run_dir=None):
        ls = Lockstep([PingerCore(PingerConfig(period_ms=20)), _Costly(PongerConfig())], run_dir=run_dir)
        acc = ls.account() if account else None
        ls.run_until(1_000_000_000)
        ls.close()
        return ls, acc

    plain, _ = run(False)
    counted, acc = run(True, tmp_path)
    assert counted.digest() == plain.digest()
    pings = sum(1 for o in counted.outputs if o.topic == "pinger/ping")
    assert pings >= 40  # 1 s at 20 ms
    assert acc["ponger"] >= 0.002 * pings
    assert acc["pinger"] < acc["ponger"]
    assert {"decode", "encode", "record", "schedule", "pinger", "ponger"} <= set(acc)
    assert acc["record"] > 0.0  # a run directory: every input and output written
    assert all(v >= 0.0 for k, v in acc.items() if k != "schedule")
