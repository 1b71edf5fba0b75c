"""Configuration: one TOML file, a section per component, validated into frozen dataclasses.

Every component declares a frozen dataclass whose ``__post_init__`` checks ranges and
raises ``ValueError``.  :func:`build` turns a TOML table into that dataclass and
raises :class:`ConfigError` naming the file, the section and the key for an unknown
key, an ill-typed value or a value the dataclass rejects.

Fields declared with :func:`live` can be changed while the component runs (through the
parameter queryable or ``humanpt param``); the change reaches the core as an input.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal


class ConfigError(ValueError):
    """A configuration problem; the message names the file, section and key."""


def live(default: Any, doc: str = "") -> Any:
    """A dataclass field that may be changed at run time."""
    return field(default=default, metadata={"live": True, "doc": doc})


def live_keys(cls_or_obj) -> list[str]:
    """Names of the fields of a config dataclass that may change at run time."""
    return [f.name for f in dataclasses.fields(cls_or_obj) if f.metadata.get("live")]


def _type_name(tp) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def coerce(tp, value: Any, where: str) -> Any:
    """Check ``value`` (from TOML or JSON) against the annotation ``tp``; return it typed.

    Accepts int for float, lists for tuples, tables for nested dataclasses.
    """
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return coerce(a, value, where)
            except ConfigError as e:
                errors.append(str(e))
        raise ConfigError(f"{where}: {value!r} is not a {' or '.join(_type_name(a) for a in args)}")
    if origin is Literal:
        if value not in args:
            raise ConfigError(f"{where}: {value!r} is not one of {', '.join(repr(a) for a in args)}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {type(value).__name__} {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(coerce(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True)))
    if origin is dict or tp is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
        vt = args[1] if args else Any
        return {str(k): coerce(vt, v, f"{where}.{k}") for k, v in value.items()}
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
        return build(tp, value, source=where, section="")
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if isinstance(tp, type) and isinstance(value, tp):
        return value
    raise ConfigError(f"{where}: cannot check a value of type {_type_name(tp)}")


def build(cls: type, table: Mapping[str, Any], *, source: str, section: str) -> Any:
    """Validate a TOML table into the frozen dataclass ``cls``.

    ``source`` names the file (or other origin) and ``section`` the TOML section, so
    that every error reads ``FILE: [section] key: problem``.
    """
    where = f"{source}: [{section}]" if section else source
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    unknown = [k for k in table if k not in names]
    if unknown:
        raise ConfigError(f"{where} unknown key {unknown[0]!r}; known keys: {', '.join(names)}")
    kwargs = {k: coerce(hints[k], v, f"{where} {k}") for k, v in table.items()}
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{where}: {e}") from e


def to_table(obj: Any) -> dict[str, Any]:
    """A config dataclass -> plain dict (tuples as lists), JSON and TOML friendly."""
    def plain(v):
        if dataclasses.is_dataclass(v):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v
    return plain(obj)


def replace_live(obj: Any, key: str, value_json: str) -> Any:
    """A copy of ``obj`` with live field ``key`` set from JSON (validated)."""
    if key not in live_keys(obj):
        raise ConfigError(f"{key!r} is not a live parameter; live parameters: {', '.join(live_keys(obj)) or 'none'}")
    try:
        value = json.loads(value_json)
    except json.JSONDecodeError as e:
        raise ConfigError(f"{key}: value is not JSON: {e}") from e
    hints = typing.get_type_hints(type(obj))
    typed = coerce(hints[key], value, key)
    try:
        return dataclasses.replace(obj, **{key: typed})
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{key}: {e}") from e


@dataclass(frozen=True)
class RuntimeConfig:
    """The ``[runtime]`` section: where components meet and where runs are recorded."""

    cell: str = "cell0"
    mode: Literal["client", "peer"] = "client"
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)  # the router's
    # mode = "peer": components still meet at the router but then link to each other
    # directly (one hop instead of two through the router), listening here (port 0: any).
    peer_listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    run_dir: str = "runs"
    record: bool = True
    chunk_size: int = 1024 * 1024  # 1 MB: ~3 camera images; zstd per chunk has a fixed cost
    flush_interval_s: float = 1.0
    multicast_scouting: bool = False
    connect_timeout_s: float = 10.0
    # Record on a writer thread of its own: off the core's path (lower latency), but a
    # crash may then also lose the few messages still queued for it.
    record_thread: bool = False

    def __post_init__(self):
        if not self.cell or "/" in self.cell or "*" in self.cell:
            raise ValueError(f"cell {self.cell!r} must be a non-empty name without '/' or '*'")
        if self.chunk_size < 1024:
            raise ValueError("chunk_size must be at least 1024 bytes")
        if self.flush_interval_s <= 0:
            raise ValueError("flush_interval_s must be positive")


@dataclass(frozen=True)
class ConfigFile:
    """A loaded configuration: the runtime section and every component's raw table."""

    source: str
    runtime: RuntimeConfig
    sections: dict[str, dict[str, Any]]
    profiles: dict[str, tuple[str, ...]]

    def component(self, name: str, cls: type) -> Any:
        """The validated config of component ``name`` (defaults when its section is absent)."""
        return build(cls, self.sections.get(name, {}), source=self.source, section=name)


def load(path: str | Path | None, known_sections: Mapping[str, type] | None = None) -> ConfigFile:
    """Load and validate a TOML config file; ``None`` gives the defaults.

    ``known_sections`` maps component names to their config classes; a section that is
    not ``runtime``, ``profiles`` or a known component is an error, and every known
    section is validated now so that a bad key fails at start, not mid-run.
    """
    if path is None:
        data: dict[str, Any] = {}
        source = "<defaults>"
    else:
        p = Path(path)
        source = str(p)
        if not p.is_file():
            raise ConfigError(f"{source}: no such config file")
        try:
            data = tomllib.loads(p.read_text())
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"{source}: not valid TOML: {e}") from e
    return from_dict(data, source, known_sections)


def from_dict(data: Mapping[str, Any], source: str, known_sections: Mapping[str, type] | None = None) -> ConfigFile:
    """Validate an already parsed TOML document (see :func:`load`)."""
    runtime = build(RuntimeConfig, data.get("runtime", {}), source=source, section="runtime")
    profiles_raw = data.get("profiles", {})
    profiles = {k: coerce(tuple[str, ...], v, f"{source}: [profiles] {k}") for k, v in profiles_raw.items()}
    sections = {k: dict(v) for k, v in data.items() if k not in ("runtime", "profiles")}
    for name, table in sections.items():
        if not isinstance(table, Mapping):
            raise ConfigError(f"{source}: {name!r} must be a [section], got a value")
        if known_sections is not None:
            if name not in known_sections:
                raise ConfigError(f"{source}: unknown section [{name}]; known: runtime, profiles, "
                                  f"{', '.join(sorted(known_sections))}")
            build(known_sections[name], table, source=source, section=name)
    return ConfigFile(source=source, runtime=runtime, sections=sections, profiles=profiles)
