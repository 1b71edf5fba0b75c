"""Snapshots of a core's state, written into its recording so that a long run can be replayed
from near its end rather than from its start (DESIGN: "State that matters for replay can be
snapshotted into the log").

The shape is copper-rs's ``Freezable``: :meth:`Core.freeze` turns the core's state into a
value, :meth:`Core.thaw` puts it into a fresh core built from the same config and rig.  The
default freezes every attribute of the core (its live config as a table; not its start
config, rig and handlers, which replay rebuilds, nor the attributes the core lists in
``Core.not_frozen``) with :func:`encode`, a restricted JSON encoding of plain data:

* JSON's own values (None, bool, int, float, str; NaN and infinities as Python writes them);
* tagged nodes ``{"<tag>": ...}`` for everything else: bytes, tuples, lists, dicts (any
  hashable key), defaultdicts (factory int, float, list, dict, set or str), deques, sets,
  numpy arrays (``{"a": {"dtype", "shape", "data": base64}}``, numeric dtypes only) and
  scalars, Enum members, protobuf messages (bytes), and objects of classes (``{"o": {"cls":
  <class name>, "attrs": {...}}}``);
* an object met twice is written once and referenced (``{"ref": n}``), so what the core
  shares stays shared; a value that is one of the core's attributes it does not freeze is
  written as ``{"core": <attribute>}`` and thawed as the fresh core's own; a function an object holds
  (filterpy's ``inv``) as ``{"fn": <name>}``, thawed as the fresh core's.

Nothing read from a snapshot is executed or imported (pickle would be): :func:`decode`
builds only the data types above, and objects only of classes the core itself holds when it
is built (found by walking a fresh core) or lists in ``Core.state_types``, named by class
name, created without calling their constructor.  Every value is checked against the fresh
core's value at the same place (same kind, an array's dtype and shape, no unknown and no
missing attribute), arrays against sizes and dtypes, the whole against :data:`MAX_BYTES`
and :data:`MAX_DEPTH`; anything else is a :class:`SnapshotError` of one line naming the
place (``controller._sent[105][0]``) and what is wrong.
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import enum
import inspect
import json
import math
import types
from collections import OrderedDict, defaultdict, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from google.protobuf import message_factory
from google.protobuf.message import DecodeError, Message

FORMAT = "humanpt.snapshot/1"
# The channel of a recording that holds a core's snapshots (direction ``snapshot``, JSON).
TOPIC = "snapshot"
MAX_BYTES = 64 * 2**20  # one snapshot, encoded
MAX_ARRAY_ELEMENTS = 2**24
MAX_DEPTH = 60  # nesting of containers and objects
DTYPES = frozenset({"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                    "float16", "float32", "float64", "complex64", "complex128"})
FACTORIES: dict[str, type] = {"int": int, "float": float, "list": list, "dict": dict, "set": set, "str": str}
_PRIMITIVES = (type(None), bool, int, float, str)


class SnapshotError(ValueError):
    """A state that cannot be frozen, or a snapshot that is refused (one line)."""


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def _is_function(v: Any) -> bool:
    return inspect.isroutine(v) or isinstance(v, type)


def _slot_names(cls: type) -> list[str]:
    names: list[str] = []
    for c in cls.__mro__:
        for s in getattr(c, "__slots__", ()):
            if isinstance(s, str) and s not in ("__dict__", "__weakref__") and s not in names:
                names.append(s)
    return names


def object_attrs(obj: Any) -> dict[str, Any]:
    """The attributes of an object: its ``__dict__`` and its slots that are set."""
    out = dict(getattr(obj, "__dict__", {}))
    for s in _slot_names(type(obj)):
        try:
            out[s] = object.__getattribute__(obj, s)
        except AttributeError:
            pass
    return out


class Encoder:
    """Encode a state; ``shared`` maps id(object) -> the core attribute it is (not frozen:
    written as a reference to the fresh core's)."""

    def __init__(self, shared: dict[int, str] | None = None, skip: frozenset[str] = frozenset()):
        self._shared = dict(shared or {})
        self._skip = skip  # places not frozen (``sim_robot.robot.applied``)
        self._memo: dict[int, int] = {}
        self._keep: list[Any] = []  # what the memo's ids refer to, alive while encoding

    def encode(self, v: Any, where: str = "state", depth: int = 0) -> Any:
        t = type(v)
        if t in _PRIMITIVES:
            return v
        if depth > MAX_DEPTH:
            raise SnapshotError(f"{where}: nested deeper than {MAX_DEPTH}")
        name = self._shared.get(id(v))
        if name is not None:
            return {"core": name}
        n = self._memo.get(id(v))
        if n is not None:
            return {"ref": n}
        if isinstance(v, enum.Enum):
            return {"e": {"cls": t.__qualname__, "v": self.encode(v.value, where, depth + 1)}}
        if isinstance(v, np.generic):
            if t.__name__ not in DTYPES and v.dtype.name not in DTYPES:
                raise SnapshotError(f"{where}: numpy {v.dtype} cannot be frozen")
            return {"n": {"dtype": v.dtype.name, "data": _b64(v.tobytes())}}
        if t is bytes:
            return {"b": _b64(v)}
        if t is tuple:
            return {"t": [self.encode(x, f"{where}[{i}]", depth + 1) for i, x in enumerate(v)]}
        if isinstance(v, Message):
            return {"pb": {"type": v.DESCRIPTOR.full_name, "data": _b64(v.SerializeToString())}}
        if _is_function(v):
            return {"fn": function_name(v)}
        # Mutable (or large): written once, then referenced.
        n = self._memo[id(v)] = len(self._memo)
        self._keep.append(v)
        if t is np.ndarray and v.dtype == object:  # filterpy's z before the first update: Nones
            items = v.ravel().tolist()
            if any(type(x) not in _PRIMITIVES for x in items):
                raise SnapshotError(f"{where}: an array of objects other than numbers and None cannot be frozen")
            node = {"ao": {"shape": list(v.shape), "items": items}}
        elif t is np.ndarray:
            if v.dtype.name not in DTYPES:
                raise SnapshotError(f"{where}: an array of dtype {v.dtype} cannot be frozen")
            node = {"a": {"dtype": v.dtype.name, "shape": list(v.shape), "data": _b64(np.ascontiguousarray(v).tobytes())}}
        elif t is bytearray:
            node = {"ba": _b64(bytes(v))}
        elif t is list:
            node = {"l": [self.encode(x, f"{where}[{i}]", depth + 1) for i, x in enumerate(v)]}
        elif t is dict or t is defaultdict or t is OrderedDict:
            items = [[self.encode(k, f"{where}.<key>", depth + 1), self.encode(x, f"{where}[{k!r}]", depth + 1)]
                     for k, x in v.items()]
            if t is not defaultdict:
                node = {"d" if t is dict else "od": items}
            else:
                factory = next((k for k, f in FACTORIES.items() if f is v.default_factory), None)
                if factory is None:
                    raise SnapshotError(f"{where}: a defaultdict of {v.default_factory!r} cannot be frozen")
                node = {"dd": {"factory": factory, "items": items}}
        elif t is deque:
            node = {"q": {"maxlen": v.maxlen, "items": [self.encode(x, f"{where}[{i}]", depth + 1)
                                                        for i, x in enumerate(v)]}}
        elif t is set or t is frozenset:
            node = {"s" if t is set else "fs": [self.encode(x, f"{where}.<item>", depth + 1) for x in v]}
        elif hasattr(v, "__dict__") or _slot_names(t):
            node = {"o": {"cls": t.__qualname__, "attrs": {
                k: self.encode(x, f"{where}.{k}", depth + 1) for k, x in object_attrs(v).items()
                if f"{where}.{k}" not in self._skip}}}
        else:
            raise SnapshotError(f"{where}: a {t.__module__}.{t.__qualname__} cannot be frozen")
        node["id"] = n
        return node


def function_name(f: Any) -> str:
    """How a snapshot names a function an object holds (``numpy.linalg.inv``)."""
    return f"{getattr(f, '__module__', None) or ''}.{getattr(f, '__qualname__', None) or type(f).__qualname__}"


def _kind(v: Any) -> str:
    """What kind of value ``v`` is, for checking a thawed value against the fresh core's."""
    if isinstance(v, bool | np.bool_):
        return "bool"
    if isinstance(v, enum.Enum):
        return f"enum {type(v).__qualname__}"
    if isinstance(v, int | float | np.integer | np.floating):
        return "number"
    for t in (str, bytes, bytearray, np.ndarray, tuple, list, defaultdict, OrderedDict, dict, deque, set, frozenset):
        if isinstance(v, t):
            return t.__name__
    return type(v).__qualname__


@dataclass
class Held:
    """What a fresh core holds, found by walking it (:func:`held`): the classes of its
    objects and Enums by class name, an instance of each class (the template of an object a
    snapshot adds), and the functions its objects hold, by :func:`function_name`."""

    classes: dict[str, type] = field(default_factory=dict)
    examples: dict[type, Any] = field(default_factory=dict)
    functions: dict[str, Any] = field(default_factory=dict)


def held(root: Any, limit: int = 200_000) -> Held:
    """What ``root`` holds in its attributes and containers, transitively (:class:`Held`)."""
    out = Held()
    seen: set[int] = set()
    stack = [root]
    while stack and len(seen) < limit:
        v = stack.pop()
        if type(v) in _PRIMITIVES or id(v) in seen or isinstance(v, np.ndarray | np.generic | bytes | bytearray):
            continue
        seen.add(id(v))
        if isinstance(v, enum.Enum):
            out.classes.setdefault(type(v).__qualname__, type(v))
        elif isinstance(v, dict):
            stack += list(v.keys()) + list(v.values())
        elif isinstance(v, list | tuple | deque | set | frozenset):
            stack += list(v)
        elif isinstance(v, Message):
            continue
        elif _is_function(v):
            out.functions.setdefault(function_name(v), v)
        elif hasattr(v, "__dict__") or _slot_names(type(v)):
            out.classes.setdefault(type(v).__qualname__, type(v))
            out.examples.setdefault(type(v), v)
            stack += list(object_attrs(v).values())
    return out


_NONE = object()  # no fresh value to check against
_TAGS = frozenset({"ref", "core", "fn", "b", "n", "e", "pb", "t", "a", "ao", "ba", "l", "d", "dd", "od", "q", "s", "fs",
                   "o"})


class Decoder:
    """Decode an encoded state; ``classes``: the classes objects may be built of (by class
    name); ``core``: the fresh core (``{"core": attr}`` and functions come from it)."""

    def __init__(self, known: Held, core: Any, skip: frozenset[str] = frozenset()):
        self._known = known
        self._classes = known.classes
        self._core = core
        self._skip = skip  # places not frozen: the fresh core's value is kept
        self._memo: dict[int, Any] = {}
        self._nodes = 0

    def _cls(self, name: Any, where: str) -> type:
        cls = self._classes.get(name) if isinstance(name, str) else None
        if cls is None:
            raise SnapshotError(f"{where}: class {str(name)[:80]!r} is not one this core holds; nothing named by a "
                                f"snapshot is imported")
        return cls

    def decode(self, node: Any, fresh: Any = _NONE, where: str = "state", depth: int = 0) -> Any:
        self._nodes += 1
        if depth > MAX_DEPTH:
            raise SnapshotError(f"{where}: nested deeper than {MAX_DEPTH}")
        value = self._decode(node, fresh, where, depth)
        if fresh is not _NONE and fresh is not None and value is not None and not _is_function(fresh):
            a, b = _kind(value), _kind(fresh)
            if a != b:
                raise SnapshotError(f"{where}: a {a} where this core holds a {b}")
            if b == "ndarray" and value.dtype != fresh.dtype and fresh.dtype != object:
                raise SnapshotError(f"{where}: an array of {value.dtype} where this core holds {fresh.dtype}")
        return value

    def _decode(self, node: Any, fresh: Any, where: str, depth: int) -> Any:
        if type(node) in _PRIMITIVES:
            return node
        if type(node) is list:
            raise SnapshotError(f"{where}: a bare JSON list (every container is tagged)")
        if type(node) is not dict or not node:
            raise SnapshotError(f"{where}: not a snapshot value")
        keys = set(node) - {"id"}
        if len(keys) != 1:
            raise SnapshotError(f"{where}: a node with keys {sorted(node)[:5]} (one tag expected)")
        tag = keys.pop()
        if tag not in _TAGS:
            raise SnapshotError(f"{where}: unknown tag {tag[:20]!r}")
        body = node[tag]
        if tag == "ref":
            if type(body) is not int or body not in self._memo:
                raise SnapshotError(f"{where}: a reference to {body!r}, which is not an earlier value")
            return self._memo[body]
        if tag == "core":
            if body == "_handlers" or body not in getattr(self._core, "unfrozen_attrs", ()):
                raise SnapshotError(f"{where}: refers to the core's {str(body)[:40]!r}, which is frozen, not kept")
            return getattr(self._core, body)
        if tag == "fn":
            if fresh is not _NONE and _is_function(fresh):
                return fresh
            f = self._known.functions.get(body) if isinstance(body, str) else None
            if f is None or (fresh is not _NONE and fresh is not None):
                raise SnapshotError(f"{where}: a function ({str(body)[:60]}) where this core holds none")
            return f
        if tag == "b":
            return self._bytes(body, where)
        if tag == "n":
            arr = self._array(body, where, scalar=True)
            return arr[()]
        if tag == "e":
            cls = self._cls(body.get("cls") if type(body) is dict else None, where)
            if not issubclass(cls, enum.Enum):
                raise SnapshotError(f"{where}: {cls.__qualname__} is not an enumeration")
            try:
                return cls(self.decode(body.get("v"), _NONE, where, depth + 1))
            except (ValueError, TypeError):
                raise SnapshotError(f"{where}: {str(body.get('v'))[:40]!r} is not a {cls.__qualname__}") from None
        if tag == "pb":
            return self._message(body, fresh, where)
        if tag == "t":
            items = self._list(body, where)
            fresh_items = fresh if isinstance(fresh, tuple) else ()
            return tuple(self.decode(x, fresh_items[i] if i < len(fresh_items) else _NONE, f"{where}[{i}]", depth + 1)
                         for i, x in enumerate(items))
        n = node.get("id")
        if type(n) is not int or n in self._memo:
            raise SnapshotError(f"{where}: a {tag!r} node without a new id")
        if tag == "a":
            v = self._memo[n] = self._array(body, where)
            return v
        if tag == "ao":
            if type(body) is not dict:
                raise SnapshotError(f"{where}: an object array without shape and items")
            shape, items = body.get("shape"), self._list(body.get("items"), where)
            self._shape(shape, where)
            if any(type(x) not in _PRIMITIVES for x in items) or len(items) != math.prod(shape):
                raise SnapshotError(f"{where}: an object array of other than {math.prod(shape)} numbers and Nones")
            arr = np.empty(len(items), dtype=object)
            arr[:] = items
            v = self._memo[n] = arr.reshape(shape)
            return v
        if tag == "ba":
            v = self._memo[n] = bytearray(self._bytes(body, where))
            return v
        if tag == "l":
            out: list = []
            self._memo[n] = out
            fresh_items = fresh if isinstance(fresh, list) else []
            out.extend(self.decode(x, fresh_items[i] if i < len(fresh_items) else _NONE, f"{where}[{i}]", depth + 1)
                       for i, x in enumerate(self._list(body, where)))
            return out
        if tag in ("d", "dd", "od"):
            if tag == "dd":
                if type(body) is not dict or body.get("factory") not in FACTORIES:
                    raise SnapshotError(f"{where}: a defaultdict whose factory is not one of {', '.join(FACTORIES)}")
                out_d: dict = defaultdict(FACTORIES[body["factory"]])
                body = body.get("items")
            else:
                out_d = {} if tag == "d" else OrderedDict()
            self._memo[n] = out_d
            fresh_d = fresh if isinstance(fresh, dict) else {}
            for pair in self._list(body, where):
                if type(pair) is not list or len(pair) != 2:
                    raise SnapshotError(f"{where}: a dict item that is not a [key, value] pair")
                k = self.decode(pair[0], _NONE, f"{where}.<key>", depth + 1)
                try:
                    f = fresh_d.get(k, _NONE)
                    out_d[k] = self.decode(pair[1], f, f"{where}[{k!r}]", depth + 1)
                except TypeError:
                    raise SnapshotError(f"{where}: a key that cannot be a dict key ({type(k).__name__})") from None
            return out_d
        if tag == "q":
            if type(body) is not dict:
                raise SnapshotError(f"{where}: a deque without its items")
            maxlen = body.get("maxlen")
            if maxlen is not None and (type(maxlen) is not int or maxlen < 0):
                raise SnapshotError(f"{where}: a deque whose maxlen is {maxlen!r}")
            if isinstance(fresh, deque) and maxlen != fresh.maxlen:
                raise SnapshotError(f"{where}: a deque of maxlen {maxlen} where this core holds maxlen {fresh.maxlen}")
            q: deque = deque(maxlen=maxlen)
            self._memo[n] = q
            fresh_items = list(fresh) if isinstance(fresh, deque) else []
            q.extend(self.decode(x, fresh_items[i] if i < len(fresh_items) else _NONE, f"{where}[{i}]", depth + 1)
                     for i, x in enumerate(self._list(body.get("items"), where)))
            return q
        if tag in ("s", "fs"):
            try:
                items = [self.decode(x, _NONE, f"{where}.<item>", depth + 1) for x in self._list(body, where)]
                v = self._memo[n] = set(items) if tag == "s" else frozenset(items)
            except TypeError:
                raise SnapshotError(f"{where}: a set of values that cannot be in a set") from None
            return v
        return self._object(n, body, fresh, where, depth)  # "o"

    def _object(self, n: int, body: Any, fresh: Any, where: str, depth: int) -> Any:
        if type(body) is not dict or type(body.get("attrs")) is not dict:
            raise SnapshotError(f"{where}: an object without its attributes")
        cls = self._cls(body.get("cls"), where)
        if issubclass(cls, enum.Enum):
            raise SnapshotError(f"{where}: {cls.__qualname__} is an enumeration, not an object")
        attrs: dict = body["attrs"]
        has_fresh = fresh is not _NONE and type(fresh) is cls
        fresh_attrs = object_attrs(fresh) if has_fresh else {}
        # An object the fresh core holds none of at this place: another of its class that it
        # holds is the template of its attributes' kinds and functions.
        example = {} if has_fresh or cls not in self._known.examples else object_attrs(self._known.examples[cls])
        for k in attrs:
            if type(k) is not str or not k.isidentifier() or k.startswith("__"):
                raise SnapshotError(f"{where}: attribute name {str(k)[:40]!r} refused")
        names = set(attrs)
        if has_fresh:
            expected = set(fresh_attrs)
        elif dataclasses.is_dataclass(cls):
            expected = {f.name for f in dataclasses.fields(cls)}
        else:
            expected = names
        unknown = sorted(names - expected - ({k for k in names if k.startswith("_")} if not has_fresh else set()))
        kept = {k for k in expected - names if has_fresh and f"{where}.{k}" in self._skip}
        missing = sorted(expected - names - kept)
        if unknown:
            raise SnapshotError(f"{where}: unknown field {unknown[0]!r} of {cls.__qualname__}")
        if missing:
            raise SnapshotError(f"{where}: field {missing[0]!r} of {cls.__qualname__} missing")
        obj = object.__new__(cls)
        self._memo[n] = obj
        slots = set(_slot_names(cls))
        for k in kept:
            object.__setattr__(obj, k, fresh_attrs[k])
        owner = fresh if has_fresh else self._known.examples.get(cls)
        for k, x in attrs.items():
            v = self.decode(x, fresh_attrs.get(k, example.get(k, _NONE)), f"{where}.{k}", depth + 1)
            if inspect.ismethod(v) and v.__self__ is owner:  # a method of its own: of the new object now
                v = types.MethodType(v.__func__, obj)
            if k in slots or hasattr(obj, "__dict__"):
                object.__setattr__(obj, k, v)
            else:
                raise SnapshotError(f"{where}: {cls.__qualname__} has no attribute {k!r}")
        return obj

    @staticmethod
    def _list(body: Any, where: str) -> list:
        if type(body) is not list:
            raise SnapshotError(f"{where}: items that are not a list")
        return body

    @staticmethod
    def _bytes(body: Any, where: str) -> bytes:
        if type(body) is not str:
            raise SnapshotError(f"{where}: bytes that are not base64 text")
        try:
            return base64.b64decode(body, validate=True)
        except (binascii.Error, ValueError):
            raise SnapshotError(f"{where}: bytes that are not base64") from None

    @staticmethod
    def _shape(shape: Any, where: str) -> int:
        """The number of elements of an array of ``shape`` (refused beyond the limits)."""
        if type(shape) is not list or len(shape) > 32 or any(type(s) is not int or s < 0 for s in shape):
            raise SnapshotError(f"{where}: shape {str(shape)[:40]} refused")
        count = 1
        for s in shape:
            count *= s
            if count > MAX_ARRAY_ELEMENTS:
                raise SnapshotError(f"{where}: an array of shape {shape} is larger than {MAX_ARRAY_ELEMENTS} elements")
        return count

    def _array(self, body: Any, where: str, scalar: bool = False) -> np.ndarray:
        if type(body) is not dict:
            raise SnapshotError(f"{where}: an array without dtype, shape and data")
        dtype = body.get("dtype")
        if dtype not in DTYPES:
            raise SnapshotError(f"{where}: dtype {str(dtype)[:20]!r} refused (numeric dtypes only)")
        shape = [] if scalar else body.get("shape")
        count = self._shape(shape, where)
        data = self._bytes(body.get("data"), where)
        dt = np.dtype(dtype).newbyteorder("<") if np.dtype(dtype).itemsize > 1 else np.dtype(dtype)
        if len(data) != count * dt.itemsize:
            raise SnapshotError(f"{where}: {len(data)} bytes of data for {count} elements of {dtype}")
        return np.frombuffer(data, dtype=dt).astype(np.dtype(dtype)).reshape(shape).copy()

    def _message(self, body: Any, fresh: Any, where: str) -> Message:
        if type(body) is not dict or type(body.get("type")) is not str:
            raise SnapshotError(f"{where}: a message without its type")
        name = body["type"]
        if not (name.startswith("humanpt.") or name.startswith("foxglove.")):
            raise SnapshotError(f"{where}: message type {name[:60]!r} is not one of humanpt's schemas")
        from humanpt.schemas import humanpt_pb2

        try:
            desc = humanpt_pb2.DESCRIPTOR.pool.FindMessageTypeByName(name)
        except KeyError:
            raise SnapshotError(f"{where}: message type {name[:60]!r} unknown") from None
        msg = message_factory.GetMessageClass(desc)()
        try:
            msg.ParseFromString(self._bytes(body.get("data"), where))
        except DecodeError as e:
            raise SnapshotError(f"{where}: a {name} that does not decode ({e})") from None
        return msg


def dumps(value: Any) -> bytes:
    """A snapshot value as JSON bytes."""
    return json.dumps(value, separators=(",", ":"), allow_nan=True).encode()


def loads(data: bytes, what: str = "snapshot") -> dict[str, Any]:
    """JSON bytes of a snapshot as a table (SnapshotError, one line, if not)."""
    if len(data) > MAX_BYTES:
        raise SnapshotError(f"{what}: {len(data)} bytes, more than the {MAX_BYTES} a snapshot may hold")
    try:
        value = json.loads(data)
    except RecursionError:
        raise SnapshotError(f"{what}: nested too deeply to be read") from None
    except ValueError as e:
        raise SnapshotError(f"{what}: not JSON ({str(e)[:80]})") from None
    if type(value) is not dict:
        raise SnapshotError(f"{what}: a JSON {type(value).__name__}, not a table")
    return value


def snapshot_bytes(core: Any, t_ns: int, inputs: int) -> bytes:
    """What a shell records: ``core``'s state (:meth:`Core.freeze`) after its ``inputs``-th
    input, given at ``t_ns``, with what replay checks it against."""
    return dumps({"format": FORMAT, "component": core.name, "t_ns": int(t_ns), "inputs": int(inputs),
                  "core": core.freeze()})


def parse_snapshot(data: bytes, what: str = "snapshot") -> dict[str, Any]:
    """A recorded snapshot's table, its header checked (SnapshotError, one line)."""
    table = loads(data, what)
    if table.get("format") != FORMAT:
        raise SnapshotError(f"{what}: format {str(table.get('format'))[:40]!r}, this version reads {FORMAT!r}")
    for key in ("t_ns", "inputs"):
        if type(table.get(key)) is not int or table[key] < 0:
            raise SnapshotError(f"{what}: {key} {str(table.get(key))[:40]!r} is not a count")
    unknown = sorted(set(table) - {"format", "component", "t_ns", "inputs", "core"})
    if unknown:
        raise SnapshotError(f"{what}: unknown field {unknown[0][:40]!r}")
    return table


class Snapshotter:
    """When a shell freezes its core: after the first input at or past each period of input
    time (``period_s``; 0: never).  :meth:`after_input` counts the inputs and returns the
    snapshot's bytes when one is due.  A state that cannot be frozen never stops the core:
    the first failure is kept in :attr:`error` (for the shell to report) and snapshots stop."""

    def __init__(self, period_s: float):
        self.period_ns = round(period_s * 1e9)
        self.inputs = 0
        self.written = 0
        self.bytes = 0
        self.error: str | None = None
        self._due: int | None = None
        self._told = False

    def after_input(self, core: Any, t_ns: int) -> bytes | None:
        self.inputs += 1
        if self.period_ns <= 0 or self.error is not None:
            return None
        if self._due is None:
            self._due = t_ns + self.period_ns
        if t_ns < self._due:
            return None
        self._due += ((t_ns - self._due) // self.period_ns + 1) * self.period_ns
        try:
            data = snapshot_bytes(core, t_ns, self.inputs)
        except Exception as e:  # noqa: BLE001 - a snapshot must never stop a core
            self.error = f"{core.name}: snapshots stopped: {type(e).__name__}: {e}"
            return None
        self.written += 1
        self.bytes += len(data)
        return data

    def news(self) -> bool:
        """Whether snapshots stopped (:attr:`error`) and nobody was told yet (True once)."""
        if self.error is None or self._told:
            return False
        self._told = True
        return True
