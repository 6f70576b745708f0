"""Situation descriptors: what a situation is like, computed from the situation file alone,
before any run (so that a rule learnt from them names something a generator can aim at).
Each is defined in docs/explain.md precisely enough to recompute from a situation file:

- ``route_length_m``: the agent's route, start then waypoints, as a polyline.
- ``route_turns``: its corners that turn by more than 30°.
- ``route_clearance_m``: the least distance from the route (sampled every map cell along
  each leg) to the nearest occupied cell, centre to centre less half a cell: how close the
  route passes walls (a narrow gap reads small; so does a route along one wall).
- ``obstacle_share``: the share of the map's cells that are occupied.
- ``peers``: how many peers.
- ``crossing_peers``: peers whose route (start then waypoints) crosses the agent's.
- ``crossing_angle_deg``: at the first crossing along the agent's route, the angle between
  the two routes' directions, 0 (same way) to 180 (head-on); 0 without a crossing.
- ``conflict_gap_s``: at that crossing, how far apart in time the agent and the peer reach it
  driving their routes at nominal speeds (the agent at ``sim.max_speed_m_s``' half, 0.4 m/s;
  the peer at its controller's ``speed_m_s``, default 0.5 m/s), seconds; 1000 without one.
- ``nearest_peer_start_m``: the nearest peer's start to the agent's route; 1000 without peers.
- ``nominal_closest_m``: the closest any peer's centre comes to the agent's when every robot
  drives its route at its nominal speed (as ``conflict_gap_s``) from time 0, sampled every
  0.1 s until the agent's route ends; a peer at the end of its route stops there (``at_end``
  ``stop``), turns back along it (``reverse``) or goes round it again, start included
  (``loop``); 1000 without peers.
- ``nominal_closest_bearing_deg``: where that peer lies then from the agent's heading (the
  direction of its current leg), 0 (dead ahead) to 180 (behind); 0 without peers.
- ``nominal_closest_clearance_m``: how near the agent's position then is to the nearest
  occupied cell, centre to centre less half a cell (as ``route_clearance_m``); 1000 without
  peers or obstacles.
- ``terrain``: the terrain preset (one-hot in a model).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from scipy import ndimage

from sitgen import _core
from sitgen.store import Store
from sitgen.triage.recall import regenerate, stored_run
from sitgen.world.situation import Situation

AGENT_SPEED_M_S = 0.4
"""The agent's nominal speed for ``conflict_gap_s``."""
PEER_SPEED_M_S = 0.5
"""A peer's nominal speed where its controller names none."""
NONE_M = 1000.0
"""What a distance or time reads without a subject (no crossing, no peer)."""

NUMERIC = (
    "route_length_m",
    "route_turns",
    "route_clearance_m",
    "obstacle_share",
    "peers",
    "crossing_peers",
    "crossing_angle_deg",
    "conflict_gap_s",
    "nearest_peer_start_m",
    "nominal_closest_m",
    "nominal_closest_bearing_deg",
    "nominal_closest_clearance_m",
)

SAMPLE_S = 0.1
"""Time step of the nominal drive (``nominal_closest_m``)."""


Point = tuple[float, float]


def _route(robot: Any) -> list[Point]:
    return [(robot.start.x_m, robot.start.y_m), *((float(x), float(y)) for x, y in robot.waypoints)]


def _crossing(p: Point, q: Point, a: Point, b: Point) -> tuple[float, float] | None:
    """Where segments pq and ab cross, as fractions along each; None if they do not."""
    r = (q[0] - p[0], q[1] - p[1])
    s = (b[0] - a[0], b[1] - a[1])
    denominator = r[0] * s[1] - r[1] * s[0]
    if abs(denominator) < 1e-12:
        return None
    t = ((a[0] - p[0]) * s[1] - (a[1] - p[1]) * s[0]) / denominator
    u = ((a[0] - p[0]) * r[1] - (a[1] - p[1]) * r[0]) / denominator
    return (t, u) if 0 <= t <= 1 and 0 <= u <= 1 else None


def _point_segment(p: Point, a: Point, b: Point) -> float:
    ab = (b[0] - a[0], b[1] - a[1])
    length2 = ab[0] ** 2 + ab[1] ** 2
    t = 0.0 if length2 == 0 else ((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / length2
    t = min(1.0, max(0.0, t))
    return math.dist(p, (a[0] + t * ab[0], a[1] + t * ab[1]))


def _turns(route: list[Point]) -> int:
    turns = 0
    for a, b, c in zip(route, route[1:], route[2:], strict=False):
        h1 = math.atan2(b[1] - a[1], b[0] - a[0])
        h2 = math.atan2(c[1] - b[1], c[0] - b[0])
        if abs(math.remainder(h2 - h1, math.tau)) > math.radians(30):
            turns += 1
    return turns


def _along(route: list[Point], s: np.ndarray, at_end: str) -> tuple[np.ndarray, np.ndarray]:
    """Positions and leg headings at arc lengths ``s`` along ``route`` (start first), past its
    end as ``at_end`` says (``stop``, ``reverse``, ``loop``)."""
    if at_end == "loop" and len(route) > 1:
        route = [*route, route[0]]
    points = np.asarray(route, dtype=float)
    cumulative = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    total = float(cumulative[-1])
    if total <= 0:
        return np.repeat(points[:1], len(s), axis=0), np.zeros(len(s))
    if at_end == "loop":
        s = np.mod(s, total)
    elif at_end == "reverse":
        s = np.mod(s, 2 * total)
        s = np.where(s > total, 2 * total - s, s)
    s = np.clip(s, 0.0, total)
    xy = np.stack([np.interp(s, cumulative, points[:, 0]), np.interp(s, cumulative, points[:, 1])])
    leg = np.clip(np.searchsorted(cumulative, s, side="right") - 1, 0, len(points) - 2)
    d = points[leg + 1] - points[leg]
    return xy.T, np.arctan2(d[:, 1], d[:, 0])


def _nominal_closest(
    situation: Situation, route: list[Point], length: float
) -> tuple[float, float, Point]:
    """``nominal_closest_m``, its bearing, and where the agent is then."""
    peers = situation.robots[1:]
    if not peers:
        return NONE_M, 0.0, route[0]
    t = np.arange(0.0, length / AGENT_SPEED_M_S + SAMPLE_S / 2, SAMPLE_S)
    agent_xy, heading = _along(route, t * AGENT_SPEED_M_S, "stop")
    best = (math.inf, 0.0, route[0])
    for peer in peers:
        speed = float(peer.controller.get("params", {}).get("speed_m_s", PEER_SPEED_M_S))
        xy, _ = _along(_route(peer), t * speed, peer.at_end)
        gap = np.hypot(*(xy - agent_xy).T)
        k = int(np.argmin(gap))
        if gap[k] < best[0]:
            d = xy[k] - agent_xy[k]
            bearing = abs(
                math.degrees(math.remainder(math.atan2(d[1], d[0]) - heading[k], math.tau))
            )
            best = (float(gap[k]), bearing, (float(agent_xy[k][0]), float(agent_xy[k][1])))
    return best


def describe(situation: Situation) -> dict[str, Any]:
    """The descriptors of ``situation`` (docs/explain.md)."""
    grid = situation.grid
    occupied, res = np.asarray(grid.occupied, dtype=bool), float(grid.resolution)
    rows = occupied.shape[0]
    agent, peers = situation.robots[0], situation.robots[1:]
    route = _route(agent)
    legs = list(itertools.pairwise(route))
    lengths = [math.dist(a, b) for a, b in legs]
    # Distance from each free cell centre to the nearest occupied cell centre, metres.
    to_wall = ndimage.distance_transform_edt(~occupied) * res if occupied.any() else None
    least = NONE_M
    if to_wall is not None:
        for (a, b), length in zip(legs, lengths, strict=True):
            for k in range(max(1, int(length / res)) + 1):
                t = k / max(1, int(length / res))
                x, y = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])
                col, row = int(x / res), rows - 1 - int(y / res)
                if 0 <= row < rows and 0 <= col < occupied.shape[1]:
                    least = min(least, float(to_wall[row, col]) - res / 2)
    crossings = []
    for peer in peers:
        peer_route = _route(peer)
        peer_legs = list(itertools.pairwise(peer_route))
        peer_lengths = [math.dist(a, b) for a, b in peer_legs]
        first = None
        for i, (p, q) in enumerate(legs):
            for j, (a, b) in enumerate(peer_legs):
                cut = _crossing(p, q, a, b)
                if cut is None:
                    continue
                along = sum(lengths[:i]) + cut[0] * lengths[i]
                peer_along = sum(peer_lengths[:j]) + cut[1] * peer_lengths[j]
                h1 = math.atan2(q[1] - p[1], q[0] - p[0])
                h2 = math.atan2(b[1] - a[1], b[0] - a[0])
                angle = abs(math.degrees(math.remainder(h2 - h1, math.tau)))
                speed = float(peer.controller.get("params", {}).get("speed_m_s", PEER_SPEED_M_S))
                gap = abs(along / AGENT_SPEED_M_S - peer_along / max(speed, 1e-6))
                if first is None or along < first[0]:
                    first = (along, angle, gap)
        if first is not None:
            crossings.append(first)
    crossings.sort()
    nearest = min(
        (min(_point_segment((p.start.x_m, p.start.y_m), a, b) for a, b in legs) for p in peers),
        default=NONE_M,
    ) if legs else NONE_M  # fmt: skip
    closest, bearing, where = _nominal_closest(situation, route, sum(lengths))
    clearance = NONE_M
    col, row = int(where[0] / res), rows - 1 - int(where[1] / res)
    if to_wall is not None and peers and 0 <= row < rows and 0 <= col < occupied.shape[1]:
        clearance = float(to_wall[row, col]) - res / 2
    spec = situation.spec.get("terrain", {})
    return {
        "route_length_m": sum(lengths),
        "route_turns": _turns(route),
        "route_clearance_m": least,
        "obstacle_share": float(occupied.mean()),
        "peers": len(peers),
        "crossing_peers": len(crossings),
        "crossing_angle_deg": crossings[0][1] if crossings else 0.0,
        "conflict_gap_s": crossings[0][2] if crossings else NONE_M,
        "nearest_peer_start_m": nearest,
        "nominal_closest_m": closest,
        "nominal_closest_bearing_deg": bearing,
        "nominal_closest_clearance_m": clearance,
        "terrain": str(spec.get("preset") or spec.get("source", {}).get("kind") or "given"),
    }


def described(store: Store) -> dict[int, dict[str, Any]]:
    """Every stored run's situation's descriptors, by run id (the situation as stored, or
    generated again from its spec and seed; runs whose situation never generated are left
    out)."""
    out = {}
    for (run_id,) in store.db.execute("SELECT id FROM runs ORDER BY id").fetchall():
        row = stored_run(store, run_id)
        if row["content_hash"] is None:
            continue
        if row["situation"] is not None:
            situation = Situation(row["situation"], check_start=False)
        else:
            try:
                situation = regenerate(row)
            except _core.GenerationFailed:
                continue
        out[run_id] = describe(situation)
    return out
