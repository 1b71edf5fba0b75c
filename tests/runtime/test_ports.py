"""Typed cores: every core's table of input ports, checked against the topic table and
the component READMEs; dispatch by the table; what an undeclared input does."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.runtime import registry
from humanpt.runtime.core import Core, Port, UndeclaredInputError
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.selftest import PingerConfig, PingerCore, PongerConfig, PongerCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.convert import header
from humanpt.testing.harness import ScriptedControllerCore

COMPONENTS = Path(__file__).resolve().parents[2] / "components"

CORES = [registry.core_class(n) for n in registry.COMPONENTS] + [ScriptedControllerCore]

# Component -> the README whose first table of inputs lists its ports.  The self-test
# components are documented by their module (runtime/selftest.py).
README_OF = {n: COMPONENTS / n / "README.md" for n in registry.COMPONENTS if n not in ("pinger", "ponger")}
README_OF["standin_robot"] = COMPONENTS / "twin" / "README.md"


@pytest.mark.parametrize("cls", CORES, ids=lambda c: c.__name__)
def test_every_port_has_the_type_of_its_topic_in_the_topic_table(cls):
    assert cls.ports, f"{cls.__name__} declares no ports"
    for p in cls.ports:
        if p.topic in topics.TOPICS:
            assert p.on_bus
            assert p.type is topics.TOPICS[p.topic].type, p
        else:
            assert not p.on_bus
            assert p.type is topics.LOCAL_TOPICS[p.topic], p
        assert callable(getattr(cls, p.handler)), p
    assert [p.topic for p in cls.ports].count("param") == 1  # every core takes parameters


def test_a_port_whose_type_disagrees_with_the_topic_table_is_refused_at_class_creation():
    with pytest.raises(TypeError, match=r"'perception/tob' carries humanpt\.TobMeasurement.*says TobState"):
        class _Wrong(Core):
            ports = (Port("perception/tob", pb.TobState, "_on_tob"),)

            def _on_tob(self, t_ns, msg):
                return []


@pytest.mark.parametrize("ports, message", [
    ((Port("perception/tobs", pb.TobMeasurement, "_h"),), "neither a topic"),
    ((Port("perception/tob", pb.TobMeasurement, "_missing"),), "no method '_missing'"),
    ((Port("perception/tob", pb.TobMeasurement, "_h"), Port("perception/tob", pb.TobMeasurement, "_h")),
     "two ports"),
    ((Port("tick", pb.Tick, "_h"),), "tick_period_ns"),  # ticks asked for by no one
    ((Port("liveliness", pb.Liveliness, "_h"),), "watch"),  # liveliness of no one
])
def test_tables_no_shell_could_serve_are_refused(ports, message):
    with pytest.raises(TypeError, match=message):
        type("_Bad", (Core,), {"ports": ports, "_h": lambda self, t_ns, msg: []})


def test_ticks_and_watch_need_their_ports():
    with pytest.raises(TypeError, match="tick"):
        type("_Ticks", (Core,), {"tick_period_ns": lambda self: 1_000})
    with pytest.raises(TypeError, match="liveliness"):
        type("_Watches", (Core,), {"watch": ("controller",)})


@dataclass(frozen=True)
class _NoLiveKeys:
    note: str = ""


class _TwoPorts(Core):
    name = "two"
    config_type = _NoLiveKeys
    ports = (
        Port("camera/image", RawImage, "_on_image"),
        Port("console/command", pb.Command, "_on_command"),
    )

    def __init__(self):
        super().__init__(_NoLiveKeys())
        self.got: list[tuple[str, int]] = []

    def _on_image(self, t_ns, msg):
        self.got.append(("image", t_ns))
        return []

    def _on_command(self, t_ns, msg):
        self.got.append((msg.verb, t_ns))
        return [self.event(t_ns, pb.SEVERITY_INFO, "command", msg.verb)]


def test_step_hands_each_input_to_the_handler_of_its_port():
    core = _TwoPorts()
    assert core.step(1, "camera/image", RawImage()) == []
    ((topic, ev),) = core.step(2, "console/command", pb.Command(verb="hold"))
    assert topic == "two/events" and ev.text == "hold"
    assert core.got == [("image", 1), ("hold", 2)]
    # param is the base class's port: a core without live keys rejects the change.
    ((_, ev),) = core.step(3, "param", pb.ParamSet(key="note", value_json='"x"'))
    assert ev.code == "param_rejected" and core.config.note == ""


def test_an_undeclared_input_is_an_error_that_names_the_ports():
    core = PongerCore(PongerConfig())
    with pytest.raises(UndeclaredInputError, match=r"no input port 'pinger/pings'; its ports: pinger/ping, param"):
        core.step(0, "pinger/pings", pb.Tick())
    assert core.pings == 0  # nothing reached a handler


def test_lockstep_refuses_an_undeclared_input_when_it_is_injected_not_when_it_is_due():
    ls = Lockstep([PingerCore(PingerConfig()), PongerCore(PongerConfig())])
    with pytest.raises(UndeclaredInputError, match="PongerCore has no input port 'tick'"):
        ls.inject(5_000_000_000, "ponger", "tick", pb.Tick(header=header(0)))
    with pytest.raises(UndeclaredInputError, match="serial_rx"):
        ls.connect_serial("pinger", "ponger")


def test_lockstep_delivers_a_bus_topic_only_to_the_cores_with_a_port_on_it():
    pinger, ponger, two = PingerCore(PingerConfig(period_ms=10.0)), PongerCore(PongerConfig()), _TwoPorts()
    ls = Lockstep([pinger, ponger, two])
    ls.run_until(95_000_000)  # ticks at 0, 10, ..., 90 ms
    assert ponger.pings == 10
    assert two.got == []


def _input_rows(readme: Path) -> list[str]:
    """The input rows of the README's first table that has any, as lists of cells."""
    tables, cur = [], []
    for line in readme.read_text().splitlines() + [""]:
        if line.startswith("|"):
            cur.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif cur:
            tables.append(cur)
            cur = []
    for head, _, *body in tables:
        if head[0] == "input":  # a table of inputs: the first column names them
            rows = [r[0] + " | " + " | ".join(r[1:]) for r in body]
        else:  # a table of inputs and outputs: rows marked "in"/"input"
            rows = [" | ".join(r[1:]) for r in body if r[0] in ("in", "input")]
            rows += [r[0][3:] + " | " + " | ".join(r[1:]) for r in body if r[0].startswith("in `")]
        if rows:
            return rows
    return []


@pytest.mark.parametrize("name", sorted(README_OF))
def test_each_component_readme_lists_exactly_its_ports_with_their_types(name):
    cls = registry.core_class(name)
    rows = _input_rows(README_OF[name])
    listed: dict[str, str] = {}
    for row in rows:
        topic_cell = row.split(" | ")[0]
        for t in re.findall(r"`([^`]+)`", topic_cell):
            assert t not in listed, f"{name}: {t} listed twice"
            listed[t] = row
    assert sorted(listed) == sorted(p.topic for p in cls.ports), f"{README_OF[name]}: input rows"
    for p in cls.ports:
        assert re.search(rf"\b{p.type.__name__}\b", listed[p.topic]), f"{name}: {p.topic} row does not name {p.type}"
