"""Issue 30 item 4: the CLI parses and prints; the work lives in API modules that take typed
arguments, and one launcher starts every component process."""

from __future__ import annotations

import ast
import json
import statistics
import subprocess
import sys

import pytest

from tests.conftest import ROOT

COMPONENTS = ROOT / "components"
CLI = COMPONENTS / "cli"

# The APIs the CLI's verbs call (moved out of components/cli by issue 30).
API_MODULES = (
    "humanpt.runtime.launcher",  # the one process launcher
    "humanpt.runtime.run",  # the entry point every component process runs
    "humanpt.runtime.supervisor",  # humanpt up
    "humanpt.runtime.player",  # humanpt runs play, runs merge
    "humanpt.runtime.params",  # humanpt param
    "humanpt.runtime.monitor",  # humanpt topics, echo
    "humanpt.runtime.progress",  # progress bars and lines of the long jobs
    "humanpt.console.client",  # humanpt console, path play
    "humanpt.console.calibration",  # humanpt calibrate camera|hand-eye --live
    "humanpt.twin.demo",  # humanpt demo
    "humanpt.twin.rerecord",  # humanpt runs rerecord
)


def _path(module: str):
    return COMPONENTS.joinpath(*module.split(".")[1:]).with_suffix(".py")


def _tree(path) -> ast.Module:
    return ast.parse(path.read_text(), filename=str(path))


def test_the_cli_defines_no_class():
    found = [f"{p.relative_to(ROOT)}:{n.lineno} class {n.name}" for p in sorted(CLI.glob("*.py"))
             for n in ast.walk(_tree(p)) if isinstance(n, ast.ClassDef)]
    assert not found, "work belongs in an API module, not the CLI: " + "; ".join(found)


def test_the_check_sees_a_class(tmp_path):
    # the walk above must find a class where there is one (else the test could not fail)
    p = tmp_path / "m.py"
    p.write_text("def f():\n    class Hidden:\n        pass\n")
    assert [n.name for n in ast.walk(_tree(p)) if isinstance(n, ast.ClassDef)] == ["Hidden"]


@pytest.mark.parametrize("module", API_MODULES)
def test_an_api_takes_typed_arguments_not_an_argparse_namespace(module):
    tree = _tree(_path(module))
    # argparse only inside a __main__ entry (main()), never at module level
    top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert not [n for n in top if any(a.name == "argparse" for a in n.names)
                or (isinstance(n, ast.ImportFrom) and n.module == "argparse")], f"{module} imports argparse"
    for fn in (n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))):
        if fn.name == "main":
            continue
        for a in (*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs):
            # a namespace is ``args`` without a type, or a Namespace: every API argument has its type
            kind = ast.unparse(a.annotation) if a.annotation is not None else None
            assert not (a.arg in ("args", "a", "ns") and kind is None) and "Namespace" not in (kind or ""), \
                f"{module}.{fn.name}({a.arg}: {kind}) takes an argparse namespace"
        for node in ast.walk(fn):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and any(a.name == "argparse" for a in node.names):
                pytest.fail(f"{module}.{fn.name} imports argparse")


PROBE = """
import importlib, json, sys
for m in sys.argv[1:]:
    importlib.import_module(m)
print(json.dumps(sorted(n for n in sys.modules if n.startswith("humanpt.cli"))))
"""


def test_the_apis_load_without_the_cli():
    r = subprocess.run([sys.executable, "-c", PROBE, *API_MODULES], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.strip().splitlines()[-1]) == []


def test_nothing_starts_the_cli_to_get_work_done():
    """One launcher (humanpt.runtime.launcher: ``python -m humanpt.runtime.run NAME``); no
    module outside the CLI names the CLI's entry module (the twin, the benches and the
    re-recorder used to start ``python -m humanpt.cli.main``)."""
    hits = []
    for p in sorted(COMPONENTS.rglob("*.py")):
        if CLI in p.parents:
            continue
        for n in ast.walk(_tree(p)):
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and "humanpt.cli" in n.value \
                    and not (n.value.startswith(("``", ":mod:")) or "\n" in n.value or " " in n.value):
                hits.append(f"{p.relative_to(ROOT)}:{n.lineno} {n.value!r}")
            if isinstance(n, (ast.Import, ast.ImportFrom)):
                mods = [a.name for a in n.names] if isinstance(n, ast.Import) else [n.module or ""]
                hits += [f"{p.relative_to(ROOT)}:{n.lineno} imports {m}" for m in mods if m.startswith("humanpt.cli")]
    assert not hits, hits


def test_the_launcher_starts_a_component_through_the_one_entry_point():
    from humanpt.runtime import launcher

    argv = launcher.argv("pinger", config="c.toml", run_dir="runs/x", duration_s=2)
    assert argv[:4] == [sys.executable, "-m", "humanpt.runtime.run", "pinger"]
    assert argv[4:] == ["--config", "c.toml", "--run-dir", "runs/x", "--duration", "2.0"]
    assert launcher.argv("router", listen=["tcp/127.0.0.1:7447"])[3:] == ["router", "--listen", "tcp/127.0.0.1:7447"]


def test_the_entry_point_names_a_bad_config_in_one_line(tmp_path):
    # a real process through the entry point: a bad key is refused before anything starts
    bad = tmp_path / "h.toml"
    bad.write_text("[ponger]\nprefx = 'x'\n")
    from humanpt.runtime import launcher

    r = subprocess.run(launcher.argv("ponger", config=bad), capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"humanpt ponger: error: {bad}: [ponger] unknown key 'prefx'; known keys: prefix"]


def test_help_loads_no_verb_module():
    """``humanpt --help`` imports a verb's module only when that verb runs (issue 30: 1.2 s,
    half of it scipy through operator.scenario)."""
    probe = ("import sys, contextlib, io\nfrom humanpt.cli.main import main\n"
             "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
             "    main(['--help'])\n"
             "print(' '.join(sorted(n for n in sys.modules if n in ('numpy', 'scipy', 'zenoh', 'cv2', 'rerun') "
             "or n.startswith(('humanpt.operator', 'humanpt.twin', 'humanpt.console', 'humanpt.runtime.core')))))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == ""


def bench_help_seconds(runs: int = 15) -> float:
    """The median wall time of ``python -m humanpt.cli.main --help`` (a figure for the
    report; not asserted: timing depends on the machine's load)."""
    import time

    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "humanpt.cli.main", "--help"], stdout=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


if __name__ == "__main__":
    print(f"humanpt --help: median {bench_help_seconds():.3f} s over 15 runs")


RESOLVE = """
import ast, importlib, json, pathlib, sys
missing = []
for path in sorted(pathlib.Path(sys.argv[1]).glob("*.py")):
    for n in ast.walk(ast.parse(path.read_text())):
        if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("humanpt"):
            mod = importlib.import_module(n.module)
            for a in n.names:
                if not hasattr(mod, a.name):
                    try:
                        importlib.import_module(f"{n.module}.{a.name}")
                    except ImportError:
                        missing.append(f"{path.name}:{n.lineno} {n.module}.{a.name}")
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name.startswith("humanpt"):
                    importlib.import_module(a.name)
print(json.dumps(missing))
"""


def test_every_import_of_the_cli_resolves():
    """The verbs import their APIs lazily (inside functions, for --help's time): a name moved
    out of the CLI and not followed would only fail when that verb runs (issue 30 moved
    Console out of cli/console.py: `calibrate tip --config` imported it from there)."""
    r = subprocess.run([sys.executable, "-c", RESOLVE, str(CLI)], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.strip().splitlines()[-1]) == []


def test_every_bench_the_parser_offers_has_its_function():
    """`humanpt bench WHAT` dispatches to cli/bench.py's ``bench_<WHAT>`` (``bench_all``
    without WHAT): a sub-bench added to the parser without its function fails here, not at a
    user's prompt."""
    import argparse

    from humanpt.cli import bench as bench_cli
    from humanpt.cli.main import build_parser

    bench = next(a for a in build_parser()._subparsers._group_actions[0].choices["bench"]._actions
                 if isinstance(a, argparse._SubParsersAction))
    verbs = sorted(bench.choices)
    assert {"faults", "perception", "rsi", "ur", "alter"} <= set(verbs), verbs
    missing = [v for v in [*verbs, "all"] if not callable(getattr(bench_cli, f"bench_{v}", None))]
    assert missing == [], missing
