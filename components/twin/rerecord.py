"""Re-record the reference runs live, show what changed, replace them (``humanpt runs
rerecord`` parses its arguments and calls :func:`rerecord`).

The reference runs are listed in ``recordings/runs.toml`` (scenario, twin seconds, seed,
``--set`` overrides).  Each is recorded LIVE as ``humanpt demo`` records it
(:func:`humanpt.twin.demo.run_live_demo`: router, sim_robot behind a pty, robot_gateway,
sim_camera, perception, pose_filter, controller and operator as processes over Zenoh) into a
temporary directory.  Then, per run:

1. every new component recording must replay exactly, byte for byte (else nothing is
   replaced);
2. *this build on the old run's inputs*: each component of the old reference run is
   replayed with this build and compared with what it recorded, messages paired by step:
   identical, within the golden test's tolerances (``golden.TOLERANCES``; the largest
   difference per field is shown) or CHANGED.  Free of live timing: it is what the change
   does to each component;
3. *the new live run against the old*: each component's outputs, paired in order per
   topic, stamps relative to each recording's start.  Live runs differ in timing from run
   to run, so expect differences here even without a change; look at their size.

Unless ``--dry-run``, the new runs then replace the old ones in ``recordings/``, each with
``reference.json`` (command, config, seed, version, date, size), and the table in
``recordings/README.md`` is rewritten.  A dry run leaves ``recordings/`` alone and keeps the
new runs where it says.
"""

from __future__ import annotations

import datetime
import json
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import humanpt
from humanpt.runtime.recording import RecordingError, read
from humanpt.runtime.replay import build_core
from humanpt.schemas import topics
from humanpt.testing import golden

REPO_ROOT = Path(humanpt.__file__).resolve().parents[1]
SPEC_FILE = "runs.toml"
README_BEGIN = "<!-- reference-runs:begin (written by humanpt runs rerecord) -->"
README_END = "<!-- reference-runs:end -->"
# What a reference run keeps of the demo's run directory.
KEEP = ("*.mcap", "humanpt.toml", "rig.toml", "world.toml", "processes.log", "demo.txt", "paths/*.csv")
_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]*$")


def default_root() -> Path:
    """``recordings/`` of the source tree humanpt runs from, else of the working directory."""
    root = REPO_ROOT / "recordings"
    return root if (root / SPEC_FILE).is_file() else Path("recordings")


@dataclass(frozen=True)
class ReferenceRun:
    """One reference run: ``humanpt demo --scenario S --duration D --seed N --set ...``."""

    name: str
    scenario: str
    duration_s: float
    seed: int = 0
    overrides: tuple[str, ...] = ()  # --set SECTION.KEY=VALUE items
    link: str = "alter"  # the robot link (demo --link): alter or rsi
    cycle_ms: float | None = None  # with link rsi: 4 or 12 (demo --cycle-ms)

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(
                f"reference run name {self.name!r}: lower-case letters, digits, - and _ only"
            )
        if not isinstance(self.scenario, str) or not self.scenario:
            raise ValueError(f"reference run {self.name}: scenario must be a scenario name or file")
        if not (isinstance(self.duration_s, (int, float)) and 0 < self.duration_s <= 60):
            raise ValueError(
                f"reference run {self.name}: duration_s must be in (0, 60] s (keep them short), "
                f"got {self.duration_s!r}"
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(
                f"reference run {self.name}: seed must be an integer >= 0, got {self.seed!r}"
            )
        if self.link not in ("alter", "rsi"):
            raise ValueError(f"reference run {self.name}: link must be alter or rsi, got {self.link!r}")
        if self.cycle_ms is not None and (self.link != "rsi" or self.cycle_ms not in (4, 12)):
            raise ValueError(f"reference run {self.name}: cycle_ms is RSI's 4 or 12 (with link = \"rsi\"), "
                             f"got {self.cycle_ms!r}")
        for o in self.overrides:
            if not isinstance(o, str) or "=" not in o or "." not in o.partition("=")[0]:
                raise ValueError(
                    f"reference run {self.name}: override {o!r} is not SECTION.KEY=VALUE"
                )

    def demo_args(self, run_dir: str | Path) -> list[str]:
        """Arguments of ``humanpt`` that record this run into ``run_dir``."""
        args = [
            "demo",
            "--scenario",
            self.scenario,
            "--duration",
            f"{self.duration_s:g}",
            "--seed",
            str(self.seed),
        ]
        if self.link != "alter":
            args += ["--link", self.link]
        if self.cycle_ms is not None:
            args += ["--cycle-ms", f"{self.cycle_ms:g}"]
        for o in self.overrides:
            args += ["--set", o]
        return args + ["--run-dir", str(run_dir)]

    def command(self, run_dir: str = "DIR") -> str:
        return "humanpt " + " ".join(_quote(a) for a in self.demo_args(run_dir))


def _quote(a: str) -> str:
    return a if re.match(r"^[\w.,:/=+-]+$", a) else "'" + a.replace("'", "'\\''") + "'"


def load_specs(path: str | Path) -> list[ReferenceRun]:
    """The reference runs of ``runs.toml``: a top-level ``set`` (overrides common to every
    run) and one ``[runs.<name>]`` table each (``scenario``, ``duration_s``, ``seed``,
    ``set``)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except OSError as e:
        raise golden.GoldenError(f"{p}: cannot read the reference run list: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise golden.GoldenError(f"{p}: not valid TOML: {e}") from None
    unknown = set(data) - {"set", "runs"}
    if unknown:
        raise golden.GoldenError(f"{p}: unknown key {sorted(unknown)[0]!r} (set, [runs.<name>])")
    common = tuple(data.get("set", ()))
    specs = []
    for name, t in data.get("runs", {}).items():
        bad = set(t) - {"scenario", "duration_s", "seed", "set", "link", "cycle_ms"}
        if bad:
            raise golden.GoldenError(
                f"{p}: [runs.{name}] unknown key {sorted(bad)[0]!r} "
                "(scenario, duration_s, seed, set, link, cycle_ms)"
            )
        try:
            specs.append(
                ReferenceRun(
                    name,
                    t.get("scenario", ""),
                    t.get("duration_s", 0),
                    t.get("seed", 0),
                    common + tuple(t.get("set", ())),
                    t.get("link", "alter"),
                    t.get("cycle_ms"),
                )
            )
        except (ValueError, TypeError) as e:
            raise golden.GoldenError(f"{p}: {e}") from None
    if not specs:
        raise golden.GoldenError(f"{p}: no [runs.<name>] tables")
    return specs


# -- provenance ------------------------------------------------------------------------------
def source_version() -> dict[str, str]:
    """humanpt and schema versions, and the git commit of the source tree (``+dirty`` when
    components/ or schemas/ have uncommitted changes)."""
    out = {
        "humanpt": humanpt.__version__,
        "schema_version": str(topics.SCHEMA_VERSION),
        "git": "unknown",
    }
    try:
        rev = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        if rev.returncode == 0:
            dirty = subprocess.run(
                [
                    "git",
                    "-C",
                    str(REPO_ROOT),
                    "status",
                    "--porcelain",
                    "--untracked-files=no",
                    "--",
                    "components",
                    "schemas",
                ],
                capture_output=True,
                text=True,
                timeout=10,
            )
            changed = [line[3:] for line in dirty.stdout.splitlines() if line.strip()]
            out["git"] = rev.stdout.strip() + ("+dirty" if changed else "")
            if changed:  # which uncommitted files the run was recorded with
                out["uncommitted"] = ", ".join(changed)
    except (OSError, subprocess.SubprocessError):
        pass
    return out


def run_size(run_dir: Path) -> int:
    return sum(p.stat().st_size for p in run_dir.rglob("*") if p.is_file())


# -- recording -------------------------------------------------------------------------------
def record_live(spec: ReferenceRun, run_dir: Path, timeout_s: float) -> tuple[bool, str]:
    """Record ``spec`` live as ``humanpt demo`` does into ``run_dir``, its report in
    ``demo.txt``; (ok, what went wrong).  ``timeout_s`` bounds the run: past it, it is
    stopped and counted as failed."""
    from .demo import demo_config, header_lines, parse_overrides, run_live_demo, write_world

    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        over = parse_overrides(spec.overrides)
        cfg = demo_config(spec.scenario, spec.seed, over)
    except ValueError as e:  # ConfigError, OverrideError too
        return False, f"{spec.command(str(run_dir))}: {e}"
    write_world(run_dir, cfg, "ideal")
    stop = threading.Event()
    timer = threading.Timer(timeout_s, stop.set)
    timer.daemon = True
    timer.start()
    try:
        res, text = run_live_demo(cfg, run_dir, duration_s=spec.duration_s, overrides=over, stop=stop,
                                  link=spec.link, cycle_ms=spec.cycle_ms)
    finally:
        timer.cancel()
    (run_dir / "demo.txt").write_text("\n".join([*header_lines(cfg, spec.scenario, run_dir, False, None), text, ""]))
    if res.failed:
        return False, f"the live run failed: {'; '.join(res.failed)} (see {run_dir / 'processes.log'})"
    if stop.is_set():
        return False, f"the live run did not finish within {timeout_s:.0f} s"
    return True, ""


Recorder = Callable[[ReferenceRun, Path, float], tuple[bool, str]]


def keep_files(src: Path, dst: Path) -> None:
    """Copy what a reference run keeps (``KEEP``) of a demo run directory."""
    dst.mkdir(parents=True, exist_ok=True)
    for pattern in KEEP:
        for f in src.glob(pattern):
            if f.is_file():
                (dst / f.relative_to(src)).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(f, dst / f.relative_to(src))


# -- comparing -------------------------------------------------------------------------------
@dataclass
class RunReport:
    """What rerecording one run found."""

    spec: ReferenceRun
    lines: list[str] = field(default_factory=list)
    ok: bool = True  # the new run was recorded and replays exactly
    changed: bool = False  # this build changes a component's outputs on the old inputs


def _outputs(path: Path) -> golden.Stream:
    return [(e.t_ns, e.topic, e.data) for e in read(path).outputs]


def accuracy_lines(demo_txt: Path) -> list[str]:
    """The accuracy lines of a run's ``humanpt demo`` report (``demo.txt``), if any."""
    try:
        text = demo_txt.read_text()
    except OSError:
        return []
    keep = ("recorded path", "x ", "ME ", "MAE ", "MaxE ", "SD ", "servo error")
    return [line.rstrip() for line in text.splitlines() if line.strip().startswith(keep)]


def compare_run(
    spec: ReferenceRun,
    old_dir: Path | None,
    new_dir: Path,
    max_fields: int,
    core_factory: golden.CoreFactory = build_core,
) -> RunReport:
    """Check the new run, and compare it (and this build, cores made by ``core_factory``)
    with the old one."""
    rep = RunReport(spec)
    out = rep.lines
    new_files = {p.stem: p for p in sorted(new_dir.glob("*.mcap"))}
    old_files = (
        {p.stem: p for p in sorted(old_dir.glob("*.mcap"))} if old_dir and old_dir.is_dir() else {}
    )
    bad = []
    for name, p in new_files.items():
        # Recorded and replayed by this build: run == replay, byte for byte.
        r = golden.check_component(golden.ReferenceFile(spec.name, name, p), exact=True)
        if not r.ok:
            bad.append(r.message)
    if not new_files:
        bad.append(f"{new_dir}: no component recordings")
    if bad:
        rep.ok = False
        out.append("  the NEW recording does not replay exactly; it cannot become a reference run:")
        out += ["    " + line for m in bad for line in m.splitlines()]
        return rep
    if not old_files:
        out.append("  a new reference run (there was none before)")
        return rep

    out.append(
        "  this build on the old run's inputs (identical, within tolerance or CHANGED: what the change does to each component):"
    )
    for name, p in old_files.items():
        try:
            _, recorded, replayed = golden.replay_streams(p, core_factory)
        except (RecordingError, ValueError) as e:
            rep.changed = True
            out.append(f"    {name}: the old recording cannot be replayed: {e}")
            continue
        diff = golden.compare_streams(recorded, replayed, pairing="step")
        if diff.identical:
            out.append(f"    {name}: identical ({len(recorded)} outputs)")
        elif diff.within_tolerance:
            # What the golden test accepts (golden.TOLERANCES): shown, not a change.
            out.append(f"    {name}: within tolerance ({len(recorded)} outputs; recorded -> this build):")
            out.append(diff.describe(max_fields, indent="      ", only_changes=True))
        else:
            rep.changed = True
            out.append(f"    {name}: CHANGED (recorded -> this build):")
            out.append(diff.describe(max_fields, indent="      ", only_changes=True))

    acc_old, acc_new = accuracy_lines(old_dir / "demo.txt"), accuracy_lines(new_dir / "demo.txt")
    if acc_old or acc_new:
        out.append("  accuracy against ground truth (humanpt demo's report), old run then new run:")
        for label, acc in (("old", acc_old), ("new", acc_new)):
            out += [f"    {label}: {line}" for line in acc] or [f"    {label}: (no report)"]

    out.append(
        "  the new live run against the old (outputs paired in order per topic, stamps relative to "
        "each recording's start; live timing varies from run to run):"
    )
    for name in sorted(set(old_files) | set(new_files)):
        if name not in new_files:
            out.append(f"    {name}: no longer recorded")
            continue
        if name not in old_files:
            out.append(f"    {name}: newly recorded ({len(_outputs(new_files[name]))} outputs)")
            continue
        try:
            a = _outputs(old_files[name])
        except RecordingError as e:
            out.append(f"    {name}: the old recording cannot be read: {e}")
            continue
        diff = golden.compare_streams(
            a, _outputs(new_files[name]), pairing="order", relative_stamps=True
        )
        out.append(f"    {name}:")
        out.append(diff.describe(max_fields, indent="      "))
    return rep


# -- replacing -------------------------------------------------------------------------------
def write_reference(
    spec: ReferenceRun, run_dir: Path, version: dict[str, str], recorded_at: str
) -> dict:
    """``<run>/reference.json``: how the run was made."""
    info = {
        "name": spec.name,
        "command": spec.command(f"recordings/{spec.name}"),
        "made_by": f"humanpt runs rerecord --only {spec.name}",
        "scenario": spec.scenario,
        "duration_s": spec.duration_s,
        "seed": spec.seed,
        "overrides": list(spec.overrides),
        "config": f"{spec.name}/humanpt.toml",
        "version": version,
        "recorded_at": recorded_at,
        "live": True,
    }
    (run_dir / "reference.json").write_text(json.dumps(info, indent=2) + "\n")
    return info


def readme_table(root: Path) -> str:
    """The table of reference runs for ``recordings/README.md`` (from each reference.json)."""
    rows = [
        "| run | how it was made | seed | version | recorded (UTC) | size |",
        "|---|---|---|---|---|---|",
    ]
    total = 0
    for ref in sorted(root.glob("*/reference.json")):
        info = json.loads(ref.read_text())
        v = info.get("version", {})
        size = run_size(ref.parent)
        total += size
        rows.append(
            f"| `{info['name']}` | `{info['command']}` (config: `{info['config']}`) | {info['seed']} | "
            f"humanpt {v.get('humanpt', '?')}, git {v.get('git', '?')}, schema {v.get('schema_version', '?')}"
            f" | {info['recorded_at']} | {size / 1e6:.2f} MB |"
        )
    rows.append(f"| | | | | total | {total / 1e6:.2f} MB |")
    return "\n".join(rows)


def update_readme(root: Path) -> None:
    """Rewrite the generated table between the markers of ``recordings/README.md``."""
    readme = root / "README.md"
    text = readme.read_text() if readme.is_file() else "# recordings/\n"
    block = f"{README_BEGIN}\n{readme_table(root)}\n{README_END}"
    if README_BEGIN in text and README_END in text:
        head, rest = text.split(README_BEGIN, 1)
        text = head + block + rest.split(README_END, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    readme.write_text(text)


def replace_run(
    spec: ReferenceRun, new_dir: Path, root: Path, version: dict[str, str], recorded_at: str
) -> None:
    """Put the new run in ``root/<name>`` (the old one goes only once the new one is in place)."""
    dst = root / spec.name
    staging = root / f".{spec.name}.new"
    if staging.exists():
        shutil.rmtree(staging)
    keep_files(new_dir, staging)
    write_reference(spec, staging, version, recorded_at)
    old = root / f".{spec.name}.old"
    if old.exists():
        shutil.rmtree(old)
    if dst.exists():
        dst.rename(old)
    staging.rename(dst)
    if old.exists():
        shutil.rmtree(old)


# -- the whole job ----------------------------------------------------------------------------
def _stdout(line: str) -> None:
    print(line, flush=True)


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def rerecord(root: str | Path | None = None, *, only: list[str] | None = None, dry_run: bool = False,
             out: str | Path | None = None, fields: int = 6, timeout_s: float = 180.0,
             recorder: Recorder = record_live, say: Callable[[str], None] = _stdout,
             complain: Callable[[str], None] = _stderr) -> int:
    """Record every reference run of ``root`` (default :func:`default_root`; ``only`` those
    named) live into ``out`` (default a temporary directory), each allowed its twin time plus
    ``timeout_s``; compare (``fields`` shown per changed topic, -1 all) and, unless
    ``dry_run`` or a run failed, replace the reference runs and the README's table.  ``say``
    gets the report, ``complain`` the failures.  0, 1 when a run failed (nothing replaced), 2
    for an unknown name in ``only``."""
    root = Path(root) if root else default_root()
    specs = load_specs(root / SPEC_FILE)
    if only:
        names = {s.name for s in specs}
        unknown = [n for n in only if n not in names]
        if unknown:
            complain(
                f"humanpt runs rerecord: no reference run {unknown[0]!r} in {root / SPEC_FILE} "
                f"(known: {', '.join(sorted(names))})"
            )
            return 2
        specs = [s for s in specs if s.name in only]
    listed = {s.name for s in load_specs(root / SPEC_FILE)}
    strays = sorted(
        d.name
        for d in root.iterdir()
        if d.is_dir() and not d.name.startswith(".") and d.name not in listed
    )
    out_dir = Path(out) if out else Path(tempfile.mkdtemp(prefix="humanpt-rerecord-"))
    version = source_version()
    say(
        f"humanpt runs rerecord: {len(specs)} reference run(s) of {root}, recorded live "
        f"(humanpt {version['humanpt']}, git {version['git']}, schema {version['schema_version']}); "
        f"new runs in {out_dir}"
    )
    reports: list[RunReport] = []
    recorded_at = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M")
    for spec in specs:
        new_dir = out_dir / spec.name
        if new_dir.exists():
            shutil.rmtree(new_dir)
        say(f"\n== {spec.name}: {spec.command(str(new_dir))}")
        t0 = time.perf_counter()
        ok, why = recorder(spec, new_dir, spec.duration_s + timeout_s)
        if not ok:
            rep = RunReport(spec, [f"  recording FAILED: {why}"], ok=False)
        else:
            rep = compare_run(spec, root / spec.name, new_dir, fields)
            old_size = run_size(root / spec.name) if (root / spec.name).is_dir() else 0
            rep.lines.insert(
                0,
                f"  recorded in {time.perf_counter() - t0:.1f} s: {run_size(new_dir) / 1e6:.2f} MB "
                f"(the old run: {old_size / 1e6:.2f} MB)",
            )
        say("\n".join(rep.lines))
        reports.append(rep)
    failed = [r.spec.name for r in reports if not r.ok]
    changed = [r.spec.name for r in reports if r.changed]
    say("")
    if strays:
        say(
            f"not in {SPEC_FILE}, left as they are (the golden test still replays them): {', '.join(strays)}"
        )
    say(f"this build changes component outputs in: {', '.join(changed) if changed else 'none'}")
    if failed:
        complain(
            f"humanpt runs rerecord: FAILED for {', '.join(failed)}: recordings/ is unchanged "
            f"(new runs kept in {out_dir})"
        )
        return 1
    if dry_run:
        say(f"dry run: {root} is unchanged; the new runs are in {out_dir}")
        return 0
    for spec in specs:
        replace_run(spec, out_dir / spec.name, root, version, recorded_at)
    update_readme(root)
    if not out:
        shutil.rmtree(out_dir, ignore_errors=True)
    say(
        f"replaced {', '.join(f'{root}/{s.name}' for s in specs)}; {root / 'README.md'} updated "
        f"(all reference runs: {sum(run_size(d) for d in root.iterdir() if d.is_dir()) / 1e6:.2f} MB). "
        "Review with git diff --stat, then commit recordings/."
    )
    return 0
