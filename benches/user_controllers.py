"""Controllers whose own cost is known, for ``make bench`` to time each controller path
against: what a path adds is its time per step less the controller's own."""

from __future__ import annotations

import time
from typing import Any


class Trivial:
    """Drives on at a constant command: its own cost is a method call."""

    def reset(self, info: dict[str, Any]) -> None:
        pass

    def act(self, obs: Any) -> tuple[float, float]:
        return 0.3, 0.1


class Busy:
    """Spends ``BUSY_S`` of computation (a spin on the clock) before the same command, as a
    controller with real work to do; the spin keeps the cost exact on a quiet machine."""

    BUSY_S = 200e-6

    def reset(self, info: dict[str, Any]) -> None:
        pass

    def act(self, obs: Any) -> tuple[float, float]:
        until = time.perf_counter() + self.BUSY_S
        while time.perf_counter() < until:
            pass
        return 0.3, 0.1
