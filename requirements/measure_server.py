"""Measure the server's lean install (a measurement, not a test; it needs pip's index):

    python3 requirements/measure_server.py [--venv DIR] [--keep]

builds a fresh venv with ``pip install --no-compile -r requirements/server.txt && pip install
--no-deps -e .`` (this checkout), prints its size in MB (after the install, and after the
first start, which compiles the bytecode of the modules the server imports; ``--compile``:
pip's default, the bytecode of every module at install) and its packages, checks that none of the
client's heavy packages is importable there, and runs ``humanpt up --profile server
--duration 1`` in it (the router and the robot gateway over the RSI link on loopback, free
ports) to tell whether both came up.  Exit status 0 when the gateway came up.  Standard
library only: run it with any Python >= 3.11.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def size_mb(path: Path) -> float:
    """Bytes on disk of the files under ``path`` (symlinks not followed), in MB (10^6)."""
    total = 0
    for dirpath, _, files in os.walk(path):
        for f in files:
            p = Path(dirpath, f)
            if not p.is_symlink():
                total += p.stat().st_blocks * 512
    return total / 1e6


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--venv", help="where to build the venv (default: a temporary directory)")
    ap.add_argument("--keep", action="store_true", help="keep the venv afterwards")
    ap.add_argument("--compile", action="store_true",
                    help="let pip compile every module's bytecode at install (its default; without: --no-compile)")
    a = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="humanpt-server-"))
    venv = Path(a.venv) if a.venv else work / "venv"
    if venv.exists():
        print(f"measure_server: {venv} exists; give a new directory", file=sys.stderr)
        return 2
    try:
        t0 = time.monotonic()
        steps = [[sys.executable, "-m", "venv", str(venv)],
                 [str(venv / "bin" / "pip"), "install", "-q", "--compile" if a.compile else "--no-compile",
                  "-r", str(ROOT / "requirements" / "server.txt")],
                 [str(venv / "bin" / "pip"), "install", "-q", "--no-deps", "-e", str(ROOT)]]
        for cmd in steps:
            r = run(cmd)
            if r.returncode != 0:
                print(f"measure_server: {' '.join(cmd[-4:])} failed:\n{r.stderr.strip()}", file=sys.stderr)
                return 1
        install_s = time.monotonic() - t0
        py = str(venv / "bin" / "python")
        pkgs = run([py, "-m", "pip", "list", "--format=freeze", "--exclude-editable"]).stdout.split()
        heavy = run([py, "-c", "from humanpt.runtime.install import FULL_ONLY; print(*FULL_ONLY)"]).stdout.split()
        present = [m for m in heavy if run([py, "-c", f"import {m}"]).returncode == 0]
        how = "pip --compile" if a.compile else "pip --no-compile"
        print(f"server install: {size_mb(venv):.0f} MB in {venv} ({len(pkgs)} packages, {install_s:.0f} s, {how}; "
              f"the checkout itself not counted)")
        print(f"packages: {' '.join(pkgs)}")
        print(f"the full install's packages importable: {', '.join(present) or 'none'} (of {', '.join(heavy)})")

        port, udp = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_DGRAM)
        cell = work / "cell.toml"
        cell.write_text(f'[runtime]\ncell = "measure"\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                        f'connect = ["tcp/127.0.0.1:{port}"]\nrun_dir = "{work / "runs"}"\n'
                        f'[robot_gateway]\nlink = "rsi"\nudp_bind = "127.0.0.1:{udp}"\n')
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}  # as a server runs
        r = run([str(venv / "bin" / "humanpt"), "up", "--profile", "server", "-c", str(cell), "--duration", "1"],
                cwd=work, timeout=300, env=env)
        up = [ln for ln in r.stdout.splitlines() if "components up after" in ln]
        started = r.returncode == 0 and bool(up) and "all 1 components up" in up[0]
        print(f"`humanpt up --profile server` (router + robot_gateway, RSI link): "
              f"{'started' if started else 'did NOT start'}"
              f"{': ' + up[0].removeprefix('humanpt up: ') if up else ''} (exit {r.returncode})")
        print(f"server install after that start: {size_mb(venv):.0f} MB (with the bytecode it compiled)")
        if not started:
            print(r.stdout + r.stderr, file=sys.stderr)
        return 0 if started and heavy and not present else 1
    finally:
        if a.keep:
            print(f"kept: {venv}")
        else:
            shutil.rmtree(venv, ignore_errors=True)
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
