"""The simulator from Python: drive robots of a situation step by step.

``world = sitgen.World(situation)``; ``world.observe(0)`` gives the agent's laser scan (numpy),
pose, velocity, stall flag and time; ``world.step({0: (v, omega)})`` advances one step
(0.1 s by default); ``world.state()`` reads every robot. Enough to drive a robot from a
notebook, or to wrap in a Gymnasium environment.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.world.situation import Situation


@dataclass(frozen=True)
class Observation:
    """What a robot senses at one instant."""

    ranges: npt.NDArray[np.float64]
    """Laser ranges, metres, one per beam (empty for robots without a laser)."""
    angles: npt.NDArray[np.float64]
    """Beam bearings relative to the heading, radians."""
    pose: tuple[float, float, float]
    """(x m, y m, heading rad)."""
    velocity: tuple[float, float]
    """(v m/s, omega rad/s)."""
    stalled: bool
    """Whether the last move was blocked."""
    time: float
    """Simulated time, seconds."""
    max_range: float = 10.0
    """The laser's maximum range, metres: a beam that hits nothing reads exactly this."""
    tracks: tuple[dict[str, Any], ...] = ()
    """The other robots the laser sees now: ``id``, ``position`` (x, y), ``velocity``
    (vx, vy) in the world frame; standing in for a perception module."""
    waypoints_reached: int = 0
    """Waypoints of the route reached so far, in order, as the monitor counts them: the index
    (into the route's waypoints) of the current one, for controllers in a run."""


class World:
    """A running world built from a situation."""

    def __init__(
        self,
        situation: Situation | str | Path,
        sim: Mapping[str, Any] | None = None,
        seed: int = 0,
    ) -> None:
        """``situation``: a Situation or a situation file; ``sim``: simulator settings
        (``dt_s``, ``max_speed_m_s``, ``max_turn_rate_deg_s``, ``max_accel_m_s2``,
        ``max_turn_accel_deg_s2``, ``laser``: {``fov_deg``, ``beams``, ``range_m``,
        ``range_step_m``, ``offset_x_m``, ``noise_sd_m``}); ``seed``: sensor noise."""
        if not isinstance(situation, Situation):
            situation = Situation.load(situation)
        self.situation = situation
        self._world = _core.World(situation.to_json(), json.dumps(dict(sim or {})), seed)

    @property
    def time(self) -> float:
        """Simulated time, seconds."""
        return self._world.time

    @property
    def steps(self) -> int:
        """Steps taken."""
        return self._world.steps

    def observe(self, robot_id: int) -> Observation:
        """What robot ``robot_id`` senses now."""
        o = self._world.observe(robot_id)
        o["tracks"] = tuple(o["tracks"])
        return Observation(**o)

    def step(self, commands: Mapping[int, tuple[float, float]] | None = None) -> None:
        """Advance one step; ``commands`` maps robot id to (v, omega) and replaces the robots'
        latched commands (a robot without one keeps its last)."""
        self._world.step(list((commands or {}).items()))

    def advance(self, steps: int) -> None:
        """Advance ``steps`` steps on the latched commands, scanning the agent's laser each
        step, with the GIL released (for benchmarks and bulk stepping)."""
        self._world.advance(steps)

    def state(self) -> list[dict[str, Any]]:
        """Every robot: id, role, pose, velocity, command, stalled, contacts ("wall" or ids)."""
        return self._world.state()
