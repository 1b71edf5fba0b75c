"""The cell's one cycle: the robot link's.

The robot link's cycle period (``[robot_gateway] cycle_period_ms``: ALTER's 28 ms, as in the
paper; RSI's 4 or 12 ms as configured) is the only cycle of a cell.  Who uses it, and from where:

- the gateway (the link) runs it and puts it in every ``RobotState`` (``cycle_period_ns``);
- the controller (its dt, per-cycle speed limits, the stamp of a command one cycle ahead), the
  pose filter (its prediction horizon: one cycle past a robot state's stamp) and the viewer
  (per-cycle steps drawn as speeds) take it from the latest robot state they received.  It is
  an input, so the cores stay pure and a replay gives them the same cycle as the run did;
- the simulated robot, the link's far end, is given it once by the launcher
  (``ConfigFile.component``: ``SimRobotConfig.cell_defaults`` calls :func:`cell_cycle_ns`).

No other section has a cycle.  The keys that once kept copies of it (:data:`RETIRED`) are
read as follows: in a config file, a retired key equal to the link's cycle is a deprecation
note (:attr:`ConfigFile.notes`, printed by ``humanpt config --check`` and at a component's
start) and is dropped; one that differs is a :class:`ConfigError` naming the key, its value
and the link's cycle (the run would not do what the file says).  In a recording made before
``RobotState.cycle_period_ns`` existed, the retired key is what the recorded core ran with:
:func:`recorded` maps it on reading, and the robot states' 0 (unknown) falls back to it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from humanpt.runtime.config_types import ConfigError

OWNER = "robot_gateway"  # the section whose link runs the cycle
KEY = "cycle_period_ms"  # its key there (the link's config: robot_gateway/config.py, links/<name>/config.py)
# A robot state that carries no cycle (0: a recording made before the field), before any
# state that does: ALTER's, the paper's 28 ms (what every component's default was).
FALLBACK_NS = 28_000_000
# A state's cycle outside the link configs' range (1 ms .. 1 s) is not believed (a forged or
# damaged state must not stretch a prediction horizon or a per-cycle step): unknown.
MIN_NS, MAX_NS = 1_000_000, 1_000_000_000

# (section, key) -> what the cycle is used for there.  A retired key mapped into a field of
# the component's config (the simulated robot's) names it in FIELD_OF.
RETIRED: dict[tuple[str, str], str] = {
    ("controller", "cycle_period_ms"): "the controller's dt and per-cycle speed limits",
    ("pose_filter", "predict_ahead_ms"): "the pose filter's prediction horizon",
    ("viz", "cycle_period_ms"): "the viewer's speeds from per-cycle steps",
    ("sim_robot", "cycle_period_ms"): "the simulated robot's cycle",
}
FIELD_OF = {"sim_robot": "cycle_period_ns"}

# Where the one cycle is used (humanpt config --check prints this).
USES: tuple[tuple[str, str], ...] = (
    ("robot_gateway", "the link's cycle: a robot state and an answer every cycle, per-cycle limits, watchdogs; "
                      "carried in every RobotState (cycle_period_ns)"),
    ("controller", "dt, per-cycle speed limits, the stamp of a command one cycle ahead (from the robot state)"),
    ("pose_filter", "prediction horizon: one cycle past the robot state's stamp (from the robot state)"),
    ("viz", "per-cycle steps drawn as speeds (from the robot state)"),
    ("sim_robot", "the simulated robot's cycle (given by the launcher from the link)"),
)


def ms(cycle_ns: int) -> float:
    """ns -> ms (exact for whole ms: ``ms(ns) * 1e-3`` is what ``cycle_period_ms * 1e-3`` was)."""
    return cycle_ns / 1e6


def from_state(cycle_period_ns: int) -> int | None:
    """A robot state's ``cycle_period_ns`` if it carries a believable one, else None
    (0: not carried; outside 1 ms .. 1 s: not believed)."""
    return cycle_period_ns if MIN_NS <= cycle_period_ns <= MAX_NS else None


def link_config(sections: Mapping[str, Mapping[str, Any]], source: str, config_class: type | None = None) -> Any:
    """The cell's gateway config (its link's class) from the ``[robot_gateway]`` table.
    The class comes from the component registry (named as a string there: runtime imports no
    product package) unless ``config_class`` is given."""
    from humanpt.runtime.config import build

    if config_class is None:
        from humanpt.runtime.registry import core_class

        config_class = core_class(OWNER).config_type
    table = {k: v for k, v in sections.get(OWNER, {}).items()}
    return build(config_class, table, source=source, section=OWNER)


def cell_cycle_ns(sections: Mapping[str, Mapping[str, Any]], source: str = "config",
                  config_class: type | None = None) -> int:
    """The cell's one cycle (ns): its link's, ``[robot_gateway] cycle_period_ms`` or the link's
    default (ALTER 28 ms, RSI 4 ms)."""
    return link_config(sections, source, config_class).cycle_period_ns


def retire(sections: dict[str, dict[str, Any]], source: str, link: Any) -> list[str]:
    """Drop the retired cycle keys from ``sections`` (in place) against the gateway config
    ``link``: a key equal to the link's cycle gives a deprecation note (returned); one that
    differs raises ConfigError (one line: the key, both values, what to do)."""
    notes: list[str] = []
    cycle_ms = ms(link.cycle_period_ns)
    for (section, key), use in RETIRED.items():
        table = sections.get(section)
        if not table or key not in table:
            continue
        value = table[key]
        where = f"{source}: [{section}] {key}"
        own = f"the cell's one cycle is the link's, [{OWNER}] {KEY} = {cycle_ms:g} (link {link.link!r})"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where} = {value!r}: no longer a key ({use} follows the link's cycle); "
                              f"remove it ({own})")
        if abs(value - cycle_ms) > 1e-9:
            raise ConfigError(f"{where} = {value:g} differs from the link's cycle: {own}, used for {use}; "
                              f"remove {key}, or set the cycle in [{OWNER}] {KEY}")
        notes.append(f"{where} = {value:g} is deprecated and ignored: {own}; remove it")
        del table[key]
    return notes


def recorded(component: str, table: Mapping[str, Any]) -> tuple[dict[str, Any], int | None]:
    """An old recording's config of ``component``: (the table without its retired cycle key,
    the cycle it ran with in ns, or None).  The simulated robot's goes into its config field
    (FIELD_OF); the controller's, the pose filter's and the viewer's is the fallback for the
    robot states of that recording, which carry none (``use_cycle``)."""
    out = dict(table)
    found = None
    for (section, key) in RETIRED:
        if section == component and key in out:
            value = out.pop(key)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                found = round(value * 1e6)
    field = FIELD_OF.get(component)
    if found is not None and field is not None:
        out.setdefault(field, found)
        return out, None
    return out, found


def report(cycle_ns: int, link: str) -> list[str]:
    """Lines saying the cell's one cycle and everywhere it is used (``humanpt config``)."""
    lines = [f"cycle: {ms(cycle_ns):g} ms, the robot link's ([{OWNER}] link = {link!r}, {KEY}); the cell's only "
             f"cycle, used by:"]
    width = max(len(name) for name, _ in USES)
    lines += [f"  {name:<{width}}  {ms(cycle_ns):g} ms: {use}" for name, use in USES]
    return lines
