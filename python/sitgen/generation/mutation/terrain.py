"""``reshape_terrain``: the walls round where the parent's failure began redrawn for another
terrain context.

What it does: :func:`reshape_terrain` draws, along the way the agent faced or its route leg
there, one of :data:`CONTEXTS`: two walls along it (``corridor``), a narrow opening across it
(``gap``), walls on three sides (``dead_end``), a wall beside it that ends just ahead
(``blind_corner``), or the walls within a few metres cleared (``open``). The agent's route
points stay :data:`POINT_CLEAR_M` clear; a peer's leg that crosses a new wall gets a doorway as
wide as the leg check needs plus :data:`DOORWAY_SLACK_M`. The core's own classifier
(``agent_context``, :func:`read_at`) must read the target there, or another context the search
accepts, or the caller draws again. ``reshape_and_approach`` (in ``mutate``) redraws the walls
and then stages a peer through the place in them (:mod:`.approach`).

Why: a targeted operator changes one coordinate of the parent's variant (its terrain context)
on purpose; the agent under test is the point, so only its route's points stay clear, while
peers, which avoid nothing, must keep drivable legs.

Parameters: :data:`WALL_M` 0.2 m, :data:`POINT_CLEAR_M` 0.45 m, :data:`DOORWAY_SLACK_M` 0.1 m;
the shapes' sizes (corridor half-width 0.85–1.15 m, gap half-width 0.42–0.6 m, …) in the code.

Source: the terrain contexts of sitgen's coverage space (docs/coverage.md).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.generation.mutation.parent import Parent
from sitgen.generation.mutation.places import Edit, cell, centres, route_of, segment_distance

CONTEXTS = ("open", "corridor", "gap", "dead_end", "blind_corner")
"""Terrain contexts ``reshape_terrain`` can draw (coverage's)."""


WALL_M = 0.2
"""Thickness of a drawn wall."""


DOORWAY_SLACK_M = 0.1
"""How much farther than the leg margin the checks ask for (the mission's ``plan_margin_m``) a
drawn wall keeps from every peer's route legs: where a peer's leg crosses one, the wall has a
doorway just wide enough, so that a narrow gap stays one."""


POINT_CLEAR_M = 0.45
"""A drawn wall keeps this far from the points of the agent's route (a robot's reach)."""


def reshape_terrain(
    robots: list[dict[str, Any]],
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    parent: Parent,
    target: str,
    rng: np.random.Generator,
    doorway: float,
) -> Edit | None:
    """The walls round the failure's place redrawn for terrain context ``target``; robots'
    routes keep their points clear, and new walls keep ``doorway`` (metres) from peers' legs."""
    if parent.failure_pose is None:
        return None
    x, y, facing = parent.failure_pose
    before, occupied = occupied, occupied.copy()
    # Walls along the way the agent was facing when the failure began or along its route there
    # (either; peers' doorways spoil one more often than the other); a blind corner's edge is
    # "ahead" of the way it faced, as the classifier reads it.
    along = _leg_heading(robots[0], (x, y))
    heading = facing if target == "blind_corner" or rng.random() < 0.5 else along
    frame = _Frame(occupied, resolution, (x, y), heading)
    if target == "open":
        frame.disc(float(rng.uniform(2.5, 4.0)), False)
    elif target == "corridor":
        half = float(rng.uniform(0.85, 1.15))
        length = float(rng.uniform(2.0, 4.0))
        frame.box((-length, length), (-half, half), False)
        for s in (-1, 1):
            frame.box((-length, length), _span(s * half, s * (half + WALL_M)), True)
    elif target == "gap":
        half = float(rng.uniform(0.42, 0.6))
        reach = float(rng.uniform(1.5, 3.0))
        frame.disc(1.2, False)
        for s in (-1, 1):
            frame.box((-WALL_M / 2, WALL_M / 2), _span(s * half, s * (half + reach)), True)
    elif target == "dead_end":
        half = float(rng.uniform(0.6, 0.9))
        ahead = float(rng.uniform(0.6, 1.2))
        back = float(rng.uniform(2.0, 3.0))
        frame.box((-back, ahead), (-half, half), False)
        frame.box((ahead, ahead + WALL_M), (-half - WALL_M, half + WALL_M), True)
        for s in (-1, 1):
            frame.box((-back, ahead), _span(s * half, s * (half + WALL_M)), True)
    elif target == "blind_corner":
        s = 1 if rng.random() < 0.5 else -1
        near = float(rng.uniform(0.6, 1.0))
        end = float(rng.uniform(0.1, 0.6))
        frame.box((-3.0, end + 3.0), _span(-s * near, s * near), False)
        frame.box((-3.0, end), _span(s * near, s * (near + 1.5)), True)
    else:
        raise ValueError(f"unknown terrain context `{target}`")
    # The agent is under test: a narrow way along its route is the point, so only its route's
    # points stay clear. Peers avoid nothing: their legs must stay drivable, through a doorway.
    changed = np.nonzero(occupied != before)
    if not changed[0].size:
        return robots, occupied
    window = centres(
        occupied.shape,
        resolution,
        int(changed[0].min()),
        int(changed[0].max()) + 1,
        int(changed[1].min()),
        int(changed[1].max()) + 1,
    )
    for point in route_of(robots[0]):
        _restore_near(occupied, before, window, (point, point), POINT_CLEAR_M)
    for robot in robots[1:]:
        for leg in itertools.pairwise(route_of(robot)):
            _restore_near(occupied, before, window, leg, doorway)
    return robots, occupied


def _restore_near(
    occupied: npt.NDArray[np.bool_],
    before: npt.NDArray[np.bool_],
    window: tuple[slice, slice, npt.NDArray[np.float64], npt.NDArray[np.float64]],
    leg: tuple[tuple[float, float], tuple[float, float]],
    reach: float,
) -> None:
    """Cells of ``window`` (:func:`centres`) within ``reach`` of ``leg`` go back to what they
    were ``before``."""
    rows, cols, px, py = window
    (ax, ay), (bx, by) = leg
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = np.zeros_like(px) if length2 == 0 else ((px - ax) * dx + (py - ay) * dy) / length2
    t = np.clip(t, 0.0, 1.0)
    near = (px - ax - t * dx) ** 2 + (py - ay - t * dy) ** 2 <= reach * reach
    occupied[rows, cols] = np.where(near, before[rows, cols], occupied[rows, cols])


def _span(a: float, b: float) -> tuple[float, float]:
    return min(a, b), max(a, b)


def _leg_heading(robot: dict[str, Any], point: tuple[float, float]) -> float:
    """The heading of the robot's route leg nearest ``point``."""
    route = route_of(robot)
    legs = list(itertools.pairwise(route)) or [(route[0], route[0])]
    a, b = min(legs, key=lambda leg: segment_distance(point, *leg))
    return math.atan2(b[1] - a[1], b[0] - a[0])


def read_at(child: str, parent: Parent) -> str:
    """The terrain context the core reads at the parent's failure pose in ``child``."""
    assert parent.failure_pose is not None
    return str(_core.agent_context(child, *parent.failure_pose))


@dataclass(frozen=True)
class _Frame:
    """The grid seen from a pose: boxes and discs drawn in metres along and across the
    heading."""

    occupied: npt.NDArray[np.bool_]
    resolution: float
    origin: tuple[float, float]
    heading: float

    def _local(self, reach: float) -> tuple[Any, Any, Any, Any]:
        """Window (rows, cols slices) within ``reach`` of the origin, and its cells' centres
        along and across the heading."""
        rows, cols = self.occupied.shape
        r, c = cell(self.occupied, self.resolution, self.origin)
        k = math.ceil(reach / self.resolution) + 1
        r0, r1, c0, c1 = max(0, r - k), min(rows, r + k + 1), max(0, c - k), min(cols, c + k + 1)
        window_rows, window_cols, xs, ys = centres(
            self.occupied.shape, self.resolution, r0, r1, c0, c1
        )
        xs, ys = xs - self.origin[0], ys - self.origin[1]
        cos, sin = math.cos(self.heading), math.sin(self.heading)
        return window_rows, window_cols, xs * cos + ys * sin, -xs * sin + ys * cos

    def box(self, along: tuple[float, float], across: tuple[float, float], value: bool) -> None:
        reach = math.hypot(max(map(abs, along)), max(map(abs, across)))
        rows, cols, u, v = self._local(reach)
        inside = (u >= along[0]) & (u <= along[1]) & (v >= across[0]) & (v <= across[1])
        self.occupied[rows, cols] = np.where(inside, value, self.occupied[rows, cols])

    def disc(self, radius: float, value: bool) -> None:
        rows, cols, u, v = self._local(radius)
        inside = u * u + v * v <= radius * radius
        self.occupied[rows, cols] = np.where(inside, value, self.occupied[rows, cols])
