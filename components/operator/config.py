"""Configuration of the operator (section ``[operator]``)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from humanpt.runtime.config import Mm, Range, live

from .scenario import (
    BUILTIN_SCENARIOS,
    Scenario,
    ScenarioError,
    Tremor,
    TremorModel,
    builtin_scenario,
    parse_scenario,
)

HAND_TREMOR_STREAM = 13  # the operator's tremor waveform: default_rng([seed, 13])


@dataclass(frozen=True)
class OperatorConfig:
    """The simulated operator: which scenario, how fast, how often truth is published.

    ``scenario`` names a built-in (static, arc, trapezium, freehand); ``scenario_file``, if
    set, names a scenario file instead (format: ``README.md``). The file is read once, when
    the config is built, into ``scenario_text`` - so a recording carries the scenario itself
    and replays without the file. ``scenario_text`` may also be given inline.
    ``speed_mm_s`` > 0 replaces a built-in's default speed (refused with a scenario
    file or text, which sets its own); ``speed_scale`` (live) scales
    the pace of any scenario (tremor stays at human frequencies). The target holds its start
    pose for ``start_delay_s`` (so the servo can settle), then moves. Truth is published at
    ``rate_hz``. ``seed`` shapes the freehand seam and its tremor.
    """

    scenario: Literal["static", "arc", "trapezium", "freehand", "scurve", "abrupt", "occluded", "partial"] = "static"
    scenario_file: str = ""
    scenario_text: str = ""
    speed_mm_s: Annotated[float, Range(0, 1000, "mm/s")] = 0.0
    speed_scale: Annotated[float, Range(1e-3, 100, "")] = live(1.0, "pace of the scenario (1 = as written)")
    rate_hz: Annotated[float, Range(1, 10000, "Hz")] = 100.0
    start_delay_s: Annotated[float, Range(0, 3600, "s")] = 2.0
    seed: Annotated[int, Range(0, 2**63 - 1, "")] = 0
    tremor_mm: Annotated[float, Range(0, 10, "mm")] = 0.0
    tremor_deg: Annotated[float, Range(0, 10, "deg")] = 0.0
    # The true driver tip's offset (TOB frame, mm) from the scenario's design value: a needle
    # a little bent or not quite seated (0: as designed). The pipeline's rig knows only the
    # design value until the tip is calibrated.
    driver_error_mm: tuple[Mm, Mm, Mm] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.scenario not in BUILTIN_SCENARIOS:
            raise ValueError(
                f"scenario must be one of {', '.join(BUILTIN_SCENARIOS)}, got {self.scenario!r}"
            )
        if self.scenario_file and not self.scenario_text:
            # Shell side (config loading), not the core: read the file once, keep its text.
            path = Path(self.scenario_file)
            try:
                text = path.read_text()
            except OSError as e:
                raise ValueError(
                    f"scenario_file {self.scenario_file!r}: cannot read it: {e}"
                ) from None
            object.__setattr__(self, "scenario_text", text)
        for name, lo, hi in (
            ("speed_mm_s", 0.0, 1000.0),
            ("speed_scale", 0.0, 100.0),
            ("rate_hz", 1e-3, 10_000.0),
            ("start_delay_s", 0.0, 1e6),
            ("tremor_mm", 0.0, 10.0),
            ("tremor_deg", 0.0, 10.0),
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"operator.{name} must be within {lo} and {hi}, got {value}")
        if self.speed_mm_s > 0 and self.scenario_text:
            # A file sets its own speeds (its ``speed`` lines, per segment): a built-in's speed
            # would be silently ignored (a "60 mm/s" run at the file's 20).
            raise ValueError(f"operator.speed_mm_s (demo --speed) {self.speed_mm_s:g} mm/s sets a built-in scenario's speed; "
                             f"the scenario {self.scenario_file or 'text'} sets its own (its 'speed' lines): edit "
                             "them, or scale its pace with operator.speed_scale")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"operator.seed must be an integer >= 0, got {self.seed!r}")
        try:
            self.build_scenario()
        except ScenarioError as e:
            raise ValueError(str(e)) from None

    def design_scenario(self) -> Scenario:
        """The scenario as designed (the file's text, else the built-in): its driver is the
        design value a nominal rig believes."""
        if self.scenario_text:
            return parse_scenario(self.scenario_text, self.scenario_file or "scenario_text")
        return builtin_scenario(self.scenario, self.speed_mm_s, self.seed)

    def build_scenario(self) -> Scenario:
        """The scenario the operator truly performs: the design, with the true driver tip
        (``driver_error_mm`` added)."""
        s = self.design_scenario()
        if s.driver_mm is None or not any(self.driver_error_mm):
            return s
        return dataclasses.replace(s, driver_mm=tuple(float(a + b) for a, b in zip(s.driver_mm, self.driver_error_mm,
                                                                                     strict=True)))

    def hand_tremor(self) -> TremorModel | None:
        """The operator's tremor (None when off)."""
        if not (self.tremor_mm or self.tremor_deg):
            return None
        return TremorModel(Tremor(self.tremor_mm, self.tremor_deg, self.seed), HAND_TREMOR_STREAM)

    @property
    def tick_period_ns(self) -> int:
        return round(1e9 / self.rate_hz)
