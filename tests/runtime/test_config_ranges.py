"""Config holes found by the live attack (issue 14): every number has a physical range, and
the gateway's safety limits are hard limits that may only become stricter at run time.

Each hole is tried through the product's own entry points: `humanpt config --check` on a
real file, the config builder, a gateway core given a ``param`` input, and `humanpt param`
against a gateway process on a real router (the verbs in this process: ``run_cli_here``).
"""

from __future__ import annotations

import dataclasses
import json
import typing

import pytest

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links import LINKS
from humanpt.robot_gateway.links import config_type as gateway_config_type
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.runtime import config as cfg
from humanpt.runtime.registry import config_types
from humanpt.schemas import humanpt_pb2 as pb
from tests.conftest import run_cli_here, wait_alive, write_config


def _numeric(tp) -> bool:
    """Whether the annotation ``tp`` holds numbers (int, float, or tuples/optionals of them)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp in (int, float):
        return True
    if origin is typing.Annotated:
        return _numeric(args[0])
    if origin in (tuple, typing.Union) or str(origin) == "<class 'types.UnionType'>":
        return any(_numeric(a) for a in args if a is not Ellipsis and a is not type(None))
    return False


def _ranged(tp) -> bool:
    """Whether every number in ``tp`` carries a :class:`Range`."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Annotated:
        return any(isinstance(m, cfg.Range) for m in tp.__metadata__)
    if tp in (int, float):
        return False
    return all(_ranged(a) for a in args if a is not Ellipsis and a is not type(None) and _numeric(a))


def _config_classes():
    seen: dict[str, type] = {}

    def walk(name, cls):
        seen[name] = cls
        for f in dataclasses.fields(cls):
            tp = cfg.hints(cls)[f.name]
            if dataclasses.is_dataclass(tp):
                walk(f"{name}.{f.name}", tp)

    for name, cls in _sections().items():
        walk(name, cls)
    return seen


def _sections() -> dict[str, type]:
    """Every section's config class; the gateway's once per link (its section is its link's)."""
    sections = {**config_types(), "runtime": cfg.RuntimeConfig}
    del sections["robot_gateway"]
    return {**sections, **{f"robot_gateway link={link}": gateway_config_type(link) for link in LINKS}}


def test_every_numeric_parameter_has_a_physical_range():
    missing = [f"[{name}] {f.name}" for name, cls in _config_classes().items()
               for f in dataclasses.fields(cls)
               if _numeric(cfg.hints(cls)[f.name]) and not _ranged(cfg.hints(cls)[f.name])]
    assert not missing, f"numeric parameters without a Range: {', '.join(missing)}"


def test_every_default_is_inside_its_range():
    # The builder checks ranges; building every section from its own defaults must pass.
    for name, cls in _sections().items():
        table = cfg.to_table(cls())
        cfg.build(cls, table, source="<defaults>", section=name)


# Each hole of the attack: the TOML text, and what the error must name.
HOLES = [
    ("robot_gateway = 5\n", "'robot_gateway' must be a [section]"),
    ("[robot_gateway]\nevent_interval_ms = inf\n", "[robot_gateway] event_interval_ms"),
    ("[runtime]\nconnect_timeout_s = -5.0\n", "[runtime] connect_timeout_s"),
    ("[robot_gateway]\nmax_speed_mm_s = 11000.0\n", "[robot_gateway] max_speed_mm_s"),
    ("[robot_gateway]\nenvelope_max_mm = [1e300, 1600.0, 1600.0]\n", "[robot_gateway] envelope_max_mm[0]"),
    ("[controller]\nmax_speed_mm_s = 1e9\n", "[controller] max_speed_mm_s"),
    ("[controller]\nmax_speed_mm_s = inf\n", "[controller] max_speed_mm_s"),
    ("[controller]\nlead_ms = nan\n", "[controller] lead_ms"),
    ("[controller]\ncycle_period_ms = 12.0\n", "[controller] cycle_period_ms = 12 differs from the link's cycle"),
]


@pytest.mark.parametrize("text,needle", HOLES, ids=[h[1] for h in HOLES])
def test_config_holes_are_named_errors_before_start(tmp_path, text, needle):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    r = run_cli_here("config", "--config", str(path), "--check")
    assert r.returncode != 0, r.stdout
    assert "Traceback" not in r.stderr, r.stderr
    assert str(path) in r.stderr and needle in r.stderr, r.stderr


def test_old_cycle_keys_equal_to_the_links_are_accepted_with_a_note():
    # (the cell's one cycle: tests/runtime/test_one_cycle.py)
    text = {"controller": {"cycle_period_ms": 12.0}, "robot_gateway": {"cycle_period_ms": 12.0},
            "sim_robot": {"cycle_period_ms": 12.0}, "viz": {"cycle_period_ms": 12.0}}
    assert len(cfg.from_dict(text, "f.toml", config_types()).notes) == 3


# -- hard limits at run time --------------------------------------------------------------
def _param(core, key, value) -> pb.Event:
    (topic, ev), = core.step(0, "param", pb.ParamSet(key=key, value_json=json.dumps(value)))
    assert topic == "robot_gateway/events"
    return ev


@pytest.mark.parametrize("key,value", [
    ("max_speed_mm_s", 1000.0),                         # outside the physical range
    ("max_speed_mm_s", 150.0),                          # in range, above the start value 100
    ("max_angular_speed_deg_s", 61.0),
    ("envelope_min_mm", [-1e6, -1e6, -1e6]),
    ("envelope_min_mm", [-1601.0, -1600.0, -1400.0]),   # 1 mm wider than at start
    ("envelope_max_mm", [1600.0, 1600.0, 1600.5]),
    ("stale_cycles", 100),
    ("fault_after_missed", 10_000),
])
def test_gateway_limits_cannot_be_loosened_at_run_time(key, value):
    start = AlterConfig()  # 100 mm/s, 60 deg/s, the box, 3 stale cycles, 10 misses
    core = GatewayCore(start)
    ev = _param(core, key, value)
    assert ev.code == "param_rejected" and ev.severity == pb.SEVERITY_WARNING, ev
    assert key in ev.text
    assert getattr(core.config, key) == getattr(start, key)


def test_gateway_limits_may_become_stricter_and_back_to_the_start_value():
    core = GatewayCore(AlterConfig())
    assert _param(core, "max_speed_mm_s", 50.0).code == "param_changed"
    assert core.config.max_speed_mm_s == 50.0
    assert core.config.max_step_mm == pytest.approx(50.0 * 0.028)  # 50 mm/s x 28 ms
    assert _param(core, "max_speed_mm_s", 100.0).code == "param_changed"  # back to the hard limit
    assert _param(core, "envelope_max_mm", [1000.0, 1000.0, 1000.0]).code == "param_changed"
    assert _param(core, "stale_cycles", 1).code == "param_changed"


@pytest.mark.timeout(60)
def test_param_over_the_bus_cannot_loosen_a_running_gateway(tmp_path, router, procs):
    """The attack itself: `humanpt param robot_gateway ...` against a gateway process (the
    tool in this process: its session is what reaches the gateway, not its process)."""
    port, _ = router
    conf = write_config(tmp_path / "gateway.toml", port,
                        extra=f'[robot_gateway]\nport = "{tmp_path / "no-robot-yet"}"\n')
    procs.start("robot_gateway", "--config", str(conf), "--run-dir", str(tmp_path / "run"))
    wait_alive(port, "robot_gateway")  # its params queryable is up before its token

    def param(*assignments):
        return run_cli_here("param", "robot_gateway", *assignments, "--config", str(conf), "--timeout", "10")

    r = param("max_speed_mm_s=1000", "envelope_min_mm=[-1e6,-1e6,-1e6]")
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout.count("REJECTED") == 2, r.stdout
    shown = json.loads(r.stdout[r.stdout.index("{"):])["params"]
    assert shown["max_speed_mm_s"] == 100.0 and shown["envelope_min_mm"] == [-1600.0, -1600.0, -1400.0]
    r = param("stale_cycles=100", "fault_after_missed=10000")
    assert r.returncode == 1 and r.stdout.count("REJECTED") == 2, r.stdout + r.stderr
    r = param("max_speed_mm_s=40")
    assert r.returncode == 0 and "set:" in r.stdout, r.stdout + r.stderr


def test_config_shows_each_range_and_hard_limit():
    r = run_cli_here("config")
    assert r.returncode == 0, r.stderr
    assert ("max_speed_mm_s = 100.0  # range [0.001, 250] mm/s; live, may only go lower at run time"
            in r.stdout)
    assert "connect_timeout_s = 10.0  # range [0.1, 3600] s" in r.stdout
