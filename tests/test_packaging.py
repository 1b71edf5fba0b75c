"""pyproject lists every package folder (a missing one would be left out of a wheel)."""

from __future__ import annotations

import tomllib

from tests.conftest import ROOT


def test_every_package_is_listed():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    found = {"humanpt.schemas"}
    for init in (ROOT / "components").rglob("__init__.py"):
        rel = init.parent.relative_to(ROOT / "components")
        found.add(".".join(("humanpt", *rel.parts)) if rel.parts else "humanpt")
    assert found == listed, f"pyproject packages differ: missing {found - listed}, extra {listed - found}"
