"""A parent of the mutation strategy, and what every child of it is made with.

What it does: :class:`Parent` is what an operator needs of a failing run: its situation,
where and when its failure began (the agent's pose there, from the run's coverage record) and
its variant; :class:`Track` is where its agent drove until then, so that a staged encounter is
timed by where the agent really was. :func:`cut_past_failure` ends a child's mission
:data:`KEPT_PAST` waypoint past the route leg nearest where its parent's failure began, and
:func:`extended` makes the agent's mission go on past its goal (the search's *stretched
mission*).

Why: what the parent drove after its failure cannot change the encounter a child aims at, and
a later, more severe failure there (a run's failure is its most severe class) would hide the
variant the child was made to show; a stretched mission meets what shows only late (a heading
that drifts with the turning done, a long route's bookkeeping).

Parameters: :data:`KEPT_PAST` (1 waypoint), :data:`ARRIVED_M` (0.3 m, how near a point the
agent must have come to have been there), :data:`IN_RANGE_M` (3.5 m, where the coverage
observer starts an encounter), :data:`SPEED_WINDOW_S` (10 s, over which the agent's speed is
read). The continuation is planned by the core as the generator plans a route
(``continued_route``: goals on the dilated map, A*, RDP, until ``min_route_length_m`` long).

Source: sitgen's coverage record (``failure_at``, docs/coverage.md) and mission planner.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.generation.mutation.places import route_of, segment_distance, with_agent_route
from sitgen.triage.variants import variant
from sitgen.world.situation import Situation

IN_RANGE_M = 3.5
"""Distance, centre to centre, at which the coverage observer starts an encounter (its 2 m
footprint clearance and two robots' reach)."""


ARRIVED_M = 0.3
"""How near a point a parent's agent must have come to have been there (:class:`Track`)."""


SPEED_WINDOW_S = 10.0
"""Time over which the agent's speed where it met its parent's failure is measured."""


KEPT_PAST = 1
"""Waypoints a child's mission keeps past the route leg its parent's failure began on
(:func:`cut_past_failure`): enough to drive on through the place, not so many that a later,
more severe failure of a class already found becomes the run's failure and hides the variant
the child was made to show."""


NOT_COMPLETED = "route_not_completed"


@dataclass(frozen=True)
class Parent:
    """What an operator needs of a parent: its situation and where its failure began."""

    situation: Situation
    failure_pose: tuple[float, float, float] | None
    """The agent's pose at the start of the failure (None: the run did not fail)."""
    variant: str | None = None
    """Its failure's variant (``CLASS/INTERACTION/CONTEXT``)."""
    failure_s: float | None = None
    """When its failure began, seconds into the run."""
    track: Track | None = field(default=None, compare=False)
    """Where its agent drove up to where its failure began (None: not known; a staged encounter
    is then timed for :data:`AGENT_M_S`)."""

    @staticmethod
    def of(
        situation: Situation,
        coverage: dict[str, Any] | None,
        failure: dict[str, Any] | None = None,
        trajectory: npt.NDArray[np.floating[Any]] | None = None,
        dt_s: float | None = None,
    ) -> Parent:
        """``situation`` as a parent, with where its run failed from the run's coverage record
        (``failure_at``; ``failure_cell`` for its variant) and when from its failure
        (``class``, ``features.start_s``); ``trajectory`` (the store's: every robot's pose at
        every step, ``dt_s`` apart) gives its agent's track."""
        coverage = coverage or {}
        at = coverage.get("failure_at")
        pose = (
            None
            if at is None
            else (float(at["pose"][0]), float(at["pose"][1]), float(at["pose"][2]))
        )
        failure = failure or {}
        start_s = (failure.get("features") or {}).get("start_s")
        failure_s = None if start_s is None else float(start_s)
        track = None
        if trajectory is not None and dt_s is not None and failure_s is not None and dt_s > 0:
            steps = min(len(trajectory), math.floor(failure_s / dt_s) + 1)
            track = Track(np.asarray(trajectory[:steps, 0, :2], dtype=np.float64), dt_s)
        return Parent(situation, pose, variant(failure.get("class"), coverage), failure_s, track)


@dataclass(frozen=True)
class Track:
    """A parent's agent's positions (x, y, metres) every ``dt_s`` from the start of its run to
    where its failure began: when it came where, so that a staged encounter is timed by where
    the agent really was rather than by a typical speed (it is slowest where it fails: a median
    0.14 m/s over the 20 s before a failure in a search's runs, against a cruising 0.4)."""

    positions: npt.NDArray[np.float64]
    dt_s: float

    def arrival_s(self, point: tuple[float, float]) -> float:
        """When the agent first came within :data:`ARRIVED_M` of ``point`` (or, where it never
        did, when it came nearest)."""
        near = self._distances(point)
        within = np.flatnonzero(near <= ARRIVED_M)
        step = int(within[0]) if within.size else int(np.argmin(near))
        return step * self.dt_s

    def in_range_s(self, point: tuple[float, float], until_s: float) -> float | None:
        """When the agent last came within :data:`IN_RANGE_M` of ``point`` before ``until_s``
        (an encounter ends when the two part, so an earlier pass does not count; None: it
        was not within range by then)."""
        steps = math.floor(until_s / self.dt_s) + 1
        within = self._distances(point)[:steps] <= IN_RANGE_M
        if not within.any():
            return None
        outside = np.flatnonzero(~within[: int(np.flatnonzero(within)[-1]) + 1])
        return float(outside[-1] + 1 if outside.size else 0) * self.dt_s

    def speed_m_s(self, until_s: float) -> float:
        """The agent's mean speed (path length over time) over the :data:`SPEED_WINDOW_S`
        before ``until_s``."""
        last = min(len(self.positions) - 1, math.floor(until_s / self.dt_s))
        first = max(0, last - round(SPEED_WINDOW_S / self.dt_s))
        if last <= first:
            return 0.0
        legs = np.diff(self.positions[first : last + 1], axis=0)
        return float(np.hypot(legs[:, 0], legs[:, 1]).sum()) / ((last - first) * self.dt_s)

    def _distances(self, point: tuple[float, float]) -> npt.NDArray[np.float64]:
        d = self.positions - np.asarray(point, dtype=np.float64)
        return np.asarray(np.hypot(d[:, 0], d[:, 1]), dtype=np.float64)


def extended(child: str, rng: np.random.Generator) -> str:
    """``child`` with the agent's mission going on past its goal (:func:`_core.continued_route`
    from the child's last waypoint, on the child's own map), or ``child`` as it is where no
    route goes on from there."""
    route = _core.continued_route(child, int(rng.integers(2**63)))
    if not route:
        return child
    waypoints = json.loads(child)["robots"][0]["waypoints"]
    return with_agent_route(child, [*waypoints, *([x, y] for x, y in route)])


def cut_past_failure(child: str, parent: Parent) -> str:
    """``child`` with the agent's mission ending :data:`KEPT_PAST` waypoints past the route
    leg nearest where its parent's failure began, or ``child`` as it is where the route ends
    there anyway, or the parent did not fail or failed for not completing its route (a
    failure of the whole mission)."""
    key = parent.variant
    if parent.failure_pose is None or key is None or key.startswith(f"{NOT_COMPLETED}/"):
        return child
    agent = json.loads(child)["robots"][0]
    waypoints, route = agent["waypoints"], route_of(agent)
    place = parent.failure_pose[:2]
    leg = min(range(len(route) - 1), key=lambda i: segment_distance(place, route[i], route[i + 1]))
    # Leg i ends at waypoint i.
    kept = leg + 1 + KEPT_PAST
    if kept >= len(waypoints):
        return child
    return with_agent_route(child, waypoints[:kept])


def focus_of(
    parent: Parent, robots: list[dict[str, Any]], rng: np.random.Generator
) -> tuple[float, float]:
    """Where the failure began, or (no failure) a point of the agent's route."""
    if parent.failure_pose is not None:
        return parent.failure_pose[0], parent.failure_pose[1]
    route = route_of(robots[0])
    x, y = route[int(rng.integers(len(route)))]
    return x, y
