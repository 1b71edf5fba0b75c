"""A running component's live parameters from Python (``humanpt param`` parses and prints):
read and set them through its params queryable, as TOML, and load a file of them all or
none.

    from humanpt.runtime.params import load_file, query
    body = query(cfg, "controller", {"gain": 0.5})   # None: nobody answered
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

from humanpt.runtime import config as cfgmod


def parse_assignment(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` -> (key, value): VALUE is JSON, a bare word a string."""
    key, eq, value = text.partition("=")
    if not eq or not key:
        raise cfgmod.ConfigError(f"{text!r} is not KEY=VALUE")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def _ask(session, cell: str, component: str, sets: dict, timeout_s: float) -> dict | None:
    from humanpt.runtime.bus import params_key

    replies = list(session.get(params_key(cell, component), payload=json.dumps({"set": sets}), timeout=timeout_s))
    bodies = [json.loads(r.ok.payload.to_bytes()) for r in replies if r.ok is not None]
    return bodies[0] if bodies else None


def query(cfg: cfgmod.ConfigFile, component: str, sets: dict | None = None, timeout_s: float = 5.0) -> dict | None:
    """One request to ``component``'s parameter queryable in ``cfg``'s cell (``sets``
    empty: a read); its reply ({"ok", "results", "params", "counters"}), or None when no
    component answered within ``timeout_s``."""
    from humanpt.runtime.bus import open_tool_session

    with open_tool_session(cfg.runtime) as session:
        return _ask(session, cfg.runtime.cell, component, dict(sets or {}), timeout_s)


def no_answer(cfg: cfgmod.ConfigFile, component: str, timeout_s: float) -> str:
    """Why ``component`` may not have answered (a line)."""
    rt = cfg.runtime
    why = (f"; under mTLS only an operator's certificate may query parameters, this one is "
           f"{rt.identity or 'tool'!r} (--as NAME)" if rt.security == "mtls" else "")
    return (f"no component {component!r} answered in cell {rt.cell} within {timeout_s:g} s "
            f"(is it running?{why})")


def dump_text(cfg: cfgmod.ConfigFile, component: str, params: dict) -> str:
    """The live parameters as TOML: a ``[COMPONENT]`` section, which :func:`load_file` and a
    config file both read."""
    return (f"# live parameters of {component} in cell {cfg.runtime.cell}, {time.strftime('%Y-%m-%d %H:%M:%S')}\n"
            f"# humanpt param load {component} FILE sets them again\n"
            + cfgmod.dumps_toml({component: params or {}}))


def read_file(path: str | Path, component: str) -> dict:
    """KEY -> value of a parameter file: a ``[COMPONENT]`` section (what :func:`dump_text`
    writes) or bare top-level keys; ConfigError naming the file otherwise."""
    doc = cfgmod.read_toml(path, kind="parameter")
    if set(doc) == {component} and isinstance(doc[component], dict):
        return doc[component]
    sections = [k for k, v in doc.items() if isinstance(v, dict)]
    if sections:
        raise cfgmod.ConfigError(f"{path}: has section(s) {', '.join(sections)}; a parameter file for {component} "
                                 f"holds [{component}] only, or bare KEY = VALUE lines")
    return doc


@dataclass
class LoadResult:
    answered: bool  # False: no component answered (nothing set)
    keys: int = 0  # parameters in the file
    results: list[dict] = field(default_factory=list)  # the component's answer per key
    refused: list[dict] = field(default_factory=list)  # the keys it refused (then it was set back)
    restored: bool = True  # after a refusal: the keys it had set were set back
    set_back: list[str] = field(default_factory=list)  # the keys set back (or that could not be)


def load_file(cfg: cfgmod.ConfigFile, component: str, path: str | Path, timeout_s: float = 5.0) -> LoadResult:
    """Set each parameter of file ``path`` on the running ``component``, all or none.

    Checked here first against the component's live parameters and its config type (an
    unknown or non-live key, a value out of range: ConfigError naming the file, nothing
    sent); a key the component itself refuses (a safety limit it may only tighten) rolls
    back the keys it had set, so the component is left as it was."""
    from humanpt.runtime.bus import open_tool_session
    from humanpt.runtime.registry import UnknownComponentError, core_class

    values = read_file(path, component)
    if not values:
        raise cfgmod.ConfigError(f"{path}: no parameters in it")
    try:
        cls = core_class(component).config_type
    except (UnknownComponentError, KeyError) as e:
        raise cfgmod.ConfigError(f"unknown component {component!r}: {e}") from None
    cell = cfg.runtime.cell
    with open_tool_session(cfg.runtime) as session:
        body = _ask(session, cell, component, {}, timeout_s)
        if body is None:
            return LoadResult(answered=False, keys=len(values))
        before = body.get("params") or {}
        unknown = [k for k in values if k not in before]
        if unknown:
            raise cfgmod.ConfigError(f"{path}: {', '.join(map(repr, unknown))} not live parameter(s) of {component}; "
                                     f"live: {', '.join(before)} (nothing set)")
        obj = cfgmod.build(cls, before, source=f"{component}'s live parameters", section=component)
        for k, v in values.items():  # in order, so checks between fields see the new values
            try:
                obj = cfgmod.replace_live(obj, k, json.dumps(v))
            except cfgmod.ConfigError as e:
                raise cfgmod.ConfigError(f"{path}: {e} (nothing set)") from None
        body = _ask(session, cell, component, values, timeout_s)
        if body is None:
            return LoadResult(answered=False, keys=len(values))
        results = body.get("results", [])
        refused = [r for r in results if not r["ok"]]
        if not refused:
            return LoadResult(True, len(values), results)
        done = {r["key"]: before[r["key"]] for r in results if r["ok"]}
        back = _ask(session, cell, component, done, timeout_s) if done else {"ok": True}
        return LoadResult(True, len(values), results, refused, back is not None and back.get("ok", False), list(done))
