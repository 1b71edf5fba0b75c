"""Rate-limited events, shared by the cores that report per cycle (the robot gateway, the
simulated robots, the pose filter): the first occurrence goes out at once, repeats at most
once per interval with a count of what was held back. Pure (times are given, never read).
And what both ends of a robot link share (:class:`SerialLinkCoreMixin`)."""

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

    def shift(self, step_ns: int) -> None:
        """Move the times kept by ``step_ns`` (the wall clock stepped: runtime/clock.py)."""
        self._last_ns = {code: t + step_ns for code, t in self._last_ns.items()}

    def reset(self, code: str) -> None:
        """Forget ``code`` (an episode ended): its next occurrence goes out at once."""
        self._last_ns.pop(code, None)
        self._held.pop(code, None)


def suffix(held: int) -> str:
    return f" (+{held} more since the last report)" if held else ""


class SerialLinkCoreMixin:
    """What both ends of a robot link share (robot_gateway and sim_robot cores): bytes to
    send gathered in ``self._tx`` go out as one ``serial_tx`` chunk per step (a core may
    send on its link's topic instead: ``_flush_tx``), and events are rate-limited by
    ``self._limiter``.

    Their port handlers take ``(t_ns, msg, outs)`` and append to ``outs``; every input
    (parameters aside) starts with :meth:`_begin` and ends by sending what it wrote."""

    def _bind(self, port):
        handler = getattr(self, port.handler)
        if port.topic == "param":
            return handler

        def step(t_ns: int, msg) -> list:
            outs = self._begin(t_ns)
            handler(t_ns, msg, outs)
            self._flush_tx(t_ns, outs)
            return outs

        return step

    def _begin(self, t_ns: int) -> list:
        """The outputs list of a step (a core may start its link here)."""
        return []

    def _flush_tx(self, t_ns: int, outs: list) -> None:
        if self._tx:
            from humanpt.schemas import humanpt_pb2 as pb

            outs.append(("serial_tx", pb.SerialChunk(header=self.next_header("serial_tx", t_ns, "alter"),
                                                     data=bytes(self._tx), outgoing=True)))
            self._tx.clear()

    def _ev(self, outs: list, t_ns: int, severity: int, code: str, text: str, limited: bool = True) -> None:
        if limited:
            held = self._limiter.allow(code, t_ns)
            if held is None:
                return
            text += suffix(held)
        outs.append(self.event(t_ns, severity, code, text))
