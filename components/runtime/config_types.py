"""The annotation types of configuration fields: :class:`Range` (a numeric field's physical
range), the shared ranges (:data:`Mm`, :data:`Deg`, :data:`SpeedMmS`, :data:`RateDegS`),
:func:`live` (a field that may change at run time) and :class:`ConfigError`.

A leaf module: it imports nothing from humanpt, so any package may declare its config with
it - in particular :mod:`humanpt.geometry` (its PSVS and rig dataclasses), which sits below
:mod:`humanpt.runtime` (``runtime.config`` builds the rig, ``runtime.rigfile`` reads it).
:mod:`humanpt.runtime.config` re-exports every name here (the old import path).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

__all__ = ["ConfigError", "Deg", "Mm", "Range", "RateDegS", "SpeedMmS", "live", "live_keys"]


class ConfigError(ValueError):
    """A configuration problem; the message names the file, section and key."""


@dataclass(frozen=True)
class Range:
    """The physical range of a numeric parameter, ``lo <= value <= hi`` (closed)."""

    lo: float
    hi: float
    unit: str = ""

    def check(self, value: float, where: str) -> None:
        if not self.lo <= value <= self.hi:
            unit = f" {self.unit}" if self.unit else ""
            raise ConfigError(f"{where}: {value!r} is outside its range [{self.lo:g}, {self.hi:g}]{unit}")


# Ranges shared by several components.  Lengths and angles of poses (the Puma's reach is
# 1.25 m; a cell is a few metres); speeds of the tool at most ISO 10218-1's reduced speed for
# a person in the cell (250 mm/s, the paper's 100 mm/s is the default).
Mm = Annotated[float, Range(-5000.0, 5000.0, "mm")]
Deg = Annotated[float, Range(-360.0, 360.0, "deg")]
SpeedMmS = Annotated[float, Range(1e-3, 250.0, "mm/s")]
RateDegS = Annotated[float, Range(1e-3, 180.0, "deg/s")]


def live(default: Any, doc: str = "", *, stricter: Literal["lower", "higher"] | None = None) -> Any:
    """A dataclass field that may be changed at run time.

    ``stricter``: a safety limit that may only become stricter than the value the component
    started with - ``"lower"`` (a speed, a count of cycles; for a tuple, every element) or
    ``"higher"`` (a lower corner of a box)."""
    return field(default=default, metadata={"live": True, "doc": doc, "stricter": stricter})


def live_keys(cls_or_obj) -> list[str]:
    """Names of the fields of a config dataclass that may change at run time."""
    return [f.name for f in dataclasses.fields(cls_or_obj) if f.metadata.get("live")]
