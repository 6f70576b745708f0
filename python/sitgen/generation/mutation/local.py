"""The local operators: one small edit to a situation near where its parent's failure began.

What it does: :func:`apply_local` applies one of them to copies of the robots and the map,
aimed at the focus (where the parent's failure began, or a point of the agent's route) and the
peer whose route passes nearest it:

- ``move_peer``: the peer's start moves by N(0, :data:`MOVE_SD_M`) in x and y;
- ``turn_peer``: its start heading turns by ±U(:data:`TURN_MIN_RAD`, :data:`TURN_MAX_RAD`);
- ``retime_peer``: it starts up to :data:`RETIME_M` earlier or later along its first leg,
  facing along it (for a peer that drives at constant speed, the same as starting that much
  earlier or later);
- ``peer_speed``: its cruising speed (``speed_m_s`` of a built-in that has one,
  ``optimal_speed`` of a navground behaviour: :func:`speed_param`) scales by U(0.6, 1.5),
  within :data:`SPEED_RANGE` (a peer whose controller has no such parameter is left alone);
- ``shift_waypoint``, ``insert_waypoint``, ``delete_waypoint``: a waypoint of the agent's
  route or the peer's moves by N(0, :data:`WAYPOINT_SD_M`), a new one goes in mid-leg (moved
  as much), or one goes (a route keeps one at least);
- ``add_obstacle``: a disc of radius U(0.2, 0.6) m near the focus (N(0, :data:`NEAR_SD_M`));
- ``remove_obstacle``, ``move_obstacle``: the obstacle (8-connected component of at most
  :data:`BLOB_MAX_CELLS` cells) nearest the focus goes, or moves by N(0, :data:`MOVE_SD_M`);
- ``mirror`` (:mod:`.mirror`).

Why: varying a campaign spec's parameters and seeds redraws the whole situation (a child keeps
its parent's class 16–19 % of the time); one edit near the failure leaves the rest of the
encounter as it was. They mostly repeat their parent's variant, so the search draws them as
one arm (``LOCAL``).

Parameters (metres, radians, m/s): :data:`MOVE_SD_M` 0.5, :data:`TURN_MIN_RAD` 0.15,
:data:`TURN_MAX_RAD` 0.6, :data:`RETIME_M` 1.5, :data:`WAYPOINT_SD_M` 0.7, :data:`NEAR_SD_M`
1.5, :data:`BLOB_MAX_CELLS` 2500, :data:`SPEED_RANGE` (0.1, 1.5).

Source: the situation operators of search-based testing of automated vehicles (Gambi et al.,
AsFault; Riccio & Tonella, DeepJanus) applied to sitgen's situations.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen.generation.mutation.mirror import mirrored
from sitgen.generation.mutation.parent import Parent
from sitgen.generation.mutation.places import Edit, cell, focus_peer, route_of

SPEED_PARAMS = {
    "straight": "speed_m_s",
    "follow": "speed_m_s",
    "vo": "speed_m_s",
    "dwa": "speed_m_s",
}
"""The built-in controllers' cruising-speed parameter (m/s)."""


def speed_param(controller: str) -> str | None:
    """The parameter that sets a peer's cruising speed under ``controller`` (m/s), or None
    where it has none (``snd``, a user's class)."""
    if controller.startswith("navground:"):
        return "optimal_speed"
    return SPEED_PARAMS.get(controller)


PEER_OPERATORS = ("move_peer", "turn_peer", "retime_peer", "peer_speed")
"""Local operators on a peer: none applies to a situation without peers (a staged approach
brings one in)."""


MOVE_SD_M = 0.5


TURN_MIN_RAD, TURN_MAX_RAD = 0.15, 0.6


RETIME_M = 1.5


WAYPOINT_SD_M = 0.7


NEAR_SD_M = 1.5


BLOB_MAX_CELLS = 2500
"""Largest obstacle a remove or move takes whole (25 m² at 0.1 m cells): a larger one is
terrain, not an obstacle near the failure."""


SPEED_RANGE = (0.1, 1.5)


def apply_local(
    operator: str,
    robots: list[dict[str, Any]],
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    focus: tuple[float, float],
    parent: Parent,
    rng: np.random.Generator,
) -> Edit | None:
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
        (sx, sy), (wx, wy) = route_of(robot)[:2]
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
        name = speed_param(str(controller.get("name", "")))
        if name is None:
            return None
        params = dict(controller.get("params") or {})
        speed = float(params.get(name, 0.5)) * float(rng.uniform(0.6, 1.5))
        params[name] = min(SPEED_RANGE[1], max(SPEED_RANGE[0], speed))
        controller["params"] = params
    elif operator in ("shift_waypoint", "insert_waypoint", "delete_waypoint"):
        who = 0 if peer is None or rng.random() < 0.5 else peer
        waypoints = robots[who]["waypoints"]
        if operator == "shift_waypoint":
            k = int(rng.integers(len(waypoints)))
            waypoints[k] = [w + float(rng.normal(0, WAYPOINT_SD_M)) for w in waypoints[k]]
        elif operator == "insert_waypoint":
            route = route_of(robots[who])
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
            start["x_m"], _, start["heading_rad"] = mirrored(
                width, start["x_m"], start["y_m"], start["heading_rad"]
            )
            robot["waypoints"] = [[width - x, y] for x, y in robot["waypoints"]]
    else:
        raise ValueError(f"unknown situation operator `{operator}`")
    return robots, occupied


def _disc(
    occupied: npt.NDArray[np.bool_],
    resolution: float,
    centre: tuple[float, float],
    radius: float,
    value: bool,
) -> None:
    rows, cols = occupied.shape
    r, c = cell(occupied, resolution, centre)
    k = math.ceil(radius / resolution)
    rr, cc = np.ogrid[max(0, r - k) : min(rows, r + k + 1), max(0, c - k) : min(cols, c + k + 1)]
    inside = (rr - r) ** 2 + (cc - c) ** 2 <= k * k
    occupied[rr, cc] = np.where(inside, value, occupied[rr, cc])


def _nearest_blob(
    occupied: npt.NDArray[np.bool_], resolution: float, focus: tuple[float, float]
) -> npt.NDArray[np.bool_] | None:
    """The mask of the obstacle of at most :data:`BLOB_MAX_CELLS` cells nearest ``focus``
    (within 4 m), or None."""
    r, c = cell(occupied, resolution, focus)
    k = int(4.0 / resolution)
    rows, cols = occupied.shape
    r0, r1, c0, c1 = max(0, r - k), min(rows, r + k + 1), max(0, c - k), min(cols, c + k + 1)
    # scipy.ndimage takes 0.35 s to import: a command that only reads a search's store (report,
    # failures) does not pay it.
    from scipy import ndimage

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
