"""Issue 38 item 5: the small defects a newcomer met, each as they met it (in-process CLI,
real files: the reference run recordings/arc)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from humanpt.cli.main import build_parser
from humanpt.runtime import config as cfgmod
from humanpt.runtime.monitor import publisher_of_key
from humanpt.runtime.recording import read_metadata
from humanpt.runtime.registry import core_class

RUN = Path(__file__).resolve().parents[2] / "recordings" / "arc"


def _merged_metadata(path: Path) -> dict[str, str]:
    with open(path, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}.get("humanpt.merged", {})


def test_runs_merge_into_an_existing_directory_writes_the_run_named_file_and_keeps_the_rig(tmp_path, capsys, cli_main):
    # was: IsADirectoryError with a traceback; and the merged file had no rig
    assert cli_main(["runs", "merge", str(RUN), str(tmp_path)]) == 0
    out = tmp_path / "arc.mcap"
    assert out.is_file() and f"-> {out}" in capsys.readouterr().out
    meta = _merged_metadata(out)
    recorded, _ = read_metadata(RUN / "controller.mcap")
    assert meta["rig"] == recorded["rig"] and meta["cell"] == recorded["cell"]
    assert meta["components"].split(",") == sorted(read_metadata(f)[0]["component"] for f in RUN.glob("*.mcap"))


def test_runs_merge_into_a_missing_directory_is_a_clear_error(tmp_path, capsys, cli_main):
    code = cli_main(["runs", "merge", str(RUN), str(tmp_path / "no" / "x.mcap")])
    err = capsys.readouterr().err
    assert code != 0 and "no such directory" in err and "Traceback" not in err
    assert not (tmp_path / "no").exists()


def test_runs_info_takes_one_recording_as_runs_play_does(capsys, cli_main):
    assert cli_main(["runs", "info", str(RUN / "controller.mcap")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("controller.mcap: component controller") and "1 recordings" in out


@pytest.mark.parametrize("argv", [["demo", "--lockstep", "--duration", "-5"], ["topics", "--duration", "0"],
                                  ["demo", "--duration", "nan"]])
def test_a_duration_that_is_not_positive_is_refused(argv, capsys, cli_main):
    # was: demo --lockstep --duration -5 exited 0 and reported "-5.2x real time"
    with pytest.raises(SystemExit) as e:
        cli_main(argv)
    assert e.value.code == 2 and "argument --duration" in capsys.readouterr().err


def test_a_missing_parameter_file_is_named_once(tmp_path):
    from humanpt.runtime.params import read_file

    with pytest.raises(cfgmod.ConfigError) as e:
        read_file(tmp_path / "missing.toml", "controller")
    assert str(e.value).endswith("missing.toml: no such parameter file")


def test_the_param_help_examples_name_live_parameters_in_range():
    # was: `param controller gain=0.5`, refused by the component
    epilog = build_parser("param")._subparsers._group_actions[0].choices["param"].epilog
    lines = [ln.split() for ln in epilog.splitlines() if ln.strip().startswith("humanpt param ")]
    sets = [ln for ln in lines if any("=" in w for w in ln)]
    assert sets
    for words in sets:
        component = words[2]
        cls = core_class(component).config_type
        obj = cls()
        for w in words[3:]:
            if "=" in w and not w.startswith("-"):
                key, value = w.split("=", 1)
                obj = cfgmod.replace_live(obj, key, json.dumps(json.loads(value)))  # refused: ConfigError


def test_topics_names_each_keys_publisher():
    # --help promises a publisher column: the table's publisher, else the key's component
    assert publisher_of_key("humanpt/demo/controller/command") == "controller"
    assert publisher_of_key("humanpt/demo/perception/events") == "perception"
    assert publisher_of_key("not/a/key") == "?"


@pytest.mark.parametrize("kind", ["folder without fps", "empty folder", "missing"])
def test_a_camera_source_that_cannot_play_stops_at_start(kind, tmp_path, capsys, cli_main):
    # was: retried "cannot open video file" forever; an image folder plays at camera.fps (issue 35)
    source = tmp_path / ("nothing.avi" if kind == "missing" else "images")
    fps = "fps = 25\n" if kind == "empty folder" else ""
    if kind != "missing":
        source.mkdir()
        shutil.copy(RUN / "rig.toml", source / "rig.toml")  # (not an image)
    if kind == "folder without fps":
        cv2.imwrite(str(source / "a.png"), np.zeros((8, 8), np.uint8))
    cfg = tmp_path / "humanpt.toml"
    cfg.write_text(f'[runtime]\nconnect = ["tcp/127.0.0.1:9"]\nlisten = []\n[camera]\nsource = "{source}"\n{fps}')
    assert cli_main(["camera", "-c", str(cfg)]) == 1
    err = capsys.readouterr().err
    why = {"folder without fps": "is an image folder: set camera.fps", "empty folder": "holds no image",
           "missing": "no such video file"}[kind]
    assert str(source) in err and why in err, err


def test_runs_merge_writes_a_foxglove_layout_on_the_runs_own_cell(tmp_path, cli_main):
    # issue 38 item 4: the layout hard-coded humanpt/cell0/..., the live demo publishes humanpt/demo/...
    from humanpt.schemas import topics

    assert cli_main(["runs", "merge", str(RUN), str(tmp_path / "arc.mcap")]) == 0
    layout = json.loads((tmp_path / "arc.layout.json").read_text())
    with open(tmp_path / "arc.mcap", "rb") as f:
        channels = {c.topic for c in make_reader(f).get_summary().channels.values()}
    keys = set(re.findall(r'humanpt/[A-Za-z0-9_-]+/[A-Za-z0-9_/]+', json.dumps(layout)))
    assert keys and all(topics.short_from_key(k)[0] == "demo" for k in keys)  # the run's cell, recorded
    image = layout["configById"]["Image!humanptimage"]["imageMode"]
    # what the panels draw is in the merged file (the image itself is the camera's: not a bus output here)
    assert set(image["annotations"]) <= channels and image["calibrationTopic"] in channels
    assert set(layout["configById"]["3D!humanpt3d"]["topics"]) & channels
