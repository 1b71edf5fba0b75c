"""Configuration: one TOML file, a section per component, validated into frozen dataclasses.

Every component declares a frozen dataclass whose ``__post_init__`` checks ranges and
raises ``ValueError``.  :func:`build` turns a TOML table into that dataclass and
raises :class:`ConfigError` naming the file, the section and the key for an unknown
key, an ill-typed value or a value the dataclass rejects.

Every number has a physical range: a numeric field is annotated
``Annotated[float, Range(lo, hi, "unit")]`` (tuples elementwise), and a value outside it, or
not finite (TOML's ``inf`` and ``nan``), is a :class:`ConfigError` naming the key before
anything starts.  ``tests/runtime/test_config.py`` checks that every numeric parameter of
every component has one.

Fields declared with :func:`live` can be changed while the component runs (through the
parameter queryable or ``humanpt param``); the change reaches the core as an input.  A live
safety limit is declared with ``stricter="lower"`` (or ``"higher"``): at run time it may only
move to the strict side of the value the component started with (its config file's value is
a hard limit, :func:`replace_live`'s ``hard``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from humanpt.runtime import cycle
from humanpt.runtime.config_types import (  # noqa: F401 (re-exported: the old import path)
    ConfigError,
    Deg,
    Mm,
    Range,
    RateDegS,
    SpeedMmS,
    live,
    live_keys,
)
from humanpt.schemas.topics import RENAMED_COMPONENTS, current_name  # noqa: F401 (re-exported)


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
    if origin is Annotated:
        typed = coerce(args[0], value, where)
        for rng in (m for m in tp.__metadata__ if isinstance(m, Range)):
            for i, v in _numbers(typed):
                rng.check(v, f"{where}{i}")
        return typed
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
        if not math.isfinite(value):
            raise ConfigError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if isinstance(tp, type) and isinstance(value, tp):
        return value
    raise ConfigError(f"{where}: cannot check a value of type {_type_name(tp)}")


def _numbers(value: Any) -> list[tuple[str, float]]:
    """(index suffix, number) of a number or a (nested) tuple of numbers."""
    if isinstance(value, (tuple, list)):
        return [(f"[{i}]{j}", v) for i, x in enumerate(value) for j, v in _numbers(x)]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [("", value)]
    return []


def hints(cls: type) -> dict[str, Any]:
    """The field annotations of a config dataclass, ranges (``Annotated``) included."""
    return typing.get_type_hints(cls, include_extras=True)


def field_notes(cls: type) -> dict[str, str]:
    """Per field of a config dataclass, what a person editing it should know: its range
    (of each element for a tuple), whether it is live, and whether it may only tighten."""
    notes = {}
    types_ = hints(cls)
    for f in dataclasses.fields(cls):
        parts = []
        ranges = {(r.lo, r.hi, r.unit) for r in _ranges(types_[f.name])}
        parts += [f"range [{lo:g}, {hi:g}]{' ' + unit if unit else ''}" for lo, hi, unit in sorted(ranges)]
        if f.metadata.get("live"):
            parts.append("live" + (f", may only go {f.metadata['stricter']} at run time"
                                   if f.metadata.get("stricter") else ""))
        if parts:
            notes[f.name] = "; ".join(parts)
    return notes


def _ranges(tp) -> list[Range]:
    if typing.get_origin(tp) is Annotated:
        return [m for m in tp.__metadata__ if isinstance(m, Range)] + _ranges(typing.get_args(tp)[0])
    return [r for a in typing.get_args(tp) if a is not Ellipsis for r in _ranges(a)]


def build(cls: type, table: Mapping[str, Any], *, source: str, section: str) -> Any:
    """Validate a TOML table into the frozen dataclass ``cls``.

    ``source`` names the file (or other origin) and ``section`` the TOML section, so
    that every error reads ``FILE: [section] key: problem``.
    """
    where = f"{source}: [{section}]" if section else source
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}: must be a [section] (a table), got {type(table).__name__} {table!r}")
    select = getattr(cls, "config_class_for", None)
    if select is not None:  # a config whose class one key chooses ([robot_gateway] link)
        cls = select(table)
    types_ = hints(cls)
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    unknown = [k for k in table if k not in names]
    if unknown:
        raise ConfigError(f"{where} unknown key {unknown[0]!r}; known keys: {', '.join(names)}")
    kwargs = {k: coerce(types_[k], v, f"{where} {k}") for k, v in table.items()}
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


def _toml_value(v: Any, where: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        raise ConfigError(f"{where}: {v!r} cannot be written (values are finite)")
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x, where) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x, where)}" for k, x in v.items()
                               if x is not None) + "}"
    raise ConfigError(f"{where}: cannot write a {type(v).__name__} to TOML")


def _toml_key(k: str) -> str:
    return k if k and all(c.isalnum() or c in "_-" for c in k) else json.dumps(k)


def dumps_toml(doc: Mapping[str, Any], prefix: str = "") -> str:
    """A document of plain values (numbers, strings, bools, lists, nested tables) as TOML
    that a person can read: scalars and lists on one line each, nested tables as
    ``[a.b]`` sections (an empty or all-scalar table of one level deeper inline when it is
    a small leaf, e.g. ``sigma = {a_u = 0.4}``).  None values are left out (TOML has no null).
    ``tomllib.loads(dumps_toml(d))`` gives ``d`` back (tuples as lists)."""
    lines: list[str] = []
    sub: list[tuple[str, Mapping]] = []
    for k, v in doc.items():
        if v is None:
            continue
        if isinstance(v, Mapping) and any(isinstance(x, Mapping) for x in v.values()):
            sub.append((k, v))
        elif isinstance(v, Mapping) and prefix and len(v) <= 4:
            lines.append(f"{_toml_key(k)} = {_toml_value(v, prefix + k)}")
        elif isinstance(v, Mapping):
            sub.append((k, v))
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v, prefix + k)}")
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in sub:
        name = f"{prefix}{_toml_key(k)}"
        out += f"\n[{name}]\n" + dumps_toml(v, name + ".")
    return out


def replace_live(obj: Any, key: str, value_json: str, hard: Any = None) -> Any:
    """A copy of ``obj`` with live field ``key`` set from JSON (validated).

    ``hard`` is the config the component started with: a field declared
    ``live(..., stricter=...)`` may not pass its value there (:func:`live`)."""
    if key not in live_keys(obj):
        raise ConfigError(f"{key!r} is not a live parameter; live parameters: {', '.join(live_keys(obj)) or 'none'}")
    try:
        value = json.loads(value_json)
    except (json.JSONDecodeError, RecursionError) as e:
        raise ConfigError(f"{key}: value is not JSON: {e}") from e
    typed = coerce(hints(type(obj))[key], value, key)
    stricter = next(f for f in dataclasses.fields(obj) if f.name == key).metadata.get("stricter")
    if stricter and hard is not None:
        limit = getattr(hard, key)
        pairs = zip(_numbers(typed), _numbers(limit), strict=True)
        if any((v > h) if stricter == "lower" else (v < h) for (_, v), (_, h) in pairs):
            side = "above" if stricter == "lower" else "below"
            raise ConfigError(f"{key}: {typed!r} is {side} the hard limit {limit!r} this component "
                              f"started with; at run time a safety limit may only become stricter")
    try:
        return dataclasses.replace(obj, **{key: typed})
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{key}: {e}") from e


_CELL = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]{0,99}")


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
    # At most 64 MiB: a chunk holds chunk_size plus one message, and the reader refuses a chunk
    # declaring more than 256 MiB (runtime.recording.MAX_CHUNK_BYTES: a crafted file's 2 GiB).
    chunk_size: Annotated[int, Range(1024, 64 * 2**20, "bytes")] = 1024 * 1024  # 1 MB: ~3 camera images; zstd per chunk has a fixed cost
    flush_interval_s: Annotated[float, Range(0.01, 3600, "s")] = 1.0
    multicast_scouting: bool = False
    connect_timeout_s: Annotated[float, Range(0.1, 3600, "s")] = 10.0
    # A tool (topics, echo, param, console) gives up on the router sooner: a person is
    # waiting (zenoh adds ~2 s to it; with the interpreter's start, ~4 s to the message).
    tool_connect_timeout_s: Annotated[float, Range(0.1, 3600, "s")] = 2.0
    # Record on a writer thread of its own: off the core's path (lower latency), but a
    # crash may then also lose the few messages still queued for it.
    record_thread: bool = False
    # A realtime core's process (Core.realtime: the robot gateway, the simulated robot, the
    # controller, the pose filter; runtime.tuning.tune_realtime). A thread woken by a
    # datagram waits up to the GIL's switch interval behind a busy one (every humanpt
    # process: 0.5 ms), an eighth of RSI's 4 ms cycle, and such waits add up along the way:
    # such a process switches every this many ms. Without SCHED_FIFO (below) it asks for this
    # nice value (needs CAP_SYS_NICE, else it runs at the normal priority with a note).
    realtime_switch_interval_ms: Annotated[float, Range(0.05, 5, "ms")] = 0.2
    realtime_nice: Annotated[int, Range(-20, 0, "")] = -10
    # ... or the kernel's SCHED_FIFO real-time class at this priority (0: not asked; then
    # realtime_nice), as RSI clients on a real cell run. The kernel keeps 5 % of each second
    # for ordinary tasks (sched_rt_runtime_us), so a runaway cannot hang the machine.
    realtime_fifo_priority: Annotated[int, Range(0, 99, "")] = 10
    # The rig file: what the pipeline believes about the hardware (intrinsics, mirrors,
    # hand-eye, target, tip), written by `humanpt calibrate` or `humanpt rig init`.  A
    # relative path is relative to this config file.  Empty: the nominal design rig.
    rig: str = ""
    # "mtls": every session (router, components, tools) runs over TLS with mutual
    # authentication, each process with its own certificate from the cell's PKI (``pki``),
    # and the router enforces access control generated from the topic table
    # (humanpt.runtime.security).  tcp/ endpoints are then taken as tls/ on the same port.
    security: Literal["none", "mtls"] = "none"
    # The PKI directory (`humanpt pki init`): the CA and the certificates.  A relative path
    # is relative to this config file; empty: pki/ in the working directory.
    pki: str = ""
    # The certificate a tool (topics, echo, console, param...) presents under mTLS; empty:
    # "tool" (read-only).  `--as NAME` on the command line; an operator's certificate may
    # command and set parameters.  Components always present their own name's certificate.
    identity: str = ""
    # mTLS: the router reports each attempt its access control refuses, as a warning event
    # on router/events (the 1st, 10th, 100th... per identity, message and key) and a log
    # line.  Zenoh says so only in a trace line of every message, allowed or not, which the
    # router reads from its own stdout: ~5-7 us of router CPU per message (measured).
    report_denied: bool = True

    def __post_init__(self):
        if not _CELL.fullmatch(self.cell):
            # It is a chunk of every Zenoh key (humanpt/<cell>/...): '/', '*', '$', '?', '#'
            # would be key-expression syntax or errors, '..' a confusing name.
            raise ValueError(f"cell {self.cell!r} must be a name of letters, digits, '_', '-' and '.' "
                             "(not first), at most 100 characters")
        if self.security == "mtls":
            if self.mode == "peer":
                raise ValueError('security = "mtls" needs mode = "client": the router enforces access control, '
                                 "and peers would link to each other around it")
            for ep in (*self.connect, *self.listen):
                if not (ep.startswith("tcp/") or ep.startswith("tls/")):
                    raise ValueError(f'endpoint {ep!r}: with security = "mtls" endpoints are tcp/ (taken as tls/) '
                                     f"or tls/")
        if self.identity and ("/" in self.identity or "*" in self.identity):
            raise ValueError(f"identity {self.identity!r} must be a certificate's name without '/' or '*'")
        if self.chunk_size < 1024:
            raise ValueError("chunk_size must be at least 1024 bytes")
        if self.flush_interval_s <= 0:
            raise ValueError("flush_interval_s must be positive")


IMAGES_EVERY_MAX = 100_000  # "every N": at most one image in this many


def keep_every(images: str) -> int:
    """``[record] images`` -> keep one image in how many: ``"all"`` 1, ``"every N"`` N,
    ``"none"`` 0.  ValueError (one line, naming the accepted forms) for anything else."""
    text = " ".join(str(images).split())
    if text == "all":
        return 1
    if text == "none":
        return 0
    word, _, n = text.partition(" ")
    if word == "every" and n.isdigit() and 1 <= int(n) <= IMAGES_EVERY_MAX:
        return int(n)
    raise ValueError(f'images = {images!r}: must be "all", "every N" (N a whole number from 1 to '
                     f'{IMAGES_EVERY_MAX}) or "none"')


@dataclass(frozen=True)
class RecordConfig:
    """The ``[record]`` section: what a run's recordings keep of its images (foxglove.RawImage
    messages: ``camera/image``, the camera's ``capture``).  runtime/README.md "Images"."""

    # The run's copy of each image: the producer's (sim_camera/camera output, the camera's
    # capture input), or a consumer's when no producer records in its run directory.
    # "all", "every N" (the 1st, N+1th... of each topic; the others are kept without
    # their pixels) or "none" (no pixels at all).  Lossless either way: zstd chunks.
    images: str = "all"
    # A consumer's image inputs (perception's, viz's camera/image): "reference" keeps the
    # image's identity (stamp + frame_id, pixels left out) when the producer records into
    # the same run directory (lock-step: it is recorded; live: its recording is there and
    # being written when the first image arrives), else the pixels as for the producer;
    # "keep": always the pixels (each image twice in the run, as before).
    image_inputs: Literal["reference", "keep"] = "reference"
    # MCAP chunk size of the recordings of the image producers (camera, sim_camera; the
    # others keep [runtime] chunk_size, the larger of the two wins): zstd compresses each
    # chunk alone, so it finds what successive frames share only within one (the twin's
    # background noise is drawn from one bank: 4 MiB chunks hold ~13 frames and make its
    # recording ~35 % smaller; a real sensor's noise is not shared). A crash loses at most
    # the chunk in progress, and it is flushed every [runtime] flush_interval_s anyway.
    image_chunk_size: Annotated[int, Range(1024, 64 * 2**20, "bytes")] = 4 * 1024 * 1024
    # Every this many seconds of input time each shell freezes its core's state into the
    # recording (runtime/snapshot.py), so that `humanpt replay --last S` need not replay a long
    # run from its start; 0: never.  runtime/README.md "Snapshots" (size and time measured).
    snapshot_period_s: Annotated[float, Range(0.0, 86400.0, "s")] = 10.0
    # Live, a realtime core (gateway, controller, pose filter, simulated robot) freezes its
    # state on its own thread, inside the cycle: the pose filter's takes about 38 ms (its
    # robot pose buffer), ten 4 ms cycles. So live realtime cores take no snapshots unless
    # this is true (lock-step runs and the other cores always do, every snapshot_period_s).
    snapshot_realtime: bool = False

    def __post_init__(self):
        keep_every(self.images)

    @property
    def keep_every(self) -> int:
        """Keep one image in this many (1: all, 0: none)."""
        return keep_every(self.images)


@dataclass(frozen=True)
class ConfigFile:
    """A loaded configuration: the runtime section and every component's raw table."""

    source: str
    runtime: RuntimeConfig
    sections: dict[str, dict[str, Any]]
    profiles: dict[str, tuple[str, ...]]
    record: RecordConfig = RecordConfig()
    # Deprecation notes (a retired cycle key equal to the link's: runtime/cycle.py), for the
    # tools to print; an error stops the load instead.
    notes: tuple[str, ...] = ()
    # The cell's one cycle, ns: its robot link's (runtime/cycle.py), and that link's name.
    cycle_period_ns: int = cycle.FALLBACK_NS
    cycle_link: str = "alter"

    def rig_path(self) -> Path | None:
        """The rig file ``[runtime] rig`` names (relative to the config file), or None."""
        if not self.runtime.rig:
            return None
        p = Path(self.runtime.rig).expanduser()
        if not p.is_absolute() and self.source not in ("<defaults>", ""):
            p = Path(self.source).resolve().parent / p
        return p

    def rig(self) -> Any:
        """The validated rig (:class:`humanpt.geometry.rig.Rig`): the file ``[runtime] rig``
        names, or the nominal design rig when it names none.  ConfigError for a missing or
        bad file, naming the field."""
        from humanpt.geometry.rig import Rig
        from humanpt.runtime.rigfile import load_rig

        p = self.rig_path()
        return Rig() if p is None else load_rig(p)

    def component(self, name: str, cls: type) -> Any:
        """The validated config of component ``name`` (defaults when its section is absent).
        A config class with a ``cell_defaults(sections)`` class method takes values its own
        section does not set from the cell's other sections (the controller's workspace
        envelope is the robot gateway's; the simulated robot's cycle is the link's).  A config
        with a ``check_cycle(cycle_period_ns)`` method is checked at the cell's one cycle
        (ValueError -> ConfigError naming the section)."""
        table = dict(self.sections.get(name, {}))
        cell_defaults = getattr(cls, "cell_defaults", None)
        if cell_defaults is not None:
            table = {**cell_defaults(self.sections, self.source), **table}
        built = build(cls, table, source=self.source, section=name)
        check_cycle = getattr(built, "check_cycle", None)
        if check_cycle is not None:  # what must hold at the cell's cycle (the controller's gains)
            try:
                check_cycle(self.cycle_period_ns)
            except ValueError as e:
                raise ConfigError(f"{self.source}: [{name}] {e}") from e
        return built


def read_toml(path: str | Path, kind: str = "config", hint: str = "") -> dict[str, Any]:
    """A TOML file's tables; ConfigError ``FILE: no such <kind> file<hint>`` or ``FILE: not
    valid TOML: ...`` (the config, rig and world files all read this way)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such {kind} file{hint}")
    try:
        return tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"{p}: not valid TOML: {e}") from None


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
        source = str(Path(path))
        data = read_toml(path)
    return from_dict(data, source, known_sections)


def from_dict(data: Mapping[str, Any], source: str, known_sections: Mapping[str, type] | None = None) -> ConfigFile:
    """Validate an already parsed TOML document (see :func:`load`)."""
    for name, table in data.items():
        if not isinstance(table, Mapping):
            raise ConfigError(f"{source}: {name!r} must be a [section] (a table), got "
                              f"{type(table).__name__} {table!r}")
    runtime = build(RuntimeConfig, data.get("runtime", {}), source=source, section="runtime")
    if runtime.pki and source not in ("<defaults>", "") and not Path(runtime.pki).expanduser().is_absolute() \
            and Path(source).is_file():
        # as the rig: a relative PKI directory is relative to the config file, so the
        # processes `humanpt up` starts find it from any working directory
        runtime = dataclasses.replace(runtime, pki=str(Path(source).resolve().parent / runtime.pki))
    profiles_raw = data.get("profiles", {})
    profiles = {k: coerce(tuple[str, ...], v, f"{source}: [profiles] {k}") for k, v in profiles_raw.items()}
    record = build(RecordConfig, data.get("record", {}), source=source, section="record")
    sections = {k: dict(v) for k, v in data.items() if k not in ("runtime", "profiles", "record")}
    for old, new in RENAMED_COMPONENTS.items():
        if old in sections:
            if new in sections:
                raise ConfigError(f"{source}: both [{old}] and [{new}]: [{old}] is the old name of [{new}]; "
                                  f"keep one")
            sections[new] = sections.pop(old)
    profiles = {k: tuple(current_name(c) for c in v) for k, v in profiles.items()}
    if known_sections is not None:
        for name in sections:
            if name not in known_sections:
                raise ConfigError(f"{source}: unknown section [{name}]; known: runtime, profiles, record, "
                                  f"{', '.join(sorted(known_sections))}")
    # The cell's one cycle is its link's (runtime/cycle.py): the keys that once copied it
    # are dropped here (a note when equal to the link's, an error when not).
    link = cycle.link_config(sections, source, (known_sections or {}).get(cycle.OWNER))
    notes = tuple(cycle.retire(sections, source, link))
    cf = ConfigFile(source=source, runtime=runtime, sections=sections, profiles=profiles, record=record,
                    notes=notes, cycle_period_ns=link.cycle_period_ns, cycle_link=link.link)
    if known_sections is not None:
        for name, cls in known_sections.items():
            cf.component(name, cls)
    return cf
