"""The server's lean install (issue 38 item 6): ``requirements/server.txt`` without the full
install's packages (``humanpt.runtime.install.FULL_ONLY``: OpenCV, rerun, filterpy, the
Foxglove SDK, matplotlib, rich), and the router and the robot gateway running without them.

The live test runs ``humanpt up --profile server`` (the router and the gateway over the RSI
link on loopback, each a process of its own) with an import hook (a ``sitecustomize`` on
PYTHONPATH, so every child has it) that refuses those packages, as an install without them
would, and waits for ``up``'s line that every component's liveliness token came (an event).
What the install weighs is measured, not tested: ``python3 requirements/measure_server.py``
(a fresh venv from PyPI; README, docs/cell.md).
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from humanpt.runtime.install import FULL_ONLY, needs_full_install
from humanpt.runtime.registry import COMPONENTS, CONFIGS, config_types, core_class
from tests.conftest import ROOT, free_port, humanpt_cmd, write_config

# The distributions of FULL_ONLY's import names (what pyproject lists).
FULL_ONLY_DISTS = {"opencv-python-headless", "rerun-sdk", "filterpy", "foxglove-sdk", "matplotlib", "rich", "numba"}

REFUSE = f"""
import importlib.abc, sys
REFUSED = {FULL_ONLY!r}
class _Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in REFUSED:
            raise ModuleNotFoundError(f"No module named {{name!r}} (refused: the server's install)", name=name)
        return None
sys.meta_path.insert(0, _Refuse())
"""


# Tries to import each name of its command line; prints why each failed.
PROBE = """
import importlib, sys
for name in sys.argv[1:]:
    try:
        importlib.import_module(name)
        print(name, "imported")
    except ModuleNotFoundError as e:
        print(e)
"""


def _requirement_lines(text: str) -> list[str]:
    return [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def _dist(req: str) -> str:
    return re.split(r"[<>=!~ \[;]", req, maxsplit=1)[0].lower()


def test_server_requirements_are_pyprojects_lines_without_the_full_only_packages():
    full = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    server = _requirement_lines((ROOT / "requirements" / "server.txt").read_text())
    assert server, "requirements/server.txt lists nothing"
    assert not set(server) - set(full), f"not pyproject's lines (bounds drifted?): {set(server) - set(full)}"
    assert FULL_ONLY_DISTS <= {_dist(r) for r in full}, "FULL_ONLY_DISTS names a package pyproject lacks"
    assert not {_dist(r) for r in server} & FULL_ONLY_DISTS
    # what the server runs needs these (the bus, messages, recordings, ALTER's serial line, mTLS)
    assert {"eclipse-zenoh", "protobuf", "mcap", "pyserial", "cryptography"} <= {_dist(r) for r in server}


def test_config_validation_reads_the_cores_config_classes():
    types = config_types()
    assert set(CONFIGS) == set(COMPONENTS) == set(types)
    for name in COMPONENTS:
        assert types[name] is core_class(name).config_type, name


@pytest.mark.parametrize("package", ["humanpt.perception", "humanpt.camera"])
def test_lazy_packages_still_export_every_name(package):
    import importlib

    pkg = importlib.import_module(package)
    assert set(pkg._EXPORTS) == set(pkg.__all__)
    for name in pkg.__all__:
        value = getattr(pkg, name)
        assert value is getattr(importlib.import_module(f"{package}.{pkg._EXPORTS[name]}"), name)
    with pytest.raises(AttributeError, match="no_such_name"):
        pkg.no_such_name  # noqa: B018


def test_rotation_vectors_without_opencv_are_opencvs_matrices(monkeypatch):
    import cv2

    from humanpt.geometry import transforms

    rng = np.random.default_rng(38)
    vectors = np.vstack([rng.normal(scale=1.0, size=(50, 3)), np.zeros((1, 3)), [[np.pi, 0.0, 0.0]]])
    expected = np.array([cv2.Rodrigues(v)[0] for v in vectors])  # OpenCV: the independent source
    monkeypatch.setattr(transforms, "_cv2_rodrigues", None)
    np.testing.assert_allclose(transforms.matrix_from_rotvec(vectors[0]), expected[0], atol=1e-15)
    np.testing.assert_allclose(transforms.matrix_from_rotvec(vectors), expected, atol=1e-15)
    stacked = transforms.matrix_from_rotvec(vectors[:50].reshape(5, 10, 3))
    assert stacked.shape == (5, 10, 3, 3)
    np.testing.assert_allclose(stacked.reshape(50, 3, 3), expected[:50], atol=1e-15)
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        transforms.matrix_from_rotvec(np.zeros(4))


def test_a_missing_full_install_package_is_named_in_one_line():
    why = needs_full_install(ModuleNotFoundError("No module named 'cv2'", name="cv2"))
    assert why is not None and "'cv2'" in why and "pip install -e ." in why and "\n" not in why
    assert needs_full_install(ModuleNotFoundError("No module named 'rerun.blueprint'", name="rerun.blueprint"))
    assert needs_full_install(ModuleNotFoundError("No module named 'numpy'", name="numpy")) is None


@pytest.fixture(scope="module")
def refusing_env(tmp_path_factory):
    """An environment whose Python processes cannot import FULL_ONLY (a sitecustomize)."""
    d = tmp_path_factory.mktemp("refuse")
    (d / "sitecustomize.py").write_text(REFUSE)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(d), env.get("PYTHONPATH")) if p)
    # the hook is in force: each of them fails to import (one process tries them all)
    r = subprocess.run([sys.executable, "-c", PROBE, *FULL_ONLY], env=env, capture_output=True, text=True, timeout=120)
    assert r.stdout.splitlines() == [f"No module named {n!r} (refused: the server's install)" for n in FULL_ONLY], \
        r.stdout + r.stderr
    return env


def test_a_full_install_verb_on_the_server_says_what_it_needs(refusing_env, tmp_path):
    r = subprocess.run(humanpt_cmd("view", str(tmp_path)), env=refusing_env, capture_output=True, text=True,
                       cwd=tmp_path, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().splitlines() == [
        "humanpt view: needs the full install (no module 'rerun' here: this is the server's lean install, "
        "requirements/server.txt); run it on the client, or `pip install -e .`"]


# Every module of the server's packages imports without them, but the two that render the
# demo's and the benches' tables and progress bars (rich).
WALK = """
import importlib, pkgutil, humanpt.robot_gateway, humanpt.runtime
names = [m.name for pkg in (humanpt.robot_gateway, humanpt.runtime)
         for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
bad = []
for name in names:
    try:
        importlib.import_module(name)
    except ImportError as e:
        bad.append(f"{name}: {e}")
print(len(names))
print(*bad, sep="\\n")
"""


def test_every_gateway_and_runtime_module_imports_on_the_server(refusing_env, tmp_path):
    r = subprocess.run([sys.executable, "-c", WALK], env=refusing_env, capture_output=True, text=True,
                       cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr
    count, *bad = r.stdout.strip().splitlines()
    assert int(count) > 40  # (the walk found the packages)
    assert bad == ["humanpt.runtime.progress: No module named 'rich' (refused: the server's install)",
                   "humanpt.runtime.tables: No module named 'rich' (refused: the server's install)"]


@pytest.mark.live
@pytest.mark.timeout(300)
def test_server_profile_comes_up_without_the_full_install(refusing_env, tmp_path):
    port = free_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        udp = s.getsockname()[1]
    cfg = write_config(tmp_path / "cell.toml", port,
                       extra=f'[robot_gateway]\nlink = "rsi"\nudp_bind = "127.0.0.1:{udp}"\n')
    run_dir = tmp_path / "run"
    # --duration counts from when every component's token came (up's wait_ready): the line
    # below is that event; the half second after it only lets up stop them all cleanly
    r = subprocess.run(humanpt_cmd("up", "--profile", "server", "-c", str(cfg), "--run-dir", str(run_dir),
                                   "--duration", "0.5"),
                       env=refusing_env, capture_output=True, text=True, cwd=tmp_path, timeout=240)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "profile server: router, robot_gateway" in out
    assert re.search(r"all 1 components up after [\d.]+ s", out), out
    assert "Traceback" not in out and "refused" not in out, out
    assert (run_dir / "robot_gateway.mcap").stat().st_size > 0, sorted(run_dir.iterdir())
