"""Where things are in a situation being mutated: map cells and their centres, routes and the
distance to their legs, the peer whose route passes nearest a place, and a child situation
with a new route for the agent. Shared by every operator; no operator of its own.

Units: metres and radians; a map's row 0 is north (its top), as the core's grids are.
"""

from __future__ import annotations

import itertools
import json
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.world.situation import Situation

Edit = tuple[list[dict[str, Any]], npt.NDArray[np.bool_]]
"""An operator's work: the child's robots (situation JSON's) and its map's occupied cells."""


def with_agent_route(child: str, waypoints: list[Any]) -> str:
    """``child`` with the agent driving ``waypoints`` after its start, on the child's map."""
    robots = json.loads(child)["robots"]
    robots[0]["waypoints"] = waypoints
    situation = Situation(child, check_start=False)
    occupied = np.ascontiguousarray(situation.grid.occupied, dtype=bool)
    return _core.mutated_situation(child, occupied, situation.grid.resolution, json.dumps(robots))


def centres(
    shape: tuple[int, ...], resolution: float, r0: int, r1: int, c0: int, c1: int
) -> tuple[slice, slice, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Rows r0..r1 and columns c0..c1 of a map of ``shape`` (row 0 north), with the x and y of
    their cells' centres in metres (the inverse of :func:`cell`)."""
    rr, cc = np.mgrid[r0:r1, c0:c1]
    xs = (cc + 0.5) * resolution
    ys = (shape[0] - rr - 0.5) * resolution
    return slice(r0, r1), slice(c0, c1), xs, ys


def route_of(robot: dict[str, Any]) -> list[tuple[float, float]]:
    start = robot["start"]
    return [(start["x_m"], start["y_m"]), *((float(x), float(y)) for x, y in robot["waypoints"])]


def segment_distance(
    p: tuple[float, float], a: tuple[float, float], b: tuple[float, float]
) -> float:
    ax, ay, bx, by = *a, *b
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / length2))
    return math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy)


def focus_peer(robots: list[dict[str, Any]], focus: tuple[float, float]) -> int | None:
    """The peer (index into ``robots``) whose route passes nearest ``focus``; None without
    peers."""
    nearest = peers_by_distance(robots, focus)
    return nearest[0] if nearest else None


def peers_by_distance(robots: list[dict[str, Any]], focus: tuple[float, float]) -> list[int]:
    """The peers (indices into ``robots``), the one whose route passes nearest ``focus``
    first."""
    distance = {}
    for i, robot in enumerate(robots[1:], start=1):
        route = route_of(robot)
        distance[i] = min(
            (segment_distance(focus, a, b) for a, b in itertools.pairwise(route)),
            default=math.hypot(focus[0] - route[0][0], focus[1] - route[0][1]),
        )
    return sorted(distance, key=lambda i: (distance[i], i))


def cell(
    occupied: npt.NDArray[Any], resolution: float, point: tuple[float, float]
) -> tuple[int, int]:
    rows = occupied.shape[0]
    return rows - 1 - int(point[1] / resolution), int(point[0] / resolution)
