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


class HoldsTheGil(FailsAt):
    """Loops in C without ever returning to the interpreter: no signal can interrupt it."""

    def fail(self) -> None:
        sum(range(10**15))


class Swallows(FailsAt):
    """Loops forever, swallowing every Exception (a timeout must still end it)."""

    def fail(self) -> None:
        while True:
            try:  # noqa: SIM105 - written as a user writes it
                time.sleep(0.01)
            except Exception:
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


class Watchful:
    """Reads everything an observation has, as a user's controller would: follows the route
    from ``waypoints_reached``, turns from the nearest tracked robot, backs off when stalled,
    smooths its speed, and clips its scan in place (its own copy, whichever path calls it)."""

    def __init__(self) -> None:
        self.waypoints: list[list[float]] = []
        self.v = 0.0
        self.scans = 0
        self.shared_scans = 0
        self._last: Any = None

    def reset(self, info: dict[str, Any]) -> None:
        self.waypoints = info["waypoints"]
        self.limit = info["max_speed_m_s"]

    def act(self, obs: Any) -> tuple[float, float]:
        import math

        import numpy as np

        self.scans += 1
        self.shared_scans += obs.ranges is self._last
        self._last = obs.ranges
        np.minimum(obs.ranges, 4.0, out=obs.ranges)
        x, y, heading = obs.pose
        if obs.waypoints_reached >= len(self.waypoints):
            return 0.0, 0.0
        gx, gy = self.waypoints[obs.waypoints_reached]
        turn = math.remainder(math.atan2(gy - y, gx - x) - heading, math.tau)
        for track in obs.tracks:
            tx, ty = track["position"]
            if math.hypot(tx - x, ty - y) < 2.0:
                turn -= 0.3 * math.copysign(
                    1.0, math.remainder(math.atan2(ty - y, tx - x) - heading, math.tau)
                )
        ahead = float(np.min(obs.ranges[np.abs(obs.angles) < 0.4]))
        target = -0.1 if obs.stalled else min(self.limit, 0.2 * ahead) * max(0.0, math.cos(turn))
        self.v += 0.5 * (target - self.v) + 0.01 * obs.velocity[1]
        return self.v, 1.2 * turn


class TellsParams:
    """Fails at once, saying what it was made with and told: its keyword arguments and the
    reset info's ``params``."""

    def __init__(self, **params: float) -> None:
        self.params = params

    def reset(self, info: dict[str, Any]) -> None:
        told = ", ".join(f"{k}={v}" for k, v in sorted(info["params"].items()))
        made = ", ".join(f"{k}={v}" for k, v in sorted(self.params.items()))
        raise RuntimeError(f"made with {made}; told {told}")

    def act(self, obs: Any) -> tuple[float, float]:
        return 0.0, 0.0


class SaysItsRadius(Forward):
    """Raises with the waypoint radius and the near-miss distance it was told."""

    def act(self, obs: Any) -> tuple[float, float]:
        radius, near = self.info["waypoint_radius_m"], self.info["monitor"]["unsafe_proximity_m"]
        raise ValueError(f"told {radius} m, near miss within {near} m")


class Orbits(Forward):
    """Drives to its first waypoint, then circles it at about a metre and never reaches it: a
    planner that cannot turn tightly enough."""

    def act(self, obs: Any) -> tuple[float, float]:
        import math

        x, y, heading = obs.pose
        gx, gy = self.info["waypoints"][0]
        distance, bearing = math.hypot(gx - x, gy - y), math.atan2(gy - y, gx - x)
        # Tangent to the circle of 1 m about the waypoint, pulled back onto it.
        wanted = bearing if distance > 1.5 else bearing + math.pi / 2 - 0.5 * (distance - 1.0)
        turn = math.atan2(math.sin(wanted - heading), math.cos(wanted - heading))
        return 0.3, max(-1.0, min(1.0, 2.0 * turn))
