"""Packages depend one way (issue 15.4, issue 30.3; the rule is ARCHITECTURE.md's).

Two checks. The AST scan reads every import statement of every module, at module level and
inside functions, so an import that only runs when a function is called is seen too: a
product package never imports a tool package (the twin, the simulators, the operator, the
test machinery, the benches, the CLI) and imports only the packages ARCHITECTURE.md allows
it. The load probe imports a package and all its submodules in a fresh interpreter and
lists what got loaded (what a process of that component really carries)."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from humanpt.robot_gateway.links import LINKS
from tests.conftest import ROOT

# The tool packages: never imported nor loaded by a product package (DESIGN.md: the twin and
# the tools sit on top; ARCHITECTURE.md).
TOOLS = ("twin", "bench", "testing", "sim_camera", "sim_robot", "operator", "cli")
FORBIDDEN = tuple(f"humanpt.{t}" for t in TOOLS)
# What each product package may load besides itself.
SHARED = ("humanpt.runtime", "humanpt.geometry", "humanpt.schemas")
PRODUCT = ("camera", "perception", "pose_filter", "controller", "robot_gateway", "viz", "calibration", "seam",
           "scene")

# Import the package and every submodule, then list the humanpt packages that got loaded. One
# interpreter for every probe (a module's fixture): it loads the third-party libraries the
# components share once (no humanpt module), then forks a child per package, so each child
# starts with no humanpt module loaded, as a component's process does, and pays only for
# humanpt's own imports (21 fresh interpreters each importing numpy, scipy and OpenCV cost ~15 s).
PROBE = """
import importlib, json, os, pkgutil, sys
for lib in ("numpy", "scipy.spatial.transform", "scipy.optimize", "scipy.linalg", "cv2",
            "google.protobuf.message"):
    importlib.import_module(lib)
assert not [n for n in sys.modules if n == "humanpt" or n.startswith("humanpt.")]
for package in sys.argv[1:]:
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        try:
            pkg = importlib.import_module(package)
            names = [pkg.__name__] + [m.name for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
            for name in names:
                importlib.import_module(name)
            loaded = sorted({".".join(n.split(".")[:2]) for n in sys.modules if n.startswith("humanpt.")})
            out = {"modules": names, "loaded": loaded}
        except BaseException as e:
            out = {"error": f"{type(e).__name__}: {e}"}
        os.write(w, json.dumps(out).encode())
        os.close(w)
        os._exit(0)
    os.close(w)
    with os.fdopen(r) as f:
        data = f.read()
    os.waitpid(pid, 0)
    print(json.dumps({package: json.loads(data)}), flush=True)
"""
PROBED = (*(f"humanpt.{n}" for n in PRODUCT), "humanpt.twin",
          *(f"humanpt.robot_gateway.links.{link}" for link in sorted(LINKS)))


@pytest.fixture(scope="module")
def probes() -> dict[str, dict]:
    r = subprocess.run([sys.executable, "-c", PROBE, *PROBED], capture_output=True, text=True, cwd=ROOT,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    out: dict[str, dict] = {}
    for line in r.stdout.splitlines():
        if line.startswith("{"):
            out.update(json.loads(line))
    assert set(out) == set(PROBED), (sorted(set(PROBED) - set(out)), r.stderr[-2000:])
    return out


@pytest.fixture(scope="module")
def loaded_by(probes):
    def loaded(package: str) -> tuple[list[str], set[str]]:
        out = probes[package]
        assert "error" not in out, f"{package}: {out.get('error')}"
        return out["modules"], set(out["loaded"])
    return loaded


@pytest.mark.parametrize("name", PRODUCT)
def test_a_product_package_loads_only_the_shared_packages(name, loaded_by):
    package = f"humanpt.{name}"
    modules, loaded = loaded_by(package)
    assert len(modules) > 1, f"{package}: no submodules found, the probe walked nothing"
    assert not loaded & set(FORBIDDEN), f"{package} loads {sorted(loaded & set(FORBIDDEN))}"
    assert loaded <= {package, *SHARED}, f"{package} loads {sorted(loaded - {package, *SHARED})}"


def test_viz_does_not_load_perception(loaded_by):
    _, loaded = loaded_by("humanpt.viz")
    assert "humanpt.perception" not in loaded


def test_the_probe_sees_a_forbidden_import(loaded_by):
    # The twin loads the simulators: the probe must report them (else the checks above
    # would pass on a probe that never records anything).
    _, loaded = loaded_by("humanpt.twin")
    assert {"humanpt.sim_camera", "humanpt.operator"} <= loaded


@pytest.mark.parametrize("link", sorted(LINKS))
def test_a_link_loads_only_the_gateway_and_the_shared_packages(link, loaded_by):
    # issue 22: RSI is a link of the one gateway (its safety core), not a simulator's
    modules, loaded = loaded_by(f"humanpt.robot_gateway.links.{link}")
    assert len(modules) > 1 and not loaded & set(FORBIDDEN), sorted(loaded & set(FORBIDDEN))
    assert loaded <= {"humanpt.robot_gateway", *SHARED}, sorted(loaded)


# --------------------------------------------------------------------------- the AST scan

# Every package but the tools is product code (a new package is product until it is listed
# as a tool). What a product package may import besides itself (ARCHITECTURE.md): the
# shared packages, and the few edges listed here.
SHARED_PACKAGES = {"runtime", "geometry", "schemas"}
MAY_IMPORT = {
    # the bottom: pure maths and the Puma model; its configs are annotated with the leaf
    # module runtime.config_types (below, checked by module), nothing else
    "geometry": set(),
    "schemas": set(),
    "runtime": {"geometry", "schemas"},  # runtime.config builds the rig, runtime.rigfile reads it
    "controller": SHARED_PACKAGES | {"seam"},  # a path file is checked against the seam's limits
    # the operator's client (console verbs, live calibration): it prepares what it sends as the
    # controller checks it, reads seams, runs the calibrations and reads the gateway's config
    "console": SHARED_PACKAGES | {"controller", "calibration", "seam", "robot_gateway"},
    # the operator's screen in a browser: its parameters and buttons are the console's
    "foxglove_bridge": SHARED_PACKAGES | {"console"},
}
# Modules of another package that a package may import (the leaf config types).
MAY_IMPORT_MODULES = {"geometry": {"humanpt.runtime.config_types"}}
# Leaf modules: import nothing from humanpt.
LEAVES = ("humanpt.runtime.config_types",)


def package_dirs() -> dict[str, Path]:
    """humanpt's subpackages -> their folder (components/*, and schemas/)."""
    dirs = {p.parent.name: p.parent for p in sorted((ROOT / "components").glob("*/__init__.py"))}
    dirs["schemas"] = ROOT / "schemas"
    return dirs


def module_name(package: str, path: Path, folder: Path) -> str:
    parts = [package, *path.relative_to(folder).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(["humanpt", *parts])


def imports_of(source: str, module: str, is_package: bool = False) -> list[tuple[str, int]]:
    """Every humanpt module ``source`` imports, anywhere in it (module level, functions,
    classes, ``if TYPE_CHECKING``), as (absolute dotted name, line); relative imports are
    resolved against ``module``. ``from humanpt.a import b`` gives ``humanpt.a.b`` (b may be
    a module)."""
    here = module.split(".") if is_package else module.split(".")[:-1]
    out: list[tuple[str, int]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = here[: len(here) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            out += [(f"{mod}.{a.name}", node.lineno) for a in node.names]
    return [(name, line) for name, line in out if name == "humanpt" or name.startswith("humanpt.")]


def scan() -> dict[str, list[tuple[str, str]]]:
    """package -> [(imported humanpt module, "file:line")] over every module of every package."""
    found: dict[str, list[tuple[str, str]]] = {}
    for package, folder in package_dirs().items():
        rows = found.setdefault(package, [])
        for path in sorted(folder.rglob("*.py")):
            module = module_name(package, path, folder)
            for name, line in imports_of(path.read_text(), module, path.name == "__init__.py"):
                rows.append((name, f"{path.relative_to(ROOT)}:{line}"))
    return found


def package_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_the_scan_sees_every_package_and_its_imports():
    found = scan()
    # the tools and the product are both there, and the scan resolves relative imports
    assert {"twin", "cli", "geometry", "runtime", "controller", "schemas"} <= set(found), sorted(found)
    assert ("humanpt.twin.run.SystemConfig", "components/twin/cal_handeye.py") in {
        (n, w.split(":")[0]) for n, w in found["twin"]}


def test_the_scan_sees_an_import_inside_a_function():
    # what the load probe cannot see (issue 30: pose_filter/bench.py imported the twin and
    # the operator inside functions): an import that runs only when a function is called
    src = ("def f():\n    from humanpt.twin.evaluate import truth_at\n"
           "class C:\n    def g(self):\n        import humanpt.operator.scenario\n"
           "        from ..sim_robot import core\n")
    got = imports_of(src, "humanpt.pose_filter.bench")
    assert got == [("humanpt.twin.evaluate.truth_at", 2), ("humanpt.operator.scenario", 5),
                   ("humanpt.sim_robot.core", 6)]


def test_no_product_module_imports_a_tool_anywhere():
    bad = [f"{where}: {package} imports {name}" for package, rows in scan().items() if package not in TOOLS
           for name, where in rows if package_of(name) in TOOLS]
    assert not bad, "product code imports a tool package:\n" + "\n".join(bad)


def test_each_product_package_imports_only_what_it_may():
    bad = []
    for package, rows in scan().items():
        if package in TOOLS:
            continue
        allowed = MAY_IMPORT.get(package, SHARED_PACKAGES) | {package}
        modules = MAY_IMPORT_MODULES.get(package, set())
        for name, where in rows:
            if name == "humanpt":  # the top package (its version; components/__init__.py imports nothing)
                continue
            if package_of(name) not in allowed and not any(name == m or name.startswith(m + ".")
                                                           for m in modules):
                bad.append(f"{where}: {package} imports {name}")
    assert not bad, "imports against ARCHITECTURE.md:\n" + "\n".join(bad)


def test_geometry_does_not_import_runtime_config():
    # issue 30: geometry <-> runtime was a cycle (geometry took Range from runtime.config,
    # runtime.config builds the Rig). Now runtime may import geometry, geometry only the
    # leaf runtime.config_types; and that leaf imports nothing of humanpt.
    found = scan()
    into_runtime = sorted({name for name, _ in found["geometry"] if package_of(name) == "runtime"})
    assert into_runtime == ["humanpt.runtime.config_types.Deg", "humanpt.runtime.config_types.Mm",
                            "humanpt.runtime.config_types.Range"], into_runtime
    for leaf in LEAVES:
        rows = [(n, w) for n, w in found["runtime"] if w.startswith(f"components/runtime/{leaf.split('.')[-1]}.py")]
        assert not rows, f"{leaf} must import nothing of humanpt: {rows}"


def test_the_old_config_import_path_still_works():
    from humanpt.runtime import config, config_types

    for name in config_types.__all__:
        assert getattr(config, name) is getattr(config_types, name), name
