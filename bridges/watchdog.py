"""Command watchdog on simulated time: notices when commands stop and when they resume."""

from __future__ import annotations


class CommandWatchdog:
    """Trips once when no command arrived for longer than `timeout_s` of simulated time.

    The clock is whatever `advance(t)` was last given; a command noted before the first
    `advance` counts as arriving at that first instant.
    """

    def __init__(self, timeout_s: float) -> None:
        if not timeout_s > 0:
            raise ValueError(f"command timeout must be positive, got {timeout_s}")
        self.timeout_s = float(timeout_s)
        self.tripped = False
        self._now: float | None = None
        self._last_command: float | None = None

    def restart(self) -> None:
        """Forget the clock, e.g. when simulated time starts over for a new episode."""
        self.tripped = False
        self._now = self._last_command = None

    def note_command(self) -> float | None:
        """Record a command now; if that ends a trip, return how long the silence lasted."""
        silence = None
        if self.tripped:
            self.tripped = False
            silence = self.silence_s()
        self._last_command = self._now
        return silence

    def advance(self, t: float) -> bool:
        """Move the clock to `t`; True exactly when this trips the watchdog."""
        self._now = t
        if self._last_command is None:
            self._last_command = t
        if self.tripped or self.silence_s() <= self.timeout_s:
            return False
        self.tripped = True
        return True

    def silence_s(self) -> float:
        if self._now is None or self._last_command is None:
            return 0.0
        return self._now - self._last_command
