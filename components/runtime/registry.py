"""Which components exist: name -> core class, imported lazily."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the registry itself loads no core (``humanpt --help`` reads it)
    from humanpt.runtime.core import Core

# name -> "module:Class".  A component appears here once its core exists.
COMPONENTS: dict[str, str] = {
    "pinger": "humanpt.runtime.selftest:PingerCore",
    "ponger": "humanpt.runtime.selftest:PongerCore",
    "perception": "humanpt.perception.core:PerceptionCore",
    "pose_filter": "humanpt.pose_filter.core:PoseFilterCore",
    "controller": "humanpt.controller.core:ControllerCore",
    "robot_gateway": "humanpt.robot_gateway.core:GatewayCore",
    "sim_robot": "humanpt.sim_robot.core:SimRobotCore",
    "camera": "humanpt.camera.core:CameraCore",
    "sim_camera": "humanpt.sim_camera.core:SimCameraCore",
    "operator": "humanpt.operator.core:OperatorCore",
    "standin_robot": "humanpt.twin.standin:StandInRobotCore",
    "viz": "humanpt.viz.core:VizCore",
    "scene": "humanpt.scene.core:SceneCore",
    "foxglove_bridge": "humanpt.foxglove_bridge.core:FoxgloveBridgeCore",
}

# name -> "module:Class" of its config dataclass (the core's ``config_type``; a test checks
# they agree).  Validating a config file checks every section but imports only these light
# modules, not the cores: the server's install (requirements/server.txt: no OpenCV, rerun,
# filterpy, Foxglove SDK) reads a cell.toml that holds the client's sections too.
CONFIGS: dict[str, str] = {
    "pinger": "humanpt.runtime.selftest:PingerConfig",
    "ponger": "humanpt.runtime.selftest:PongerConfig",
    "perception": "humanpt.perception.config:PerceptionConfig",
    "pose_filter": "humanpt.pose_filter.config:PoseFilterConfig",
    "controller": "humanpt.controller.config:ControllerConfig",
    "robot_gateway": "humanpt.robot_gateway.config:GatewayConfig",
    "sim_robot": "humanpt.sim_robot.config:SimRobotConfig",
    "camera": "humanpt.camera.config:CameraConfig",
    "sim_camera": "humanpt.sim_camera.config:SimCameraConfig",
    "operator": "humanpt.operator.config:OperatorConfig",
    "standin_robot": "humanpt.twin.standin:StandInRobotConfig",
    "viz": "humanpt.viz.config:VizConfig",
    "scene": "humanpt.scene.config:SceneConfig",
    "foxglove_bridge": "humanpt.foxglove_bridge.config:FoxgloveBridgeConfig",
}

# name -> "module:function": builds the live shell's adapters (serial ports...) from the
# component's config: ``function(config) -> list[Adapter]``.  Components without local I/O
# are not listed.
ADAPTERS: dict[str, str] = {
    "controller": "humanpt.controller.shell:adapters",
    "robot_gateway": "humanpt.robot_gateway.shell:adapters",
    "sim_robot": "humanpt.sim_robot.shell:adapters",
    "camera": "humanpt.camera.capture:capture_adapters",
    "viz": "humanpt.viz.sink:adapters",
    "foxglove_bridge": "humanpt.foxglove_bridge.server:adapters",
}

# The paper's two machines.  Single-machine use needs no profile ("all").
PROFILES: dict[str, dict] = {
    "server": {"router": True, "components": ("robot_gateway",),
               "doc": "router + the robot gateway (ALTER serial or RSI UDP), beside the robot controller"},
    "client": {"router": False, "components": ("camera", "perception", "pose_filter", "controller", "viz", "scene",
                                              "foxglove_bridge"),
               "doc": "vision and control, connecting to the server's router; the operator's screen in "
                      "Foxglove (foxglove_bridge, loopback)"},
    "twin": {"router": True, "components": ("operator", "standin_robot", "sim_camera"),
             "doc": "router + the digital twin: operator, stand-in robot, simulated PSVS camera"},
    "loop": {"router": True, "components": ("operator", "standin_robot", "sim_camera", "perception", "pose_filter",
                                            "controller", "scene"),
             "doc": "router + the closed loop on the twin with a stand-in robot (the default of `up`; "
                    "`humanpt demo` runs the simulated Puma behind the ALTER link)"},
    "selftest": {"router": True, "components": ("pinger", "ponger"),
                 "doc": "router + two self-test components exchanging pings"},
}


class UnknownComponentError(KeyError):
    def __str__(self) -> str:
        return self.args[0]


def import_path(path: str) -> type:
    """Import ``"module:Attr"``."""
    module, _, attr = path.partition(":")
    return getattr(importlib.import_module(module), attr)


def core_class(name: str) -> type[Core]:
    """The core class of component ``name`` (or its old name, ``RENAMED_COMPONENTS``)."""
    from humanpt.runtime.config import current_name  # (the registry loads lightly: humanpt --help)

    name = current_name(name)
    if name not in COMPONENTS:
        raise UnknownComponentError(
            f"no component {name!r} in this version; available: {', '.join(sorted(COMPONENTS))}")
    return import_path(COMPONENTS[name])


def adapters_for(name: str, config, run_dir=None, rig=None, config_file=None) -> list:
    """The live-shell adapters of component ``name`` (empty for most components).

    A factory that takes a ``run_dir`` keyword gets the run directory (to write files
    beside the recordings), one that takes ``rig`` the cell's rig, one that takes
    ``config_file`` the loaded config file (the cell, its session: the Foxglove bridge's
    requests)."""
    from humanpt.runtime.config import current_name

    path = ADAPTERS.get(current_name(name))
    if not path:
        return []
    import inspect

    factory = import_path(path)
    params = inspect.signature(factory).parameters
    kwargs = {k: v for k, v in (("run_dir", run_dir), ("rig", rig), ("config_file", config_file)) if k in params}
    return factory(config, **kwargs)


def config_types() -> dict[str, type]:
    """Component name -> config dataclass, for validating a whole config file (imports the
    config modules only, :data:`CONFIGS`)."""
    return {name: import_path(CONFIGS[name]) for name in COMPONENTS}


def class_path(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"
