"""Adding a link is one folder plus one registry line (issue 30): a third, made-up link
(a text wire: ``S <cycle> <base_T_flange, 12 numbers>`` from the robot, ``C <cycle> <dp mm>
<rv rad>`` back), defined here as a link folder would define it (config table, Link, I/O
adapter, kind), registered by one line in ``links.LINKS`` and passing the rule-set test every
registered link passes (test_one_rule_set.py), with no change to the gateway."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.link import CycleReceived, CycleState, LinkError, LinkUp, Transmit
from humanpt.robot_gateway.links import LINKS, LinkKind, gateway_config, link_kind
from humanpt.runtime.config import ConfigError, build
from tests.robot_gateway import rig as rigmod
from tests.robot_gateway.rig import Rig
from tests.robot_gateway.test_one_rule_set import assert_the_rule_set, run_rule_set


# -- the link "folder": its config table, codec, Link, adapter and kind ------------------------
@dataclass(frozen=True)
class TextConfig(GatewayConfig):
    """The gateway's config over the text link: the safety rules plus the link's own field."""

    greeting: str = "hello"  # (the link's own key, in its up_text)
    link: str = "text"


@dataclass(frozen=True)
class TextCorrection:
    cycle: int
    dp_mm: tuple[float, ...]
    rv_rad: tuple[float, ...]


def encode_state(cycle: int, base_T_flange_mm: np.ndarray) -> bytes:
    return " ".join(["S", str(cycle), *(repr(float(v)) for v in base_T_flange_mm[:3].ravel())]).encode()


def decode_correction(data: bytes) -> TextCorrection:
    tag, cycle, *v = data.decode().split()
    assert tag == "C" and len(v) == 6
    return TextCorrection(int(cycle), tuple(map(float, v[:3])), tuple(map(float, v[3:])))


class TextLink:
    name = "TEXT"
    rx_topic = "serial_rx"
    tx_topic = "serial_tx"

    def __init__(self, config: TextConfig):
        self.up_text = f"text link up ({config.greeting})"
        self._running = False

    @property
    def is_running(self) -> bool:
        return self._running

    def start(self, t_ns: int) -> list:
        self._running = False
        return []

    def poll(self, t_ns: int) -> list:
        return []

    def receive(self, data: bytes, t_ns: int) -> list:
        tag, *fields = data.decode(errors="replace").split()
        if tag != "S" or len(fields) != 13:
            return [LinkError(f"TEXT link: not a state: {data[:40]!r}")]
        events = [] if self._running else [LinkUp()]
        self._running = True
        pose = np.vstack([np.array(fields[1:], float).reshape(3, 4), [0.0, 0.0, 0.0, 1.0]])
        events.append(CycleReceived(CycleState(int(fields[0]), pose, corrections_on=True, tool_mode=False,
                                               cumulative=True, arm_power=True, fault=False,
                                               correction_missed=False)))
        return events

    def correction(self, cycle, dp_mm, rv_rad, max_step_mm, max_step_deg) -> TextCorrection:
        return TextCorrection(cycle, tuple(map(float, dp_mm)), tuple(map(float, rv_rad)))  # floats: exact

    def hold(self, cycle: int, corrections_off: bool) -> TextCorrection:
        return TextCorrection(cycle, (0.0,) * 3, (0.0,) * 3)

    def send(self, c: TextCorrection, t_ns: int) -> list:
        return [Transmit(" ".join(["C", str(c.cycle), *map(repr, c.dp_mm + c.rv_rad)]).encode())]


KIND = LinkKind(name="text", config_type=TextConfig, make=TextLink, adapters=lambda config: [],
                rx_topic=TextLink.rx_topic, tx_topic=TextLink.tx_topic)


class TextRobot:
    """The test rig's robot side of the text link."""

    fields: dict = {}

    def __init__(self, config):
        pass

    def begin(self, t_ns):
        return []

    def send(self, cycle, base_T_flange_mm, bits, t_ns):
        return [encode_state(cycle, base_T_flange_mm)]

    def take(self, data, t_ns):
        c = decode_correction(data)
        return [], [(c.cycle, c)]


@pytest.fixture
def text_link(monkeypatch):
    monkeypatch.setitem(LINKS, "text", f"{__name__}:KIND")  # the one registry line
    monkeypatch.setitem(rigmod.ROBOTS, "text", TextRobot)  # (the test rig's robot side)


def test_a_third_link_passes_the_rule_set_every_link_passes(text_link):
    rig = run_rule_set("text")
    assert type(rig.gw) is GatewayCore and isinstance(rig.gw.link, TextLink)
    assert rig.gw.link.up_text == "text link up (hello)"  # (made from its own config field)
    assert_the_rule_set(rig, run_rule_set("alter"))
    # What reached the robot over the text wire is the step decided (floats: exact).
    by_cycle = dict(rig.corrections)
    np.testing.assert_allclose(by_cycle[4].dp_mm, [0.72, 0.96, 0.0], atol=1e-12)
    assert by_cycle[8].dp_mm == (0.0, 0.0, 0.0)  # stale: zero


def test_the_registry_line_makes_the_config_from_the_section(text_link):
    cfg = build(GatewayConfig, {"link": "text", "greeting": "hi", "cycle_period_ms": 12.0},
                source="cell.toml", section="robot_gateway")
    assert type(cfg) is TextConfig and cfg.greeting == "hi" and cfg.max_step_mm == pytest.approx(1.2)
    assert gateway_config("text") == TextConfig() and link_kind("text") is KIND
    with pytest.raises(ConfigError, match=r"cell.toml: \[robot_gateway\] unknown key 'port'"):
        build(GatewayConfig, {"link": "text", "port": "/dev/ttyS0"}, source="cell.toml", section="robot_gateway")


def test_without_its_registry_line_the_link_is_refused_by_name():
    assert "text" not in LINKS
    known = ", ".join(sorted(LINKS))
    with pytest.raises(ConfigError, match=rf"link 'text' is not a robot link of this version; known links: {known}$"):
        build(GatewayConfig, {"link": "text"}, source="cell.toml", section="robot_gateway")


def test_a_gateway_reads_only_its_own_links_receive_topic():
    from humanpt.runtime.core import UndeclaredInputError
    from humanpt.schemas import humanpt_pb2 as pb

    alter = Rig()
    with pytest.raises(UndeclaredInputError, match="'udp_rx' is another link's; this gateway's ALTER link reads "
                                                   "'serial_rx'"):
        alter.gw.step(0, "udp_rx", pb.SerialChunk(data=b"<Rob/>"))
    with pytest.raises(ValueError, match="link 'alter' takes .*AlterConfig, not GatewayConfig"):
        GatewayConfig()  # the safety rules alone make no gateway: a config is its link's
