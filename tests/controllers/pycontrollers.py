"""Python controllers for the tests: one that drives, and ones that fail in each way."""

from __future__ import annotations

import ctypes
import os
import sys
import time
from typing import Any


class Forward:
    """Drives straight at 0.3 m/s and records what it was given."""

    def __init__(self) -> None:
        self.info: dict[str, Any] = {}
        self.observations: list[Any] = []

    def reset(self, info: dict[str, Any]) -> None:
        self.info = info

    def act(self, obs: Any) -> tuple[float, float]:
        self.observations.append(obs)
        return 0.3, 0.0


class Raises(Forward):
    def act(self, obs: Any) -> tuple[float, float]:
        if obs.time > 0.45:
            raise ValueError("lost track of the goal")
        return 0.3, 0.0


class ReturnsText(Forward):
    def act(self, obs: Any) -> tuple[float, float]:
        return "fast", "left"  # type: ignore[return-value]


class ReturnsNaN(Forward):
    def act(self, obs: Any) -> tuple[float, float]:
        return float("nan"), 0.0


class NoAct:
    def reset(self, info: dict[str, Any]) -> None:
        pass


class FailsAt(Forward):
    """Drives, and from 0.3 s on fails as ``fail`` does."""

    def act(self, obs: Any) -> tuple[float, float]:
        if obs.time > 0.25:
            self.fail()
        return 0.3, 0.0

    def fail(self) -> None:
        raise NotImplementedError


class Hangs(FailsAt):
    def fail(self) -> None:
        while True:
            pass


class Exits(FailsAt):
    def fail(self) -> None:
        sys.exit(0)


class HardExits(FailsAt):
    def fail(self) -> None:
        os._exit(7)


class Segfaults(FailsAt):
    def fail(self) -> None:
        ctypes.string_at(0)


class Prints(Forward):
    """Prints to stdout every step: what it prints must not reach the protocol."""

    def act(self, obs: Any) -> tuple[float, float]:
        print("thinking...", obs.time)
        return 0.3, 0.0


class Slow(Forward):
    """Takes 50 ms a step: a run lasts long enough to be interrupted."""

    def act(self, obs: Any) -> tuple[float, float]:
        time.sleep(0.05)
        return 0.3, 0.0
