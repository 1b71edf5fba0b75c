"""The component contract: a pure core with ``step(t_ns, topic, message)``.

A core never reads the wall clock, never draws unseeded random numbers, never starts
threads and never touches Zenoh, files or serial ports.  Timer ticks (topic ``tick``),
parameter changes (topic ``param``) and serial bytes reach it as inputs like any other
message.  A shell (live, replay or lock-step) binds it to the world.

A core states its inputs once, as a table of :class:`Port` rows (topic, message type,
handler) on its class; :meth:`Core.step` dispatches by that table and every shell uses it
to subscribe and to decode.

Replaying a core's recorded inputs into a fresh core built from the same config must
reproduce its recorded outputs exactly; every shell relies on that.
"""

from __future__ import annotations

import dataclasses
import json
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from google.protobuf.message import Message

from humanpt.runtime.config import ConfigError, live_keys, replace_live, to_table
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.checks import ABSURD, absurd_field
from humanpt.schemas.convert import header

Output = tuple[str, Message]


def count_decades(counts: dict, key) -> int | None:
    """Count one more ``key`` in ``counts``; the count when it is 1, 10, 100... (worth a
    report: a flood of the same fault must not become a flood of events), else None."""
    n = counts[key] = counts.get(key, 0) + 1
    return n if n == 10 ** (len(str(n)) - 1) else None


def command_operator(msg: pb.Command) -> str:
    """Who sent a console command: the ``operator`` its arguments name ("user@host", what
    ``humanpt console`` sends), or "" when none does."""
    try:
        args = json.loads(msg.args_json or "{}")
    except (ValueError, RecursionError):
        return ""
    who = args.get("operator") if isinstance(args, dict) else None
    return who.strip()[:100] if isinstance(who, str) else ""


@dataclass(frozen=True)
class Port:
    """One input of a core: messages on ``topic`` (a short name: ``<component>/<topic>`` from
    the bus, or a local input without a slash: ``tick``, ``param``, ``serial_rx``,
    ``liveliness``, ``capture``) are of protobuf class ``type`` and go to the core's method
    named ``handler``, called as ``handler(t_ns, msg) -> list[Output]``.

    ``type`` must be the topic's type in ``humanpt.schemas.topics`` (checked when the core
    class is created): the shells decode what arrives on ``topic`` with it.

    ``queue``: how many messages of a bus topic the live shell holds while the core is busy;
    beyond it the oldest is dropped (counted).  1 means latest wins (a newer image replaces the
    one waiting).  Local inputs (serial bytes, ticks, liveliness, parameters) are never
    bounded and always go first: bus traffic can never delay the serial line.
    """

    topic: str
    type: type[Message]
    handler: str
    queue: int = 64

    @property
    def on_bus(self) -> bool:
        """Whether messages come from the bus (a topic of the topic table) rather than from
        the shell itself."""
        return self.topic in topics.TOPICS


# Every core takes live parameter changes (:meth:`Core._on_param`); the base class adds
# this port to each core's table.
PARAM_PORT = Port("param", pb.ParamSet, "_on_param")


class UndeclaredInputError(ValueError):
    """An input on a topic the core has no port for.

    Shells deliver only declared ports, so this is the caller's mistake (a wrong topic
    given to ``step`` or ``Lockstep.inject``, or a recording of a core that had a port
    this version dropped); it is raised rather than dropped so that a misspelt topic
    cannot silently starve a core.
    """


def _check_ports(cls: type[Core]) -> None:
    """Refuse a port table that no shell could serve (TypeError, at class creation)."""
    seen: set[str] = set()
    for p in cls.ports:
        where = f"{cls.__name__}.ports"
        if not isinstance(p, Port):
            raise TypeError(f"{where}: {p!r} is not a Port")
        if p.topic in seen:
            raise TypeError(f"{where}: two ports on {p.topic!r}")
        seen.add(p.topic)
        try:
            expected = topics.message_type(p.topic)
        except topics.UnknownTopicError:
            raise TypeError(f"{where}: {p.topic!r} is neither a topic of humanpt.schemas.topics nor a "
                            f"local input ({', '.join(topics.LOCAL_TOPICS)})") from None
        if p.type is not expected:
            raise TypeError(f"{where}: {p.topic!r} carries {expected.DESCRIPTOR.full_name} "
                            f"(humanpt.schemas.topics), the port says {p.type.__name__}")
        if not callable(getattr(cls, p.handler, None)):
            raise TypeError(f"{where}: {cls.__name__} has no method {p.handler!r} for {p.topic!r}")
    # The shells deliver ticks when tick_period_ns says so, and liveliness for ``watch``.
    ticks = cls.tick_period_ns is not Core.tick_period_ns
    if ticks != ("tick" in seen):
        raise TypeError(f"{cls.__name__}: a core that overrides tick_period_ns needs a 'tick' port, "
                        "and one with a 'tick' port must override tick_period_ns")
    if bool(cls.watch) != ("liveliness" in seen):
        raise TypeError(f"{cls.__name__}: a core that watches components needs a 'liveliness' port, "
                        "and one with a 'liveliness' port must name them in watch")


class Core:
    """Base class of every component core.

    Subclasses set ``name`` (the component name, first part of its topics),
    ``config_type`` (a frozen dataclass) and ``ports``: one :class:`Port` per input, bus
    topics and local inputs alike, e.g.
    ``ports = (Port("perception/tob", pb.TobMeasurement, "_on_tob"), Port("tick", pb.Tick,
    "_on_tick"))``; the base class adds :data:`PARAM_PORT`, and checks the table when the
    class is created.  A core with a ``tick`` port returns its period from
    :meth:`tick_period_ns`; one that must know whether other components are up names them
    in ``watch`` and has a ``liveliness`` port.  Outputs on local topics (``serial_tx``) go
    to the shell's adapters, not the bus.
    """

    name: ClassVar[str] = ""
    config_type: ClassVar[type] = type(None)
    # Every input of the core (see Port); after class creation it includes PARAM_PORT.
    ports: ClassVar[tuple[Port, ...]] = (PARAM_PORT,)
    # Components whose liveliness this core is told about (``liveliness`` inputs).
    watch: ClassVar[tuple[str, ...]] = ()
    _port_of: ClassVar[dict[str, Port]] = {PARAM_PORT.topic: PARAM_PORT}
    # Whether the core reads the rig (what the pipeline believes about the hardware,
    # :class:`humanpt.geometry.rig.Rig`): it is then built as ``cls(config, rig=...)``
    # (:meth:`create`) and defaults to the nominal rig when given none.
    uses_rig: ClassVar[bool] = False
    # A core on a robot link's hard cycle (the gateway, the simulated controller): its process
    # gets the GIL more often and, where allowed, a higher priority (runtime.tuning
    # .tune_realtime); the live shell records off its worker thread and never gives it a
    # tick sooner than a period after the last was taken.
    realtime: ClassVar[bool] = False
    # Snapshots (:meth:`freeze`, :meth:`thaw`, runtime/snapshot.py): the attributes a
    # snapshot leaves out, a thawed core keeping those it was built with: what ``__init__`` and
    # :meth:`on_config_changed` make from the config and the rig alone (a renderer's noise
    # bank), and records kept for benches and tests that no output depends on (the
    # corrections sent); ``"robot.applied"`` names an attribute of an object the core holds.
    # Everything else is frozen.
    not_frozen: ClassVar[frozenset[str]] = frozenset()
    # Classes the core's state may hold that a freshly built core holds none of (the items
    # of a queue that starts empty); a snapshot builds objects of these and of those only.
    state_types: ClassVar[tuple[type, ...]] = ()
    # What no core freezes: replay rebuilds the core from its recorded config and rig.
    _NOT_FROZEN: ClassVar[frozenset[str]] = frozenset({"config", "start_config", "rig", "_handlers"})

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        declared = cls.__dict__.get("ports")
        if declared is not None and all(p.topic != PARAM_PORT.topic for p in declared):
            cls.ports = (*declared, PARAM_PORT)
        _check_ports(cls)
        cls._port_of = {p.topic: p for p in cls.ports}

    def __init__(self, config: Any, rig: Any = None):
        if not isinstance(config, self.config_type):
            raise TypeError(f"{type(self).__name__} needs a {self.config_type.__name__}, got {type(config).__name__}")
        self.config = config
        # The rig the core was started with (None for a core that needs none and was given
        # none); every shell records it, and replay rebuilds the core with it.
        self.rig = rig
        # The config the core started with: the hard limit of its ``stricter`` parameters.
        self.start_config = config
        self._seq: dict[str, int] = defaultdict(int)
        self._bad_inputs: dict[str, int] = {}
        # topic -> bound handler: step's one lookup per input.
        self._handlers: dict[str, Callable[[int, Message], list[Output]]] = {
            p.topic: self._bind(p) for p in self.ports}

    # -- what shells call -------------------------------------------------------------
    @classmethod
    def default_config(cls) -> Any:
        """The config a section left empty gives: ``config_type()``, or the class a config
        type picks for an empty table (``config_class_for``: the gateway's default link's)."""
        pick = getattr(cls.config_type, "config_class_for", None)
        return (pick({}) if pick else cls.config_type)()

    @classmethod
    def create(cls, config: Any, rig: Any = None) -> Core:
        """A core of this class from its config and the cell's rig (recorded by the shells
        with every core; only a core that ``uses_rig`` reads it)."""
        if cls.uses_rig:
            return cls(config, rig=rig)
        core = cls(config)
        core.rig = rig
        return core

    def recording_metadata(self, shell: str, **extra: Any) -> dict[str, Any]:
        """What every shell writes into this core's recording: the component, its core
        class and config, the rig (JSON) and the software version, plus ``extra``."""
        import humanpt
        from humanpt.runtime.registry import class_path  # (the registry imports this module)

        meta: dict[str, Any] = {"component": self.name, "core": class_path(type(self)),
                                "config": to_table(self.config), "version": humanpt.__version__, "shell": shell}
        if self.rig is not None:
            from humanpt.runtime.rigfile import rig_to_json

            meta["rig"] = rig_to_json(self.rig)
        return {**meta, **extra}

    def tick_period_ns(self) -> int | None:
        """Period of the ``tick`` input this core wants, or None for no ticks."""
        return None

    @classmethod
    def port(cls, topic: str) -> Port:
        """The port of input ``topic`` (UndeclaredInputError if the core has none)."""
        try:
            return cls._port_of[topic]
        except KeyError:
            raise UndeclaredInputError(cls._undeclared(topic)) from None

    def step(self, t_ns: int, topic: str, msg: Message) -> list[Output]:
        """Consume one input given at time ``t_ns`` (ns) on one of the core's ports; return
        the outputs it causes.  An undeclared ``topic`` raises UndeclaredInputError."""
        try:
            handler = self._handlers[topic]
        except KeyError:
            raise UndeclaredInputError(self._undeclared(topic)) from None
        bad = absurd_field(msg)
        if bad is not None:
            return self._bad_input(t_ns, topic, bad)
        return handler(t_ns, msg)

    def _bad_input(self, t_ns: int, topic: str, what: str) -> list[Output]:
        """Drop an input with a non-finite or absurd number before it touches any state;
        report the 1st, 10th, 100th... of each topic (a flood must not become one)."""
        n = count_decades(self._bad_inputs, topic)
        if n is None:
            return []
        return [self.event(t_ns, pb.SEVERITY_WARNING, "bad_input",
                           f"{self.name}: input on {topic} dropped ({n} so far): {what} is not a "
                           f"finite number within +-{ABSURD:g}")]

    @classmethod
    def _undeclared(cls, topic: str) -> str:
        return (f"{cls.__name__} has no input port {topic!r}; its ports: "
                f"{', '.join(p.topic for p in cls.ports)}")

    def warm_up(self) -> None:
        """Work to do once before the first input, called by a live shell before the
        component says it is up (e.g. perception compiles its detector on a fresh install);
        it must not change what the core does with its inputs (replays never call it).
        Default: nothing."""

    def params(self) -> dict[str, Any]:
        """Current values of the live parameters."""
        table = to_table(self.config)
        return {k: table[k] for k in live_keys(self.config)}

    # -- snapshots (copper-rs's Freezable) ----------------------------------------------
    @property
    def unfrozen_attrs(self) -> frozenset[str]:
        """The attributes a snapshot does not hold: :attr:`not_frozen` and what every core
        rebuilds from its recording (start config, rig, handlers)."""
        return self._NOT_FROZEN | self.not_frozen

    def freeze(self) -> dict[str, Any]:
        """The core's state as plain data (JSON-able; runtime/snapshot.py): its live config
        as a table and every attribute but :attr:`unfrozen_attrs`.  A core whose state this
        default cannot encode overrides it and :meth:`thaw` together."""
        from humanpt.runtime.snapshot import Encoder

        shared = {id(getattr(self, k)): k for k in sorted(self.unfrozen_attrs - {"_handlers"})
                  if not isinstance(getattr(self, k, None), (type(None), bool, int, float, str))}
        enc = Encoder(shared, self._skipped_places())
        return {"config": to_table(self.config),
                "state": {k: enc.encode(v, f"{self.name}.{k}") for k, v in vars(self).items()
                          if k not in self.unfrozen_attrs}}

    def thaw(self, frozen: Any) -> None:
        """Put a state made by :meth:`freeze` into this core, a fresh one built from the same
        config and rig as the frozen core was.  Nothing in it is executed or imported: every
        value is checked against this core's own at the same place (kind, an array's dtype,
        no unknown or missing attribute), a changed config only in its live
        parameters and within their hard limits, as a parameter change would be.  Raises
        :class:`~humanpt.runtime.snapshot.SnapshotError` (one line); the core is then to be
        thrown away."""
        from humanpt.runtime.snapshot import Decoder, SnapshotError, held

        if type(frozen) is not dict or set(frozen) != {"config", "state"} or type(frozen["state"]) is not dict:
            raise SnapshotError(f"{self.name}: a snapshot is a table of 'config' and 'state'")
        config = self._thawed_config(frozen["config"])
        if config != self.config:
            old, self.config = self.config, config
            self.on_config_changed(old, config)
        fresh = {k: v for k, v in vars(self).items() if k not in self.unfrozen_attrs}
        state = frozen["state"]
        # An attribute set on first use (controller's _last_mode), its default on the class.
        lazy = [k for k in state if type(k) is str and k not in fresh and k not in self.unfrozen_attrs
                and not k.startswith("__") and hasattr(type(self), k)]
        fresh.update({k: getattr(type(self), k) for k in lazy
                      if isinstance(getattr(type(self), k), (type(None), bool, int, float, str))})
        unknown = sorted(set(state) - set(fresh), key=str)
        missing = sorted(set(fresh) - set(state))
        if unknown:
            raise SnapshotError(f"{self.name}: unknown field {str(unknown[0])[:40]!r} in the snapshot")
        if missing:
            raise SnapshotError(f"{self.name}: field {missing[0]!r} missing from the snapshot")
        known = held(self)
        for cls in self.state_types:
            known.classes.setdefault(cls.__qualname__, cls)
        dec = Decoder(known, self, self._skipped_places())
        try:
            values = {k: dec.decode(v, fresh[k], f"{self.name}.{k}") for k, v in state.items()}
        except SnapshotError:
            raise
        except RecursionError:
            raise SnapshotError(f"{self.name}: the snapshot is nested too deeply") from None
        except (TypeError, ValueError, AttributeError, KeyError, IndexError, OverflowError, MemoryError) as e:
            raise SnapshotError(f"{self.name}: the snapshot cannot be thawed ({type(e).__name__}: "
                                f"{str(e)[:200]})") from None
        vars(self).update(values)

    def _skipped_places(self) -> frozenset[str]:
        """The places of :attr:`not_frozen` inside the core's objects (``robot.applied``), as
        the snapshot names them (``sim_robot.robot.applied``)."""
        return frozenset(f"{self.name}.{p}" for p in self.not_frozen if "." in p)

    def _thawed_config(self, table: Any) -> Any:
        """The config a snapshot holds: the start config with the live parameters that
        differ applied as parameter changes (checked, within their hard limits)."""
        from humanpt.runtime.snapshot import SnapshotError

        start = to_table(self.start_config)
        if type(table) is not dict:
            raise SnapshotError(f"{self.name}: the snapshot's config is not a table")
        extra = sorted(set(table) - set(start), key=str)
        if extra or set(start) - set(table):
            key = extra[0] if extra else sorted(set(start) - set(table))[0]
            raise SnapshotError(f"{self.name}: the snapshot's config {'has an unknown' if extra else 'lacks the'} "
                                f"key {str(key)[:40]!r}")
        config = self.start_config
        live = set(live_keys(config))
        for key in start:
            if table[key] == start[key]:
                continue
            if key not in live:
                raise SnapshotError(f"{self.name}: the snapshot's config changes {key!r}, which is not a live "
                                    f"parameter")
            try:
                config = replace_live(config, key, json.dumps(table[key]), hard=self.start_config)
            except (ConfigError, TypeError, ValueError) as e:
                raise SnapshotError(f"{self.name}: the snapshot's config: {e}") from None
        return config

    # -- what subclasses implement / use -----------------------------------------------
    def _bind(self, port: Port) -> Callable[[int, Message], list[Output]]:
        """What takes ``port``'s inputs: the method named ``port.handler``.  A core that
        treats many topics alike and must know which one came (viz) binds one per topic."""
        return getattr(self, port.handler)

    def check_config(self, config: Any) -> None:
        """Refuse (ValueError) a parameter change that the config alone cannot judge, given
        what the core knows (the controller's gains at the link's cycle); default: none."""

    def on_config_changed(self, old: Any, new: Any) -> None:
        """Called after a live parameter changed ``self.config`` from ``old`` to ``new``."""

    def next_header(self, topic: str, stamp_ns: int, frame_id: str = "") -> pb.Header:
        """A header for the next message on ``topic`` (sequence numbers count per topic)."""
        seq = self._seq[topic]
        self._seq[topic] = seq + 1
        return header(stamp_ns, seq, frame_id)

    def event(self, t_ns: int, severity: int, code: str, text: str) -> Output:
        """An event output on ``<name>/events``."""
        topic = f"{self.name}/events"
        return topic, pb.Event(header=self.next_header(topic, t_ns), severity=severity,
                               source=self.name, code=code, text=text)

    # -- parameters ----------------------------------------------------------------------
    def _on_param(self, t_ns: int, msg: pb.ParamSet) -> list[Output]:
        old = self.config
        try:
            new = replace_live(old, msg.key, msg.value_json, hard=self.start_config)
            self.check_config(new)
        except (ConfigError, ValueError) as e:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "param_rejected", f"{self.name}: {e}")]
        self.config = new
        self.on_config_changed(old, new)
        value = dataclasses.asdict(new)[msg.key]
        return [self.event(t_ns, pb.SEVERITY_INFO, "param_changed", f"{self.name}: {msg.key} = {value!r}")]
