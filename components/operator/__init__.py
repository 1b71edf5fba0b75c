"""The simulated operator: moves the target (TOB) along a scenario and publishes the truth.

``scenario`` is pure (scenario model, text format, trajectory, built-ins); ``core`` is the
component (``humanpt operator``). See ``README.md`` for the scenario file format.
"""

from .config import OperatorConfig
from .core import OperatorCore
from .scenario import (
    BUILTIN_SCENARIOS,
    TABLE1_X_MM_DEG,
    Arc,
    Cover,
    Dwell,
    Line,
    Scenario,
    ScenarioError,
    Trajectory,
    Tremor,
    builtin_scenario,
    format_scenario,
    parse_scenario,
)

__all__ = [
    "BUILTIN_SCENARIOS",
    "TABLE1_X_MM_DEG",
    "Arc",
    "Cover",
    "Dwell",
    "Line",
    "OperatorConfig",
    "OperatorCore",
    "Scenario",
    "ScenarioError",
    "Trajectory",
    "Tremor",
    "builtin_scenario",
    "format_scenario",
    "parse_scenario",
]
