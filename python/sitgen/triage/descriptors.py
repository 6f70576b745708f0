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
  ``stop``), drives it back to its start and again (``reverse``) or drives from its last
  waypoint to its first and round again (``loop``); 1000 without peers.
- ``nominal_closest_bearing_deg``: where that peer lies then from the agent's heading (the
  direction of its current leg), 0 (dead ahead) to 180 (behind); 0 without peers.
- ``nominal_closest_clearance_m``: how near the agent's position then is to the nearest
  occupied cell, centre to centre less half a cell (as ``route_clearance_m``); 1000 without
  peers or obstacles.
- ``terrain``: the terrain preset (one-hot in a model).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.store import Store
from sitgen.triage.recall import regenerate, stored_run
from sitgen.world.situation import Situation

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


RUN_NUMERIC = (
    "closest_approach_m",
    "closest_approach_s",
    "speed_at_closest_m_s",
    "first_sight_s",
    "speed_at_first_sight_m_s",
)
"""Run descriptors (docs/explain.md): measured from a run, not known before it."""

NONE = 1000.0
"""What a run descriptor reads without a subject (no peer, never seen)."""


def run_descriptors(signals: dict[str, Any], dt_s: float) -> dict[str, float]:
    """A run's descriptors from its requirement signals (docs/requirements.md), one value a
    sample ``dt_s`` apart: the closest any peer's footprint came to the agent's
    (``peer_clearance``), when, and the agent's speed then; when the agent's laser first saw
    a peer (``peer_seen``), and its speed then."""
    gap = np.asarray(signals["peer_clearance"], dtype=float)
    speed = np.abs(np.asarray(signals["speed"], dtype=float))
    seen = np.flatnonzero(np.asarray(signals["peer_seen"], dtype=float) > 0)
    finite = np.isfinite(gap)
    out = dict.fromkeys(RUN_NUMERIC, NONE)
    if finite.any():
        k = int(np.argmin(np.where(finite, gap, np.inf)))
        out |= {"closest_approach_m": float(gap[k]), "closest_approach_s": k * dt_s,
                "speed_at_closest_m_s": float(speed[k])}  # fmt: skip
    if len(seen):
        k = int(seen[0])
        out |= {"first_sight_s": k * dt_s, "speed_at_first_sight_m_s": float(speed[k])}
    return out


def describe(situation: Situation) -> dict[str, Any]:
    """The descriptors of ``situation`` (docs/explain.md), computed by the core
    (``sitgen_core::situation::descriptors``, which a campaign also runs on every situation it
    generates and stores)."""
    out: dict[str, Any] = json.loads(_core.situation_descriptors(situation.to_json()))
    return out


def described(store: Store) -> dict[int, dict[str, Any]]:
    """Every stored run's situation's descriptors, by run id: as stored with the situation (a
    campaign stores them), else computed from the situation as stored, or generated again from
    its spec and seed, and stored for the next time; runs whose situation never generated are
    left out."""
    out = store.stored_descriptors()
    missing: dict[int, dict[str, Any]] = {}
    ids = store.db.execute("SELECT id, situation_id FROM runs ORDER BY id").fetchall()
    for run_id, situation_id in ids:
        if run_id in out:
            continue
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
        out[run_id] = missing[situation_id] = describe(situation)
    if missing:
        store.record_descriptors(missing)
    return {i: out[i] for i, _ in ids if i in out}
