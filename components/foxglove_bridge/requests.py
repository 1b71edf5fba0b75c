"""What a Foxglove client may ask, checked before anything reaches the bus (pure: no I/O).

Parameters are the paper's GUI options (Figure 5) as the owning components' live parameters,
named ``component.key`` (``perception.threshold``), as ``humanpt console set`` and ``humanpt
param`` name them; the robot gateway's limits are shown read-only.  A change is then sent to
the component's params queryable, whose checks (types, ranges, hard limits) decide, as for
``humanpt param``.  Services are the console's verbs (:data:`SERVICES`); a request is a JSON
object, checked here field by field; the component's answering event decides the rest, as
for ``humanpt console``.  Anything refused raises :class:`RequestError` with one line saying
why: the server sends it to the client as the error reply.
"""

from __future__ import annotations

import hmac
import json
import math
from dataclasses import dataclass, field

from humanpt.console.client import OPTIONS

__all__ = ["RequestError", "Param", "PARAMETERS", "Service", "SERVICES", "typed_value", "service_command",
           "param_table", "OPERATOR_FIELDS"]


class RequestError(ValueError):
    """A client's request that is refused: the message is the reply."""


@dataclass(frozen=True)
class Param:
    name: str  # "component.key"
    component: str
    key: str
    writable: bool
    integer: bool = False  # whole numbers (a Foxglove client may send 10.0 for 10)
    doc: str = ""


def _gui() -> list[Param]:
    integers = {"recording_delay_cycles", "calibration_samples", "mask"}
    rows = [(c, k, d) for c, k, d in OPTIONS.values()]  # the console's GUI options
    rows += [("perception", "mask", "rectangles [u, v, width, height] (px) left out of the search"),
             ("controller", "playback_speed_mm_s", "tool speed along a played-back path, mm/s")]
    return [Param(f"{c}.{k}", c, k, True, k in integers, d) for c, k, d in rows]


# The gateway's limits: shown, never set from a browser (they may only become stricter, with
# `humanpt param robot_gateway KEY=VALUE` from an operator's console).
_LIMITS = ("max_speed_mm_s", "max_angular_speed_deg_s", "envelope_min_mm", "envelope_max_mm", "stale_cycles",
           "fault_after_missed")
PARAMETERS: dict[str, Param] = {p.name: p for p in _gui() + [
    Param(f"robot_gateway.{k}", "robot_gateway", k, False, doc="the robot gateway's limit (read-only)")
    for k in _LIMITS]}


def param_table(replies: dict[str, dict]) -> dict[str, object]:
    """Parameter name -> value, from components' live parameters ({component: params})."""
    out = {}
    for p in PARAMETERS.values():
        params = replies.get(p.component) or {}
        if p.key in params:
            out[p.name] = params[p.key]
    return out


def _whole(value, where: str):
    """``value`` with whole floats made ints (nested lists too); RequestError for a fraction."""
    if isinstance(value, list):
        return [_whole(v, where) for v in value]
    if isinstance(value, float):
        if not math.isfinite(value) or not value.is_integer():
            raise RequestError(f"{where}: expected whole numbers, got {value!r}")
        return int(value)
    return value


def typed_value(name: str, value) -> tuple[Param, object]:
    """The parameter ``name`` and ``value`` as its component takes it; RequestError for an
    unknown or read-only parameter, or no value."""
    p = PARAMETERS.get(name)
    if p is None:
        raise RequestError(f"unknown parameter {str(name)[:100]!r}; parameters: {', '.join(PARAMETERS)}")
    if not p.writable:
        raise RequestError(f"{name} is read-only here: the robot gateway's limits may only become stricter, with "
                           f"`humanpt param robot_gateway {p.key}=VALUE` from an operator's console")
    if value is None:
        raise RequestError(f"{name}: no value given")
    if isinstance(value, (bytes, dict)):
        raise RequestError(f"{name}: expected {'whole numbers' if p.integer else 'a value'}, got {type(value).__name__}")
    return p, (_whole(value, name) if p.integer else value)


# -- services ----------------------------------------------------------------------------------
# A request field: (JSON type, required).  "number" takes ints and finite floats, "integer"
# whole numbers, "point" three finite numbers.
OPERATOR_FIELDS = {"operator": ("string", True), "token": ("string", True)}


@dataclass(frozen=True)
class Service:
    name: str
    component: str
    verb: str
    doc: str
    fields: dict[str, tuple[str, bool]] = field(default_factory=dict)
    operator: bool = False  # needs the operator's name and token

    def schema(self) -> dict:
        """The request's JSON schema (what Foxglove's Service Call panel shows)."""
        kinds = {"string": {"type": "string"}, "boolean": {"type": "boolean"}, "number": {"type": "number"},
                 "integer": {"type": "integer"}, "point": {"type": "array", "items": {"type": "number"},
                                                           "minItems": 3, "maxItems": 3}}
        return {"title": self.name, "description": self.doc, "type": "object",
                "properties": {k: kinds[t] for k, (t, _) in self.fields.items()},
                "required": [k for k, (_, req) in self.fields.items() if req], "additionalProperties": False}


SERVICES: dict[str, Service] = {s.name: s for s in (
    Service("track", "controller", "track", "track the target (the servo follows it)"),
    Service("hold", "controller", "hold", "stop on the current location"),
    Service("return", "controller", "return", "return to the start"),
    Service("record_start", "controller", "record_start", "start recording the path"),
    Service("record_stop", "controller", "record_stop", "stop recording the path"),
    Service("save", "controller", "save", "save the path as paths/FILE.csv on the controller's machine "
            "(a plain name; overwrite: replace an existing file)", {"file": ("string", True),
                                                                    "overwrite": ("boolean", False)}),
    Service("calibrate_tip", "controller", "calibrate", "driver-tip calibration (§4.1) from N samples; with "
            "pivot_mm (P', mm) also eq. 12-13", {"samples": ("integer", False), "pivot_mm": ("point", False)}),
    Service("playback", "controller", "playback", "the tool follows the recorded path (speed_mm_s: the tool's "
            "speed, default the controller's playback_speed_mm_s)", {"speed_mm_s": ("number", False)}),
    Service("playback_pause", "controller", "playback_pause", "pause the playback"),
    Service("playback_resume", "controller", "playback_resume", "resume the playback"),
    Service("reset_fault", "robot_gateway", "reset_fault", "clear the robot gateway's fault (the operator: "
            "name and token)", dict(OPERATOR_FIELDS), operator=True),
    Service("alter_on", "sim_robot", "alter_on", "robot link (ALTER) on (the operator: name and token)",
            dict(OPERATOR_FIELDS), operator=True),
    Service("alter_off", "sim_robot", "alter_off", "robot link (ALTER) off (the operator: name and token)",
            dict(OPERATOR_FIELDS), operator=True),
)}


def _check(kind: str, value, where: str):
    if kind == "string":
        ok = isinstance(value, str) and 0 < len(value) <= 200 and value.isprintable()
        what = "a non-empty printable string of at most 200 characters"
    elif kind == "boolean":
        ok, what = isinstance(value, bool), "true or false"
    elif kind == "integer":
        ok = (isinstance(value, int) and not isinstance(value, bool)) or (
            isinstance(value, float) and math.isfinite(value) and value.is_integer())
        what = "a whole number"
        value = int(value) if ok else value
    elif kind == "number":
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        what = "a finite number"
    else:  # point
        ok = (isinstance(value, list) and len(value) == 3 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))
        what = "three finite numbers [x, y, z] (mm)"
    if not ok:
        raise RequestError(f"{where}: expected {what}, got {json.dumps(value)[:60]}")
    return value


def service_command(name: str, payload: bytes, token: str | None, client: str) -> tuple[str, str, dict]:
    """(component, verb, arguments) of a call of service ``name`` with JSON ``payload``, by
    Foxglove client ``client``; RequestError (one line) for an unknown service, a malformed
    request, a field that is unknown or of the wrong type, or an operator's service without
    the operator's name and token (``token`` None: this bridge grants no operator rights)."""
    svc = SERVICES.get(name)
    if svc is None:
        raise RequestError(f"unknown service {str(name)[:100]!r}; services: {', '.join(SERVICES)}")
    try:
        body = json.loads(payload.decode("utf-8")) if payload.strip() else {}
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise RequestError(f"{name}: the request is not JSON ({str(e)[:80]})") from None
    if svc.operator and token is None:
        raise RequestError(f"{name} refused: it needs the operator, and this bridge grants no operator rights "
                           "([foxglove_bridge] operator_token_file is not set)")
    if not isinstance(body, dict):
        raise RequestError(f"{name}: the request must be a JSON object, got {type(body).__name__}")
    unknown = sorted(set(body) - set(svc.fields))
    if unknown:
        raise RequestError(f"{name}: unknown field {unknown[0][:60]!r}; fields: {', '.join(svc.fields) or 'none'}")
    args = {}
    for key, (kind, required) in svc.fields.items():
        if key not in body:
            if required:
                raise RequestError(f"{name}: {key!r} missing" + (
                    " (the operator's name and token: this service needs the operator)" if svc.operator else ""))
            continue
        args[key] = _check(kind, body[key], f"{name}.{key}")
    if svc.operator:
        if not hmac.compare_digest(args.pop("token").encode(), token.encode()):
            raise RequestError(f"{name} refused: the operator's token is wrong")
        args["operator"] = f"{args['operator']} (foxglove client {client})"
    return svc.component, svc.verb, args
