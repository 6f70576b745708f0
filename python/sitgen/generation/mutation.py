"""Situation operators: small, local changes to a situation itself, for a search that keeps what
its parent failed at and varies how.

What it does: :func:`mutate` makes a child situation from a parent by one operator, drawn from
:data:`OPERATORS`, aimed where the parent's failure began (its ``failure_at`` pose, and the
peer whose route passes nearest it):

- ``move_peer``: the peer's start moves by N(0, ``MOVE_SD_M``) in x and y;
- ``turn_peer``: its start heading turns by ±U(``TURN_MIN_RAD``, ``TURN_MAX_RAD``);
- ``retime_peer``: it starts up to ``RETIME_M`` earlier or later along its first leg, facing
  along it — for a peer that drives at constant speed the same as starting that much earlier or
  later (situations have no start delay; this is one that needs none);
- ``peer_speed``: its cruising speed (``speed_m_s``) scales by U(0.6, 1.5), within
  [0.1, 1.5] m/s;
- ``shift_waypoint``, ``insert_waypoint``, ``delete_waypoint``: a waypoint of the agent's route
  or the peer's moves by N(0, ``WAYPOINT_SD_M``), a new one goes in mid-leg (moved as much), or
  one goes (a route keeps one at least);
- ``add_obstacle``: a disc of radius U(0.2, 0.6) m near the failure (N(0, ``NEAR_SD_M``));
- ``remove_obstacle``, ``move_obstacle``: the obstacle (8-connected component of at most
  ``BLOB_MAX_CELLS`` cells) nearest the failure goes, or moves by N(0, ``MOVE_SD_M``);
- ``mirror``: the whole situation mirrored left to right, so a crossing from the left becomes
  one from the right.

Every child is checked as a shrink's candidates are (the core's ``shrink_check``: a valid
situation, every robot starting clear, peer legs clear on the dilated map); an operator that
cannot make a valid child in ``TRIES`` draws gives None, and the search draws afresh.

Why: varying a campaign spec's parameters and seeds redraws the whole situation, so a child
keeps its parent's failure class only 16-19 % of the time (``make bench-search``); an operator
on the situation leaves the rest of the encounter as it was. Sources: the situation operators of
search-based testing of automated vehicles (e.g. Gambi et al., AsFault; Riccio & Tonella,
DeepJanus' local mutations of the input) applied to sitgen's situations.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from sitgen import _core
from sitgen.world.situation import Situation

OPERATORS = (
    "move_peer",
    "turn_peer",
    "retime_peer",
    "peer_speed",
    "shift_waypoint",
    "insert_waypoint",
    "delete_waypoint",
    "add_obstacle",
    "remove_obstacle",
    "move_obstacle",
    "mirror",
)
PEER_OPERATORS = ("move_peer", "turn_peer", "retime_peer", "peer_speed")
MOVE_SD_M = 0.5
TURN_MIN_RAD, TURN_MAX_RAD = 0.15, 0.6
RETIME_M = 1.5
WAYPOINT_SD_M = 0.7
NEAR_SD_M = 1.5
BLOB_MAX_CELLS = 2500
"""Largest obstacle a remove or move takes whole (25 m² at 0.1 m cells): a larger one is
terrain, not an obstacle near the failure."""
TRIES = 8
SPEED_RANGE = (0.1, 1.5)


@dataclass(frozen=True)
class Parent:
    """What an operator needs of a parent: its situation and where its failure began."""

    situation: Situation
    failure_pose: tuple[float, float, float] | None
    """The agent's pose at the start of the failure (None: the run did not fail)."""
    with_peer: bool
    """Whether a peer took part in the failure (its failure cell names one)."""

    @staticmethod
    def of(situation: Situation, coverage: dict[str, Any] | None) -> Parent:
        """``situation`` as a parent, with where its run failed from the run's coverage record
        (``failure_at``, ``failure_cell``)."""
        coverage = coverage or {}
        at = coverage.get("failure_at")
        pose = (
            None
            if at is None
            else (float(at["pose"][0]), float(at["pose"][1]), float(at["pose"][2]))
        )
        return Parent(situation, pose, bool(coverage.get("failure_cell")))


def mutate(parent: Parent, operator: str, rng: np.random.Generator) -> str | None:
    """A valid child of ``parent`` by ``operator`` (situation JSON), or None if none of
    :data:`TRIES` draws made a valid one."""
    data = json.loads(parent.situation.to_json())
    robots: list[dict[str, Any]] = data["robots"]
    grid = parent.situation.grid
    occupied = np.ascontiguousarray(grid.occupied, dtype=bool)
    focus = _focus(parent, robots, rng)
    margin = _core.shrink_leg_margin(parent.situation.to_json())
    for _ in range(TRIES):
        changed = _apply(
            operator, copy.deepcopy(robots), occupied, grid.resolution, focus, parent, rng
        )
        if changed is None:
            return None
        new_robots, new_occupied = changed
        child = _core.mutated_situation(
            parent.situation.to_json(), new_occupied, grid.resolution, json.dumps(new_robots)
        )
        if _core.shrink_check(child, margin) is None:
            return child
    return None


def _focus(
    parent: Parent, robots: list[dict[str, Any]], rng: np.random.Generator
) -> tuple[float, float]:
    """Where the failure began, or (no failure) a point of the agent's route."""
    if parent.failure_pose is not None:
        return parent.failure_pose[0], parent.failure_pose[1]
    route = _route(robots[0])
    x, y = route[int(rng.integers(len(route)))]
    return x, y


def _route(robot: dict[str, Any]) -> list[tuple[float, float]]:
    start = robot["start"]
    return [(start["x_m"], start["y_m"]), *((float(x), float(y)) for x, y in robot["waypoints"])]


def _segment_distance(
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
    best, nearest = None, math.inf
    for i, robot in enumerate(robots[1:], start=1):
        route = _route(robot)
        d = min(
            (_segment_distance(focus, a, b) for a, b in itertools.pairwise(route)),
            default=math.hypot(focus[0] - route[0][0], focus[1] - route[0][1]),
        )
        if d < nearest:
            best, nearest = i, d
    return best


def _apply(
    operator: str,
    robots: list[dict[str, Any]],
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    focus: tuple[float, float],
    parent: Parent,
    rng: np.random.Generator,
) -> tuple[list[dict[str, Any]], npt.NDArray[np.bool_]] | None:
    """The operator applied to copies of the robots and the map; None where it does not apply
    (a peer operator without peers, a route too short to lose a waypoint, …)."""
    peer = focus_peer(robots, focus)
    if operator in PEER_OPERATORS and peer is None:
        return None
    if operator == "move_peer":
        assert peer is not None
        start = robots[peer]["start"]
        start["x_m"] += float(rng.normal(0, MOVE_SD_M))
        start["y_m"] += float(rng.normal(0, MOVE_SD_M))
    elif operator == "turn_peer":
        assert peer is not None
        turn = float(rng.uniform(TURN_MIN_RAD, TURN_MAX_RAD)) * (1 if rng.random() < 0.5 else -1)
        start = robots[peer]["start"]
        start["heading_rad"] = math.remainder(start["heading_rad"] + turn, math.tau)
    elif operator == "retime_peer":
        assert peer is not None
        robot = robots[peer]
        (sx, sy), (wx, wy) = _route(robot)[:2]
        heading = math.atan2(wy - sy, wx - sx)
        d = float(rng.uniform(-RETIME_M, RETIME_M))
        robot["start"] = {
            "x_m": sx + d * math.cos(heading),
            "y_m": sy + d * math.sin(heading),
            "heading_rad": heading,
        }
    elif operator == "peer_speed":
        assert peer is not None
        controller = robots[peer]["controller"]
        params = dict(controller.get("params") or {})
        speed = float(params.get("speed_m_s", 0.5)) * float(rng.uniform(0.6, 1.5))
        params["speed_m_s"] = min(SPEED_RANGE[1], max(SPEED_RANGE[0], speed))
        controller["params"] = params
    elif operator in ("shift_waypoint", "insert_waypoint", "delete_waypoint"):
        who = 0 if peer is None or rng.random() < 0.5 else peer
        waypoints = robots[who]["waypoints"]
        if operator == "shift_waypoint":
            k = int(rng.integers(len(waypoints)))
            waypoints[k] = [w + float(rng.normal(0, WAYPOINT_SD_M)) for w in waypoints[k]]
        elif operator == "insert_waypoint":
            route = _route(robots[who])
            k = int(rng.integers(len(route) - 1))
            (ax, ay), (bx, by) = route[k], route[k + 1]
            mid = [
                (ax + bx) / 2 + float(rng.normal(0, WAYPOINT_SD_M)),
                (ay + by) / 2 + float(rng.normal(0, WAYPOINT_SD_M)),
            ]
            waypoints.insert(k, mid)
        else:
            if len(waypoints) < 2:
                return None
            del waypoints[int(rng.integers(len(waypoints)))]
    elif operator == "add_obstacle":
        occupied = occupied.copy()
        cx, cy = (f + float(rng.normal(0, NEAR_SD_M)) for f in focus)
        _disc(occupied, resolution, (cx, cy), float(rng.uniform(0.2, 0.6)), True)
    elif operator in ("remove_obstacle", "move_obstacle"):
        blob = _nearest_blob(occupied, resolution, focus)
        if blob is None:
            return None
        occupied = occupied.copy()
        occupied[blob] = False
        if operator == "move_obstacle":
            shift = [round(float(rng.normal(0, MOVE_SD_M)) / resolution) for _ in range(2)]
            rows, cols = np.nonzero(blob)
            rows, cols = rows - shift[1], cols + shift[0]  # row 0 is north: +y is -row
            inside = (
                (rows >= 0) & (rows < occupied.shape[0]) & (cols >= 0) & (cols < occupied.shape[1])
            )
            occupied[rows[inside], cols[inside]] = True
    elif operator == "mirror":
        width = occupied.shape[1] * resolution
        occupied = np.ascontiguousarray(occupied[:, ::-1])
        for robot in robots:
            start = robot["start"]
            start["x_m"] = width - start["x_m"]
            start["heading_rad"] = math.remainder(math.pi - start["heading_rad"], math.tau)
            robot["waypoints"] = [[width - x, y] for x, y in robot["waypoints"]]
    else:
        raise ValueError(f"unknown situation operator `{operator}`")
    return robots, occupied


def _cell(
    occupied: npt.NDArray[np.bool_], resolution: float, point: tuple[float, float]
) -> tuple[int, int]:
    rows = occupied.shape[0]
    return rows - 1 - int(point[1] / resolution), int(point[0] / resolution)


def _disc(
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    centre: tuple[float, float],
    radius: float,
    value: bool,
) -> None:
    rows, cols = occupied.shape
    r, c = _cell(occupied, resolution, centre)
    k = math.ceil(radius / resolution)
    rr, cc = np.ogrid[max(0, r - k) : min(rows, r + k + 1), max(0, c - k) : min(cols, c + k + 1)]
    inside = (rr - r) ** 2 + (cc - c) ** 2 <= k * k
    occupied[rr, cc] = np.where(inside, value, occupied[rr, cc])


def _nearest_blob(
    occupied: npt.NDArray[np.bool_], resolution: float, focus: tuple[float, float]
) -> npt.NDArray[np.bool_] | None:
    """The mask of the obstacle of at most :data:`BLOB_MAX_CELLS` cells nearest ``focus``
    (within 4 m), or None."""
    r, c = _cell(occupied, resolution, focus)
    k = int(4.0 / resolution)
    rows, cols = occupied.shape
    r0, r1, c0, c1 = max(0, r - k), min(rows, r + k + 1), max(0, c - k), min(cols, c + k + 1)
    labels, _ = ndimage.label(occupied, structure=np.ones((3, 3), dtype=bool))
    window = labels[r0:r1, c0:c1]
    found = np.nonzero(window)
    if not found[0].size:
        return None
    d2 = (found[0] + r0 - r) ** 2 + (found[1] + c0 - c) ** 2
    for i in np.argsort(d2, kind="stable"):
        mask = labels == window[found[0][i], found[1][i]]
        if int(mask.sum()) <= BLOB_MAX_CELLS:
            return np.asarray(mask)
    return None
