"""`humanpt experiment ... --link rsi`: the paper's experiments with the simulated Puma over
the RSI link, the controller and the filter on its cycle."""

from __future__ import annotations

import pytest

from humanpt.runtime.recording import read

pytestmark = pytest.mark.twin  # runs the lock-step twin for seconds


def test_the_static_experiment_runs_over_rsi_at_12_ms(tmp_path, cli_main, capsys):
    out = tmp_path / "exp"
    rc = cli_main(["experiment", "static", "--link", "rsi", "--cycle-ms", "12", "--vectors", "10",
                   "--method", "weighted", "--no-plots", "--record", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "the robot over RSI at 12 ms" in text and "10 vectors" in text
    gateway = read(out / "run-weighted" / "robot_gateway.mcap")
    assert '"link": "rsi"' in gateway.metadata["config"] and '"cycle_period_ms": 12.0' in gateway.metadata["config"]
    # The controller ran the 12 ms cycle: a path point every recording_delay_cycles (10)
    # cycles, 120 ms on average (each stamped with its image's time, 1/30 s apart; at
    # ALTER's 28 ms it would be 280 ms).
    controller = read(out / "run-weighted" / "controller.mcap")
    stamps = [e.decode().header.stamp_ns for e in controller.outputs if e.topic == "controller/path"]
    assert len(stamps) >= 10
    mean_gap_ms = (stamps[-1] - stamps[0]) / (len(stamps) - 1) / 1e6
    assert abs(mean_gap_ms - 120.0) < 34.0 / (len(stamps) - 1) + 1.0, mean_gap_ms


def test_a_link_the_experiment_cannot_run_is_refused_before_anything_is_made(tmp_path, cli_main, capsys):
    for argv, why in ((["--link", "alter", "--cycle-ms", "4"], "28 ms cycle"),
                      (["--link", "rsi", "--robot", "standin"], "simulated Puma")):
        out = tmp_path / "never"
        rc = cli_main(["experiment", "static", *argv, "--out", str(out)])
        err = capsys.readouterr().err
        assert rc == 2 and why in err, err
        assert not out.exists()
