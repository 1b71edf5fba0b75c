"""The process supervisor of ``humanpt up``: the router (when the profile has one) and a set
of components, each a child process started by :mod:`humanpt.runtime.launcher`, recording
to one run directory; stopped together, components first.

    from humanpt.runtime.run import load_config
    from humanpt.runtime.supervisor import resolve_profile, up
    cfg = load_config("cell.toml")
    up(cfg, resolve_profile(cfg, "selftest"), "runs/x", duration_s=5)
"""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from humanpt.runtime import config as cfgmod
from humanpt.runtime import launcher
from humanpt.runtime.bus import liveliness_key, open_tool_session
from humanpt.runtime.registry import COMPONENTS, PROFILES, UnknownComponentError

READY_TIMEOUT_S = 120.0  # bounds a hang only: a component that cannot start exits sooner
ROUTER_LISTEN_TIMEOUT_S = 60.0  # likewise (a loaded machine took more than 10 s to start one)


@dataclass(frozen=True)
class Profile:
    """What ``up`` starts: ``label`` names the run directory; ``router``: start one."""

    label: str
    router: bool
    components: tuple[str, ...]


def resolve_profile(cfg: cfgmod.ConfigFile, profile: str | None = None, components: Sequence[str] | None = None,
                    no_router: bool = False) -> Profile:
    """The profile ``up`` runs: ``components`` (a router too) if given, else ``profile`` (the
    config's ``[profiles]`` first, then the built-in ones), else ``loop``; ``no_router``:
    none is started (one runs elsewhere)."""
    if components:
        comps = tuple(cfgmod.current_name(c.strip()) for c in components if c.strip())
        label, with_router = "custom", True
    elif profile:
        if profile in cfg.profiles:
            label, with_router, comps = profile, True, cfg.profiles[profile]
        elif profile in PROFILES:
            prof = PROFILES[profile]
            label, with_router, comps = profile, prof["router"], tuple(prof["components"])
        else:
            raise cfgmod.ConfigError(f"unknown profile {profile!r}; known: "
                                     f"{', '.join(sorted(set(PROFILES) | set(cfg.profiles)))}")
    else:
        prof = PROFILES["loop"]
        label, with_router, comps = "loop", prof["router"], tuple(prof["components"])
    missing = [c for c in comps if c not in COMPONENTS]
    if missing:
        raise UnknownComponentError(f"profile {label!r} needs {', '.join(missing)}, not available in this "
                                    f"version (available: {', '.join(sorted(COMPONENTS))})")
    return Profile(label, with_router and not no_router, comps)


def wait_ready(rt: cfgmod.RuntimeConfig, comps: tuple[str, ...], children: list[tuple[str, subprocess.Popen]],
               stop: threading.Event, timeout_s: float = READY_TIMEOUT_S) -> str:
    """Wait until every component of ``comps`` is up (its liveliness token, which a live
    shell declares last, when it serves), a child died, ``stop`` is set or ``timeout_s``
    passed; watched as a tool (under mTLS the ``tool`` identity, or ``[runtime] identity``).
    Returns a line saying when they were up, or why it could not tell."""
    import zenoh

    t0 = time.monotonic()
    want, alive = set(comps), set()
    changed = threading.Condition()

    def on_token(sample):
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        with changed:
            (alive.add if sample.kind == zenoh.SampleKind.PUT else alive.discard)(name)
            changed.notify_all()

    try:
        session = open_tool_session(rt, patient=True)
    except Exception as e:  # noqa: BLE001 - no router reachable, no tool certificate: say so, run anyway
        return f"cannot watch the components come up ({e}); --duration counts from their start"
    with session:
        sub = session.liveliness().declare_subscriber(liveliness_key(rt.cell, "*"), on_token, history=True)
        try:
            with changed:
                while not want <= alive:
                    if stop.is_set() or any(p.poll() is not None for _, p in children):
                        return "stopped before every component was up"
                    if time.monotonic() - t0 > timeout_s:
                        return (f"not up after {timeout_s:g} s: {', '.join(sorted(want - alive))}; "
                                "--duration counts from now")
                    changed.wait(0.2)
        finally:
            sub.undeclare()
    return f"all {len(want)} components up after {time.monotonic() - t0:.1f} s; --duration counts from now"


@dataclass
class UpResult:
    run_dir: Path
    failed: list[str]  # children that died (or a router that never listened); empty: stopped cleanly

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0


def up(cfg: cfgmod.ConfigFile, profile: Profile, run_dir: str | Path, *, config_file: str | Path | None = None,
       cell: str | None = None, connect: Sequence[str] = (), duration_s: float | None = None,
       stop: threading.Event | None = None, say: Callable[[str], None] = lambda line: None) -> UpResult:
    """Start ``profile`` (the router first, once it listens, then every component recording
    into ``run_dir``), each process with ``config_file`` and the overrides ``cell`` and
    ``connect`` (``cfg``: that file loaded with them), and supervise them until ``stop`` is
    set, ``duration_s`` has passed since every component was up, or a child dies; then stop
    them all, components first.  ``say`` gets the progress lines."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    stop = stop or threading.Event()
    rt = cfg.runtime
    common = dict(config=config_file, cell=cell, connect=tuple(connect))
    children: list[tuple[str, subprocess.Popen]] = []
    failed: list[str] = []
    try:
        if profile.router:
            proc = launcher.spawn(launcher.ROUTER, **common)
            children.append((launcher.ROUTER, proc))
            addr = launcher.endpoint_addr(rt.listen[0])
            if addr and launcher.wait_listening(*addr, ROUTER_LISTEN_TIMEOUT_S, alive=lambda: proc.poll() is None,
                                                stop=stop):
                failed.append("router (did not start listening)")
                return UpResult(run_dir, failed)
        for name in profile.components:
            children.append((name, launcher.spawn(name, run_dir=run_dir, **common)))
        if duration_s:  # seconds of the running cell: counted from when every component is up
            say(wait_ready(rt, profile.components, children, stop))
        deadline = time.monotonic() + duration_s if duration_s else None
        while not stop.wait(0.2):
            if deadline and time.monotonic() >= deadline:
                break
            dead = [(n, p.returncode) for n, p in children if p.poll() is not None]
            if dead:
                failed += [f"{n} (exit {rc})" for n, rc in dead]
                break
    finally:
        launcher.stop_all([p for _, p in children], timeout_s=10, together=False)
    return UpResult(run_dir, failed)
