"""Packages depend one way (issue 15.4): a product package, with every one of its modules
loaded, has not loaded the twin, the simulators, the test machinery, the benches or the
CLI. Each check runs in a fresh interpreter, so nothing another test imported counts."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT

# Never loaded by a product package (DESIGN.md: the twin and the tools sit on top).
FORBIDDEN = ("humanpt.twin", "humanpt.sim_camera", "humanpt.sim_robot", "humanpt.operator",
             "humanpt.testing", "humanpt.bench", "humanpt.cli")
# What each product package may load besides itself.
SHARED = ("humanpt.runtime", "humanpt.geometry", "humanpt.schemas")
PRODUCT = ("camera", "perception", "pose_filter", "controller", "robot_gateway", "viz", "calibration", "seam",
           "scene")

# Import the package and every submodule, then list the humanpt packages that got loaded.
PROBE = """
import importlib, json, pkgutil, sys
pkg = importlib.import_module(sys.argv[1])
names = [pkg.__name__] + [m.name for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
for name in names:
    importlib.import_module(name)
loaded = sorted({".".join(n.split(".")[:2]) for n in sys.modules if n.startswith("humanpt.")})
print(json.dumps({"modules": names, "loaded": loaded}))
"""


def loaded_by(package: str) -> tuple[list[str], set[str]]:
    r = subprocess.run([sys.executable, "-c", PROBE, package], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    return out["modules"], set(out["loaded"])


@pytest.mark.parametrize("name", PRODUCT)
def test_a_product_package_loads_only_the_shared_packages(name):
    package = f"humanpt.{name}"
    modules, loaded = loaded_by(package)
    assert len(modules) > 1, f"{package}: no submodules found, the probe walked nothing"
    assert not loaded & set(FORBIDDEN), f"{package} loads {sorted(loaded & set(FORBIDDEN))}"
    assert loaded <= {package, *SHARED}, f"{package} loads {sorted(loaded - {package, *SHARED})}"


def test_viz_does_not_load_perception():
    _, loaded = loaded_by("humanpt.viz")
    assert "humanpt.perception" not in loaded


def test_the_probe_sees_a_forbidden_import():
    # The twin loads the simulators: the probe must report them (else the checks above
    # would pass on a probe that never records anything).
    _, loaded = loaded_by("humanpt.twin")
    assert {"humanpt.sim_camera", "humanpt.operator"} <= loaded


@pytest.mark.parametrize("link", ["alter", "rsi"])
def test_a_link_loads_only_the_gateway_and_the_shared_packages(link):
    # issue 22: RSI is a link of the one gateway (its safety core), not a simulator's
    modules, loaded = loaded_by(f"humanpt.robot_gateway.links.{link}")
    assert len(modules) > 1 and not loaded & set(FORBIDDEN), sorted(loaded & set(FORBIDDEN))
    assert loaded <= {"humanpt.robot_gateway", *SHARED}, sorted(loaded)
