"""Rate-limited events: the first occurrence goes out at once, repeats at most once per
interval with a count of what was held back. Pure (times are given, never read)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class EventLimiter:
    """Per-code rate limit. ``allow(code, t_ns)`` -> None (suppress) or the number of
    occurrences suppressed since the last one let through (0 for a fresh one)."""

    interval_ns: int
    _last_ns: dict[str, int] = field(default_factory=dict)
    _held: dict[str, int] = field(default_factory=dict)

    def allow(self, code: str, t_ns: int) -> int | None:
        last = self._last_ns.get(code)
        if last is not None and t_ns - last < self.interval_ns:
            self._held[code] = self._held.get(code, 0) + 1
            return None
        self._last_ns[code] = t_ns
        return self._held.pop(code, 0)

    def reset(self, code: str) -> None:
        """Forget ``code`` (an episode ended): its next occurrence goes out at once."""
        self._last_ns.pop(code, None)
        self._held.pop(code, None)


def suffix(held: int) -> str:
    return f" (+{held} more since the last report)" if held else ""
