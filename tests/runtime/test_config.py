"""Config: one TOML file, validated into frozen dataclasses, errors name key and file."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import pytest

from humanpt.runtime import config as cfg
from humanpt.runtime.registry import config_types
from humanpt.runtime.selftest import PingerConfig


@dataclass(frozen=True)
class Sample:
    gain: float = cfg.live(1.0)
    n: int = 3
    name: str = "x"
    flag: bool = False
    mode: Literal["a", "b"] = "a"
    limits: tuple[float, float] = (0.0, 1.0)
    eps: tuple[str, ...] = ()

    def __post_init__(self):
        if self.gain < 0:
            raise ValueError(f"gain must be >= 0, got {self.gain}")


def test_defaults_and_types():
    s = cfg.build(Sample, {"gain": 2, "limits": [1, 2], "eps": ["p", "q"], "mode": "b"}, source="f.toml",
                  section="s")
    assert s == Sample(gain=2.0, limits=(1.0, 2.0), eps=("p", "q"), mode="b")
    assert isinstance(s.gain, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.gain = 3.0  # type: ignore[misc]


@pytest.mark.parametrize("table,needle", [
    ({"gian": 1.0}, "f.toml: [s] unknown key 'gian'"),
    ({"n": 1.5}, "f.toml: [s] n: expected an integer, got 1.5"),
    ({"n": True}, "f.toml: [s] n: expected an integer"),
    ({"flag": "yes"}, "f.toml: [s] flag: expected true or false"),
    ({"mode": "c"}, "f.toml: [s] mode: 'c' is not one of 'a', 'b'"),
    ({"limits": [1.0]}, "f.toml: [s] limits: expected 2 values, got 1"),
    ({"eps": "p"}, "f.toml: [s] eps: expected a list"),
    ({"gain": -1.0}, "f.toml: [s]: gain must be >= 0, got -1.0"),
])
def test_errors_name_file_section_and_key(table, needle):
    with pytest.raises(cfg.ConfigError) as e:
        cfg.build(Sample, table, source="f.toml", section="s")
    assert needle in str(e.value)


def test_load_file_errors(tmp_path):
    with pytest.raises(cfg.ConfigError, match="no such config file"):
        cfg.load(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[runtime\ncell = 1")
    with pytest.raises(cfg.ConfigError, match=f"{bad}: not valid TOML"):
        cfg.load(bad)
    f = tmp_path / "h.toml"
    f.write_text('[runtime]\ncell = "a"\n[pinger]\nperiod_msec = 5\n')
    with pytest.raises(cfg.ConfigError, match=rf"{f}: \[pinger\] unknown key 'period_msec'"):
        cfg.load(f, config_types())
    f.write_text('[pingr]\nperiod_ms = 5\n')
    with pytest.raises(cfg.ConfigError, match=r"unknown section \[pingr\]"):
        cfg.load(f, config_types())
    f.write_text('[runtime]\ncell = "a/b"\n')
    with pytest.raises(cfg.ConfigError, match=r"\[runtime\]: cell 'a/b'"):
        cfg.load(f, config_types())
    f.write_text('[runtime]\ncell = "a"\n[pinger]\nperiod_ms = 0.5\n')
    with pytest.raises(cfg.ConfigError, match=r"\[pinger\] period_ms: 0.5 is outside its range \[1, 60000\] ms"):
        cfg.load(f, config_types())


def test_load_good_file(tmp_path):
    f = tmp_path / "h.toml"
    f.write_text('[runtime]\ncell = "weld1"\n[pinger]\nperiod_ms = 20\n[profiles]\nmine = ["pinger"]\n')
    c = cfg.load(f, config_types())
    assert c.runtime.cell == "weld1"
    assert c.component("pinger", PingerConfig).period_ms == 20.0
    assert c.component("ponger", config_types()["ponger"]).prefix == "pong"  # absent section = defaults
    assert c.profiles == {"mine": ("pinger",)}


def test_live_parameters():
    s = Sample()
    assert cfg.live_keys(s) == ["gain"]
    assert cfg.replace_live(s, "gain", "2.5").gain == 2.5
    with pytest.raises(cfg.ConfigError, match="'n' is not a live parameter"):
        cfg.replace_live(s, "n", "4")
    with pytest.raises(cfg.ConfigError, match="gain must be >= 0"):
        cfg.replace_live(s, "gain", "-1")
    with pytest.raises(cfg.ConfigError, match="not JSON"):
        cfg.replace_live(s, "gain", "fast")
    with pytest.raises(cfg.ConfigError, match="expected a number"):
        cfg.replace_live(s, "gain", '"fast"')
