"""robot_gateway configuration (the ``[robot_gateway]`` section)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np

from humanpt.robot_gateway.links import DEFAULT_LINK, UnknownLinkError, config_type
from humanpt.runtime import cell_limits
from humanpt.runtime.config import Deg, Mm, Range, RateDegS, SpeedMmS, live


@dataclass(frozen=True)
class GatewayConfig:
    """The gateway's safety rules, whatever its link: cycle, limits, envelope, watchdogs.

    A gateway's config is its link's (``links.<name>.config``): this class plus the link's
    own fields (a serial port, a UDP address) and its defaults for the cycle and timers;
    ``[robot_gateway] link`` chooses it (:meth:`config_class_for`, ``links.LINKS``).

    Lengths in mm, angles in degrees (what a person edits); the envelope is an
    axis-aligned box in the world frame. ``world_T_base_mm_deg`` places the robot base
    (the controller's "world" for ALTER) in the world: x, y, z mm, yaw, pitch, roll deg
    (Z-Y-X); identity by default, as in the paper (world frame at the robot base).
    """

    # The link's cycle: what the robot sends every cycle and expects an answer to. It is the
    # cell's only cycle: every RobotState carries it (cycle_period_ns) to the controller, the
    # pose filter and viz; the launcher gives it to the simulated robot (runtime/cycle.py).
    cycle_period_ms: Annotated[float, Range(1, 1000, "ms")] = 28.0
    # Gateway timer: link timers, reply deadline, silence watchdog are checked this often.
    tick_ms: Annotated[float, Range(0.1, 1000, "ms")] = 2.0
    # Per-cycle limits = speed x cycle period (100 mm/s, 60 deg/s -> 2.8 mm, 1.68 deg).
    # The limits, envelope and watchdogs are hard limits: the values in the config file at
    # start; at run time (`humanpt param`) they may only become stricter.
    max_speed_mm_s: SpeedMmS = live(
        cell_limits.MAX_SPEED_MM_S, "translation limit, mm/s (clamped by norm)", stricter="lower")
    max_angular_speed_deg_s: RateDegS = live(
        cell_limits.MAX_ANGULAR_SPEED_DEG_S, "rotation limit, deg/s (clamped by angle)", stricter="lower")
    envelope_min_mm: tuple[Mm, Mm, Mm] = live(
        cell_limits.ENVELOPE_MIN_MM, "workspace box, world frame, lower corner (mm)",
        stricter="higher")
    envelope_max_mm: tuple[Mm, Mm, Mm] = live(
        cell_limits.ENVELOPE_MAX_MM, "workspace box, world frame, upper corner (mm)",
        stricter="lower")
    # A command older than this many cycles is stale: the gateway sends zero (HOLD).
    stale_cycles: Annotated[int, Range(0, 100, "cycles")] = live(
        3, "cycles a command may be reused before it is stale", stricter="lower")
    # This many consecutive missed cycles (no fresh command, correction late at the robot,
    # statuses lost) raise a fault: HOLD, and ALTER off if alter_off_on_fault.
    fault_after_missed: Annotated[int, Range(1, 10000, "cycles")] = live(
        10, "consecutive missed cycles that raise a fault", stricter="lower")
    alter_off_on_fault: bool = True
    # After a STATUS, wait at most this long for the command of its cycle before answering
    # with the freshest one (38 400 baud leaves ~9.8 ms of host slack in a 28 ms cycle).
    reply_deadline_ms: Annotated[float, Range(0.01, 1000, "ms")] = 6.0
    # No STATUS for this many cycles while the link is up: link_down event (silence).
    status_timeout_cycles: Annotated[int, Range(1, 1000, "cycles")] = 3
    # Subtracted from the receive time to stamp robot_state (the pose's sample time);
    # 0: stamp = receive time. On a real 38 400 baud line a STATUS takes 10.7 ms.
    status_delay_ms: Annotated[float, Range(0, 1000, "ms")] = 0.0
    world_T_base_mm_deg: tuple[Mm, Mm, Mm, Deg, Deg, Deg] = (0.0,) * 6
    # Repeated safety events of one code are rate-limited to one per interval.
    event_interval_ms: Annotated[float, Range(0, 3600000, "ms")] = 1000.0
    # A command's stamp is the stamp of the robot_state it answers (gateway time, + one
    # cycle per cycle ahead); one further off than this is not the controller's answer to
    # this gateway's cycle (forged, replayed, another cell's): dropped (stamp_mismatch).
    stamp_tolerance_ms: Annotated[float, Range(0.1, 1000, "ms")] = 50.0
    # A second command stream (header.seq not continuing the bound controller session's:
    # a second controller session, a replay, a forger) holds the robot for this long after
    # its last command (controller_conflict).
    conflict_hold_ms: Annotated[float, Range(0, 60000, "ms")] = 500.0
    # The link to the robot controller: "alter" (the Puma's serial ALTER line) or "rsi" (a
    # KUKA RSI-style UDP link), one of links.LINKS; each adds its own keys to this section
    # (links/<name>/config.py). Component name, topics and rules are the same.
    link: str = DEFAULT_LINK
    # The largest step per cycle the link's wire can carry (mm or deg); None: no limit.
    wire_max_per_cycle: ClassVar[float | None] = None

    @classmethod
    def config_class_for(cls, table) -> type:
        """The config class of a ``[robot_gateway]`` table: its link's (``link``, default
        "alter"), from the registry (runtime.config.build calls this)."""
        if cls is not GatewayConfig:
            return cls
        try:
            return config_type(table.get("link", DEFAULT_LINK))
        except UnknownLinkError:
            return cls  # (its __post_init__ names the known links)

    def __post_init__(self) -> None:
        own = config_type(self.link)  # (UnknownLinkError, a ValueError, for a link not registered)
        if type(self) is not own:
            raise ValueError(f"link {self.link!r} takes {own.__module__}.{own.__qualname__}, "
                             f"not {type(self).__qualname__}")
        if not 1.0 <= self.cycle_period_ms <= 1000.0:
            raise ValueError(
                f"cycle_period_ms must be within 1 and 1000, got {self.cycle_period_ms}"
            )
        if not 0.1 <= self.tick_ms <= self.cycle_period_ms:
            raise ValueError(f"tick_ms must be within 0.1 and cycle_period_ms, got {self.tick_ms}")
        if not 0.0 < self.reply_deadline_ms < self.cycle_period_ms:
            raise ValueError(
                f"reply_deadline_ms must be > 0 and shorter than the cycle, got {self.reply_deadline_ms}"
            )
        cycle_s = self.cycle_period_ms / 1000.0
        for name, value in (
            ("max_speed_mm_s", self.max_speed_mm_s),
            ("max_angular_speed_deg_s", self.max_angular_speed_deg_s),
        ):
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be > 0, got {value}")
            wire = self.wire_max_per_cycle
            if wire is not None and value * cycle_s > wire:
                raise ValueError(f"{name} = {value} exceeds the wire range ({wire} per cycle)")
        lo, hi = np.asarray(self.envelope_min_mm, float), np.asarray(self.envelope_max_mm, float)
        if (
            lo.shape != (3,)
            or hi.shape != (3,)
            or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)))
        ):
            raise ValueError("envelope_min_mm and envelope_max_mm need three finite values each")
        if np.any(lo >= hi):
            raise ValueError(
                f"envelope_min_mm {self.envelope_min_mm} must be below envelope_max_mm "
                f"{self.envelope_max_mm} on every axis"
            )
        if not 0 <= self.stale_cycles <= 100:
            raise ValueError(f"stale_cycles must be within 0 and 100, got {self.stale_cycles}")
        if not 1 <= self.fault_after_missed <= 10_000:
            raise ValueError(
                f"fault_after_missed must be within 1 and 10000, got {self.fault_after_missed}"
            )
        if not 1 <= self.status_timeout_cycles <= 1000:
            raise ValueError(
                f"status_timeout_cycles must be within 1 and 1000, got {self.status_timeout_cycles}"
            )
        if not 0.0 <= self.status_delay_ms < self.cycle_period_ms:
            raise ValueError(
                f"status_delay_ms must be within 0 and the cycle, got {self.status_delay_ms}"
            )
        if len(self.world_T_base_mm_deg) != 6 or not np.all(np.isfinite(self.world_T_base_mm_deg)):
            raise ValueError(
                "world_T_base_mm_deg needs six finite values (x, y, z mm, yaw, pitch, roll deg)"
            )
        for name in ("stamp_tolerance_ms", "conflict_hold_ms"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be a finite value >= 0, got {v}")
        if self.event_interval_ms < 0:
            raise ValueError(f"event_interval_ms must be >= 0, got {self.event_interval_ms}")

    # -- derived, in the units the core uses ------------------------------------------
    @property
    def cycle_period_ns(self) -> int:
        return round(self.cycle_period_ms * 1e6)

    @property
    def tick_period_ns(self) -> int:
        return round(self.tick_ms * 1e6)

    @property
    def max_step_mm(self) -> float:
        """Per-cycle translation limit (norm), mm."""
        return self.max_speed_mm_s * self.cycle_period_ms / 1000.0

    @property
    def max_step_deg(self) -> float:
        """Per-cycle rotation limit (angle), degrees."""
        return self.max_angular_speed_deg_s * self.cycle_period_ms / 1000.0
