"""The main job: humanpt demo (lock-step and live) and humanpt experiment, end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from humanpt.bench.summary import CHAIN, latency_and_cycles, latency_chain
from humanpt.controller import pathfile
from humanpt.runtime.replay import replay
from tests.conftest import free_port, run_cli

pytestmark = [pytest.mark.cell, pytest.mark.timeout(600)]


def test_lockstep_demo_records_writes_the_path_and_reports_accuracy(tmp_path, cli):
    run = tmp_path / "run"
    code, out, err = cli("demo", "--lockstep", "--scenario", "arc", "--duration", "6", "--run-dir", str(run))
    assert code == 0, out + err
    assert "recorded path of G against ground truth" in out
    assert {p.stem for p in run.glob("*.mcap")} >= {"operator", "sim_robot", "robot_gateway", "sim_camera",
                                                      "perception", "pose_filter", "controller"}
    path = pathfile.read(run / "paths" / "path-1.csv")
    assert len(path) > 5
    # The servo kept the target: the path follows the paper's arc (radius 246 mm).
    radius = np.linalg.norm(path.x_g[:, :2] - [147.5, 1378.5], axis=1)
    assert np.all(np.abs(radius - 246.0) < 1.0)
    for comp in ("controller", "robot_gateway", "sim_robot"):
        res = replay(run / f"{comp}.mcap")
        # An output per 28 ms ALTER cycle of the 6 s run (recorded from 1 s after start-up).
        assert res.match and res.compared >= 150, res.report()


@pytest.mark.live
def test_live_demo_runs_every_component_as_a_process(tmp_path, cli):
    run = tmp_path / "live"
    port = free_port()
    # (5 s of the running loop, counted from everything up: 170 ALTER cycles of 28 ms)
    # (the demo's shell in this process: the components, and the router, are processes of their own)
    code, out, err = cli("demo", "--scenario", "static", "--duration", "5", "--run-dir", str(run), "--port", str(port))
    assert code == 0, out + err + (run / "processes.log").read_text()[-3000:]
    assert "humanpt demo (live)" in out and "recorded path of G against ground truth" in out
    assert (run / "humanpt.toml").is_file() and list((run / "paths").glob("path-*.csv"))
    # Where a user's tools find it (issue 20.4): the router's endpoint and the cell.
    assert f"router tcp/127.0.0.1:{port}, cell demo" in out and "humanpt topics --config" in out
    res = latency_and_cycles(run)
    assert res["cycles"] > 100 and len(res["latency_ms"]) > 50
    # Cycles answered on time are a bench figure (humanpt bench), not asserted here (issue 31:
    # a loaded machine answers fewer in time; that is no defect of the loop); printed for the log.
    print(f"live demo: {res['on_time']}/{res['cycles']} cycles answered on time")
    assert res["on_time"] > 0  # the loop closed at all
    assert np.all(res["latency_ms"] > 0)
    # Where the time goes (issue 37.3), hop by hop from four recordings: every hop of an image
    # is a forward step in time, and its first four add up to the image-to-command latency
    # measured directly from the controller's recording (same images, to the nanosecond).
    chain = latency_chain(run)
    hops = np.column_stack([chain[name] for name, _ in CHAIN])
    assert len(hops) > 50 and np.all(hops >= 0)
    direct = np.sort(res["latency_ms"])  # every image with a command; the chain's also reached the gateway
    sums = hops[:, :4].sum(axis=1)
    nearest = direct[np.clip(np.searchsorted(direct, sums), 0, len(direct) - 1)]
    below = direct[np.clip(np.searchsorted(direct, sums) - 1, 0, len(direct) - 1)]
    assert np.all(np.minimum(abs(nearest - sums), abs(below - sums)) < 1e-6)
    code, out, err = cli("replay", str(run))
    assert code == 0, out[-3000:] + err
    # Foxglove's own types beside ours in the live run too (issue 20 item 1; tests/scene: content).
    code, out, err = cli("runs", "merge", str(run), str(tmp_path / "merged.mcap"))
    assert code == 0, err
    with open(tmp_path / "merged.mcap", "rb") as fh:
        schemas = {c.topic: s.name for s, c, _ in make_reader(fh).iter_messages()}
    for topic, name in (("transforms", "FrameTransforms"), ("path", "PosesInFrame"), ("log", "Log"),
                        ("annotations", "ImageAnnotations"), ("calibration", "CameraCalibration"),
                        ("entities", "SceneUpdate")):
        assert schemas.get(f"humanpt/demo/scene/{topic}") == f"foxglove.{name}", topic


@pytest.mark.twin
def test_experiment_prints_the_papers_table_beside_the_twins(tmp_path, cli):
    out = tmp_path / "exp"
    # (10 vectors, 6 s of twin time: x/y/z SD against the truth 0.0001/0.0003/0.0013 mm for the
    # default perception, 0.065/0.038/0.216 for the paper's, seed 0, measured on 82f73a1)
    code, text, err = cli("experiment", "static", "--vectors", "10", "--out", str(out))
    assert code == 0, text + err
    assert "SD  paper, Table 1 (published)" in text
    assert "twin, default perception, vs ground truth" in text
    res = json.loads((out / "results.json").read_text())
    assert res["twin"]["weighted"]["n"] == [10]  # one seed
    # The default perception is far better than the paper's on the same images.
    assert np.mean(res["twin"]["weighted"]["truth_SD"][:3]) < np.mean(res["twin"]["paper"]["truth_SD"][:3])
    assert (out / "figure-static.png").stat().st_size > 10_000


def test_demo_rejects_a_bad_scenario_file(tmp_path, cli):
    bad = tmp_path / "bad.scn"
    bad.write_text("start 1 2 3 0 0 0\nline 1 2\n")
    code, out, err = cli("demo", "--lockstep", "--scenario", str(bad), "--run-dir", str(tmp_path / "r"))
    assert code == 2
    assert "bad.scn:2" in err


@pytest.mark.twin
def test_experiment_set_overrides_a_component(tmp_path, cli):
    def static_theta_sd(*extra):
        out = tmp_path / f"exp{len(extra)}"
        code, text, err = cli("experiment", "static", "--method", "weighted", "--vectors", "20", "--no-plots",
                              "--out", str(out), *extra)
        assert code == 0, text + err
        return json.loads((out / "results.json").read_text())["twin"]["weighted"]["paper_SD"][4]

    # The still-target averaging is what brings the static tilt noise below the paper's.
    # 20 vectors each (8.8 s of twin time), over seeds 0-2: theta SD 0.0016 deg (median)
    # against 0.0286 without, and the largest seed's 0.0020 against the smallest's 0.0257
    # (measured on 5efe7e1): every seed is 12x apart, so one seed (0) shows the 3x asked.
    assert static_theta_sd() * 3 < static_theta_sd("--set", "pose_filter.still_detect=false")


def test_experiment_rejects_unknown_sections_and_keys_before_running(tmp_path, cli):
    # (as a process: the message and the status the user sees, nothing run, nothing written)
    r = run_cli("experiment", "static", "--set", "nosuch.key=1", "--out", str(tmp_path / "x"), timeout=120)
    assert r.returncode == 2 and "no section nosuch" in r.stderr
    assert not (tmp_path / "x").exists()
    code, out, err = cli("experiment", "static", "--set", "pose_filter.still_q_scale=3", "--out", str(tmp_path / "y"))
    assert code != 0 and "still_q_scale" in err
    assert not (tmp_path / "y").exists()
