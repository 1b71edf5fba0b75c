"""Names of a package imported from their submodules on first use (PEP 562), so that
importing the package (validating a config file, the server's install without OpenCV)
imports none of its heavy submodules."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: dict[str, str]) -> Callable[[str], object]:
    """The module ``__getattr__`` of ``package``: ``exports`` maps each name to the submodule
    (relative, without the dot) that defines it; a name is imported on its first use and
    kept in the package. Any other name: AttributeError."""

    def __getattr__(name: str) -> object:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__
