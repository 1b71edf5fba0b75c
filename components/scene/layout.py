"""The Foxglove layout of a cell: image with its overlays, 3D, plots and log, on the keys of
the cell given (``humanpt/<cell>/...``). The template (``foxglove_layout.json``, package data)
is written for the default cell ``cell0``; ``docs/foxglove-layout.json`` is that rendering,
and ``humanpt runs merge`` writes one for the merged run's own cell beside the file."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

from humanpt.schemas import topics

TEMPLATE_CELL = "cell0"


def _template() -> dict[str, Any]:
    return json.loads(resources.files("humanpt.scene").joinpath("foxglove_layout.json").read_text())


def foxglove_layout(cell: str = TEMPLATE_CELL) -> dict[str, Any]:
    """The layout with every key on ``cell``'s (``humanpt/cell0/`` -> ``humanpt/<cell>/``
    in every string: topic fields and plot paths alike)."""
    old, new = f"{topics.KEY_PREFIX}/{TEMPLATE_CELL}/", f"{topics.KEY_PREFIX}/{cell}/"

    def swap(v: Any) -> Any:
        if isinstance(v, str):
            return v.replace(old, new)
        if isinstance(v, list):
            return [swap(x) for x in v]
        if isinstance(v, dict):
            return {swap(k): swap(x) for k, x in v.items()}
        return v

    return swap(_template())


def layout_text(cell: str = TEMPLATE_CELL) -> str:
    return json.dumps(foxglove_layout(cell), indent=2) + "\n"


def write_layout(path: str | Path, cell: str) -> Path:
    """Write ``cell``'s layout to ``path`` (replaced if it exists); the path written."""
    p = Path(path)
    p.write_text(layout_text(cell))
    return p
