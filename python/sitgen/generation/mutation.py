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
  one from the right (a directed search draws it for any parent; otherwise it is aimed, below);

and four that aim at a *target*, a neighbouring variant (``sitgen.triage.variants``) of the
parent's failure the search has not seen yet (drawn at random when none is given):

- ``mirror`` again, aimed: a failure met in a crossing from the left, mirrored, is met from the
  right (:data:`MIRRORED`; every other interaction and context reads the same either way
  round). It is the one operator whose child's variant can be told before it runs: the
  encounter is the same with left and right swapped, and the agent's controller, the monitor
  and the classes have no side of their own, so the child mostly fails as its parent did;

- ``approach_peer``: the peer is sent through where the failure began (or the nearest point
  the agent drove through on its way there with room for it) in another interaction
  (:data:`APPROACHES`): head-on from ahead, crossing from the left or the right, from behind
  (faster than the agent), overtaken (slow, ahead, going the same way), or stopped in the way.
  It starts up to ``APPROACH_M`` from there, as far as the ground is clear, on a straight leg
  through it, and departs (``straight``'s ``start_s``) early enough to be moving when the agent
  comes in range, at the speed that brings it there when the agent came there; a stopped one
  never departs. Both times are read from the parent's :class:`Track` (the agent's run is its
  parent's until it sees the peer, and it is slow where it fails: timed for a cruising
  ``AGENT_M_S`` instead, half the staged peers stood in view as the agent came by, and most of
  the children that missed their aim met a standing peer). The meeting point is the first one
  back along the agent's way (up to ``MEET_BACK_M``) with room for the peer to come from its
  side and go on. A situation without peers gets one, of the agent's build under the peers'
  controller;
- ``reshape_terrain``: the walls round where the failure began are redrawn to make another
  terrain context (:data:`CONTEXTS`): two walls along the way the agent faced or its route
  leg there (``corridor``), a narrow opening across it (``gap``), walls on three sides
  (``dead_end``), a wall beside it that ends just ahead (``blind_corner``), or the walls within
  a few metres cleared (``open``); a peer's leg that crosses a new wall gets a doorway as wide
  as the leg check needs and the agent's route points stay clear. The core's own classifier
  (``agent_context``) must read the target there (or another context the caller accepts: a
  draw aimed at a dead end that makes a gap the search has not seen is as good), or the draw
  is tried again;
- ``reshape_and_approach``: both at once, the walls redrawn and then a peer staged through
  the place in them (target ``INTERACTION/CONTEXT``): a staged meeting or new walls often
  change the failure's class as well, and a class met in a new interaction *and* a new context
  is less often one already seen than with one of them changed.

Two additions make a child more demanding without moving the encounter it aims at, each
drawn with a fixed chance by the search (``sitgen.generation.search``'s ``CROWD_SHARE`` and
``STRETCH_SHARE``):

- a *crowd* (``mutate``'s ``crowd``): a staged approach is met by more peers through the same
  place, one from each other side of :data:`CROWD` (the situation's peers whose routes pass
  nearest first, then new ones up to its spec's ``peers_max``), so that four robots come into
  the agent's view at once; a side with no room to start is left out;
- :func:`extended`: the agent's mission goes on past its goal, planned by the core as the
  generator plans a route (``continued_route``: goals on the dilated map, A*, RDP, until the
  continuation is ``min_route_length_m`` long), so a child drives longer and more winding
  routes than its parent (the search applies it to a share of its fresh jobs as well).

:func:`cut_past_failure` ends a child's mission :data:`KEPT_PAST` waypoint past the route leg
nearest where its parent's failure began (before any stretch): what the parent drove after that
cannot change the encounter the child aims at, and a later, more severe failure there (the run's
failure is its most severe class) would hide the variant the child was made to show.

Every child is checked as a shrink's candidates are (the core's ``shrink_check``: a valid
situation, every robot starting clear, peer legs clear on the dilated map); an operator that
cannot make a valid child in ``TRIES`` draws gives None, and the search draws afresh.

Why: varying a campaign spec's parameters and seeds redraws the whole situation, so a child
keeps its parent's failure class only 16-19 % of the time (``make bench-search``); an operator
on the situation leaves the rest of the encounter as it was. The local operators mostly repeat
their parent's variant, too; the targeted ones change one or two coordinates of it on
purpose (the interaction, the terrain context, or both; ``mirror`` the side a crossing comes
from) and leave the rest, so that a search for distinct failures gets new ones at a higher
rate than random generation. Sources: the
situation operators of search-based testing of automated vehicles (e.g. Gambi et al.,
AsFault; Riccio & Tonella, DeepJanus' local mutations of the input) applied to sitgen's
situations.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import math
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from sitgen import _core
from sitgen.triage.variants import variant
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
    "approach_peer",
    "reshape_terrain",
    "reshape_and_approach",
)
TARGETED = ("approach_peer", "reshape_terrain", "reshape_and_approach", "mirror")
"""Operators aimed at a target variant's interaction, terrain context, or both."""
MIRRORED = {"crossing_left": "crossing_right", "crossing_right": "crossing_left"}
"""The interaction a mirrored encounter is met in: every other reads the same either way."""
PEER_OPERATORS = ("move_peer", "turn_peer", "retime_peer", "peer_speed")
"""Local operators on a peer: none applies to a situation without peers (a staged approach
brings one in)."""
APPROACHES = ("head_on", "crossing_left", "crossing_right", "from_behind", "overtaking", "stopped")
"""Interactions ``approach_peer`` can stage (coverage's interaction types but ``hidden``)."""
CONTEXTS = ("open", "corridor", "gap", "dead_end", "blind_corner")
"""Terrain contexts ``reshape_terrain`` can draw (coverage's)."""
CROWD = ("head_on", "crossing_left", "crossing_right", "stopped")
"""The sides a crowd comes from: the staged peer's and one more peer from each other one, so
that four robots come into the agent's view at once."""
CROWD_TRIES = 6
"""Draws of each further peer of a crowd before its side is left out."""
APPROACH_M = (1.5, 6.0)
"""How far from where they meet a staged peer may start, metres."""
AGENT_M_S = 0.4
"""The agent's speed a staged encounter is timed for (a typical cruising speed of the
built-in agents; a guess: the encounter need only be about right)."""
IN_RANGE_M = 3.5
"""Distance, centre to centre, at which the coverage observer starts an encounter (its 2 m
footprint clearance and two robots' reach)."""
ARRIVED_M = 0.3
"""How near a point a parent's agent must have come to have been there (:class:`Track`)."""
SPEED_WINDOW_S = 10.0
"""Time over which the agent's speed where it met its parent's failure is measured."""
MOVING_M_S = 0.05
"""The least speed at which the coverage observer reads a peer as moving (the core's
``MOVING_M_S``)."""
STAGED_MIN_M_S = 2 * MOVING_M_S
"""Least speed of a staged peer that drives to the meeting: one the agent came within range of
long before the meeting sets off late, standing in view till then, rather than creeping along
too slowly to read as moving."""
MEET_BACK_M = 1.5
"""How far back along the agent's way to the failure a staged encounter may be placed."""
PEER_CLEAR_M = 0.6
"""Clearance a staged peer's start and leg keep from every wall (its reach, 0.45 m, and the
leg margin the checks ask for)."""
START_S_MAX = 3600.0
"""``straight``'s largest ``start_s``: a peer that never departs in any run sitgen makes."""
WALL_M = 0.2
"""Thickness of a drawn wall."""
DOORWAY_SLACK_M = 0.1
"""How much farther than the leg margin the checks ask for (the mission's ``plan_margin_m``) a
drawn wall keeps from every peer's route legs: where a peer's leg crosses one, the wall has a
doorway just wide enough, so that a narrow gap stays one."""
ONWARD_M = 0.5
"""How far a staged peer's leg must go on past where it meets the agent (an overtaken one: past
where it starts, ahead of the agent)."""
POINT_CLEAR_M = 0.45
"""A drawn wall keeps this far from the points of the agent's route (a robot's reach)."""
MOVE_SD_M = 0.5
TURN_MIN_RAD, TURN_MAX_RAD = 0.15, 0.6
RETIME_M = 1.5
WAYPOINT_SD_M = 0.7
NEAR_SD_M = 1.5
BLOB_MAX_CELLS = 2500
"""Largest obstacle a remove or move takes whole (25 m² at 0.1 m cells): a larger one is
terrain, not an obstacle near the failure."""
KEPT_PAST = 1
"""Waypoints a child's mission keeps past the route leg its parent's failure began on
(:func:`cut_past_failure`): enough to drive on through the place, not so many that a later,
more severe failure of a class already found becomes the run's failure and hides the variant
the child was made to show."""
NOT_COMPLETED = "route_not_completed"
TRIES = 8
SPEED_RANGE = (0.1, 1.5)


Edit = tuple[list[dict[str, Any]], npt.NDArray[np.bool_]]
"""An operator's work: the child's robots (situation JSON's) and its map's occupied cells."""


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
    return _with_agent_route(child, [*waypoints, *([x, y] for x, y in route)])


def cut_past_failure(child: str, parent: Parent) -> str:
    """``child`` with the agent's mission ending :data:`KEPT_PAST` waypoints past the route
    leg nearest where its parent's failure began, or ``child`` as it is where the route ends
    there anyway, or the parent did not fail or failed for not completing its route (a
    failure of the whole mission)."""
    key = parent.variant
    if parent.failure_pose is None or key is None or key.startswith(f"{NOT_COMPLETED}/"):
        return child
    agent = json.loads(child)["robots"][0]
    waypoints, route = agent["waypoints"], _route(agent)
    place = parent.failure_pose[:2]
    leg = min(range(len(route) - 1), key=lambda i: _segment_distance(place, route[i], route[i + 1]))
    # Leg i ends at waypoint i.
    kept = leg + 1 + KEPT_PAST
    if kept >= len(waypoints):
        return child
    return _with_agent_route(child, waypoints[:kept])


def as_made_by(parent: Parent, operator: str) -> Parent:
    """``parent`` with its failure where a child made by ``operator`` has it: mirrored left to
    right for ``mirror`` (without its track, which is the unmirrored run's), else where it
    was."""
    if operator != "mirror" or parent.failure_pose is None:
        return parent
    grid = parent.situation.grid
    pose = _mirrored(grid.occupied.shape[1] * grid.resolution, *parent.failure_pose)
    return dataclasses.replace(parent, failure_pose=pose, track=None)


def _mirrored(width: float, x: float, y: float, heading: float) -> tuple[float, float, float]:
    """A pose on a map ``width`` metres wide, mirrored left to right."""
    return width - x, y, math.remainder(math.pi - heading, math.tau)


def _with_agent_route(child: str, waypoints: list[Any]) -> str:
    """``child`` with the agent driving ``waypoints`` after its start, on the child's map."""
    robots = json.loads(child)["robots"]
    robots[0]["waypoints"] = waypoints
    situation = Situation(child, check_start=False)
    occupied = np.ascontiguousarray(situation.grid.occupied, dtype=bool)
    return _core.mutated_situation(child, occupied, situation.grid.resolution, json.dumps(robots))


def mutate(
    parent: Parent,
    operator: str,
    rng: np.random.Generator,
    target: str | None = None,
    accept: Collection[str] = (),
    crowd: float = 0.0,
) -> str | None:
    """A valid child of ``parent`` by ``operator`` (situation JSON), or None if none of
    :data:`TRIES` draws made a valid one. ``target``: the interaction (``approach_peer``),
    terrain context (``reshape_terrain``) or both (``reshape_and_approach``,
    ``INTERACTION/CONTEXT``) to make, one of :func:`neighbours`; drawn from them if None.
    ``accept``: other targets a child that redraws walls may make instead and be kept (a draw
    aimed at one context that makes another the search wants is as good). ``crowd``: the
    chance that a staged approach is met by a crowd (:func:`_crowd`)."""
    original = parent.situation.to_json()
    robots: list[dict[str, Any]] = json.loads(original)["robots"]
    grid = parent.situation.grid
    occupied = np.ascontiguousarray(grid.occupied, dtype=bool)
    focus = _focus(parent, robots, rng)
    margin = _core.shrink_leg_margin(original)
    doorway = float(parent.situation.spec["mission"]["plan_margin_m"]) + DOORWAY_SLACK_M
    aimable = neighbours(parent.variant, operator) if operator in TARGETED else {}
    if target is None and aimable:
        target = _other_target(parent, operator, rng)
        accept = list(aimable)
    ground = _Ground.of(occupied, grid.resolution) if operator == "approach_peer" else None
    # The terrain contexts a child may read as: the one aimed at, or another the caller wants.
    contexts = {target, *accept}
    if operator == "reshape_and_approach":
        assert target is not None
        interaction = target.split("/")[0]
        contexts = {t.split("/")[1] for t in (target, *accept) if t.split("/")[0] == interaction}
    for _ in range(TRIES):
        if operator == "approach_peer":
            assert target is not None and ground is not None
            changed = _approach_peer(copy.deepcopy(robots), occupied, ground, parent, target, rng)
        elif operator == "reshape_terrain":
            assert target is not None
            changed = _reshape_terrain(
                robots, occupied, grid.resolution, parent, target, rng, doorway
            )
        elif operator == "reshape_and_approach":
            assert target is not None
            interaction, context = target.split("/")
            walls = _reshape_terrain(
                robots, occupied, grid.resolution, parent, context, rng, doorway
            )
            if walls is None:
                return None
            reshaped = walls[1]
            ground = _Ground.of(reshaped, grid.resolution)
            changed = _approach_peer(
                copy.deepcopy(robots), reshaped, ground, parent, interaction, rng
            )
            if changed is None:
                continue  # these walls leave the peer no room: other walls may
        else:
            changed = _apply(
                operator, copy.deepcopy(robots), occupied, grid.resolution, focus, parent, rng
            )
        if changed is None:
            return None
        new_robots, new_occupied = changed
        child = _core.mutated_situation(
            original, new_occupied, grid.resolution, json.dumps(new_robots)
        )
        if _core.shrink_check(child, margin) is not None:
            continue
        reshapes = operator in ("reshape_terrain", "reshape_and_approach")
        if reshapes and _read_at(child, parent) not in contexts:
            continue
        if ground is not None and crowd and rng.random() < crowd:
            assert target is not None
            interaction = target.split("/")[0]
            # The peer staged is the one the approach took: the parent's focus peer, if any.
            assert parent.failure_pose is not None
            staged_peer = focus_peer(robots, parent.failure_pose[:2])
            crowd_at = _Placing(original, new_occupied, grid.resolution, margin)
            return crowd_at.situation(
                _crowd(new_robots, ground, parent, interaction, staged_peer, rng, crowd_at)
            )
        return child
    return None


@dataclass(frozen=True)
class _Placing:
    """Robots placed on a child's map: the situation they make, and whether it passes the
    checks (everyone starts clear)."""

    original: str
    occupied: npt.NDArray[np.bool_]
    resolution: float
    margin: float | None

    def situation(self, robots: list[dict[str, Any]]) -> str:
        return _core.mutated_situation(
            self.original, self.occupied, self.resolution, json.dumps(robots)
        )

    def fits(self, robots: list[dict[str, Any]]) -> bool:
        return _core.shrink_check(self.situation(robots), self.margin) is None


def _crowd(
    robots: list[dict[str, Any]],
    ground: _Ground,
    parent: Parent,
    staged: str,
    staged_peer: int | None,
    rng: np.random.Generator,
    placing: _Placing,
) -> list[dict[str, Any]]:
    """``robots`` with more peers sent through the failure's place beside the one staged
    there in interaction ``staged`` (``staged_peer``; None: the peer brought in): one from
    each other side of :data:`CROWD`, the peers whose routes pass nearest first, then new ones
    while the situation has fewer than its spec's ``peers_max``. Each must leave a situation
    that fits the map (everyone starts clear), in :data:`CROWD_TRIES` draws, or its side is
    left out."""
    assert parent.failure_pose is not None
    place = parent.failure_pose[:2]
    staged_peer = len(robots) - 1 if staged_peer is None else staged_peer
    others = [i for i in peers_by_distance(robots, place) if i != staged_peer]
    most = max(len(robots) - 1, int(parent.situation.spec["mission"].get("peers_max", 0)))
    for interaction in (i for i in CROWD if i != staged):
        peer = others[0] if others else len(robots)
        if peer == len(robots) and len(robots) - 1 >= most:
            break
        for _ in range(CROWD_TRIES):
            changed = _approach_peer(
                copy.deepcopy(robots), placing.occupied, ground, parent, interaction, rng, peer
            )
            if changed is not None and placing.fits(changed[0]):
                robots = changed[0]
                others = others[1:]
                break
    return robots


def neighbours(key: str | None, operator: str) -> dict[str, str]:
    """The targets a targeted ``operator`` can aim at from variant ``key``
    (``CLASS/INTERACTION/CONTEXT``; None: any), each with the variant it would make: every
    other interaction (``approach_peer``), terrain context (``reshape_terrain``), or
    ``INTERACTION/CONTEXT`` with both other (``reshape_and_approach``), or the crossing from
    the other side (``mirror``; none from any other interaction)."""
    cls, interaction, context = (key or "//").split("/")
    interactions = [i for i in APPROACHES if i != interaction]
    contexts = [c for c in CONTEXTS if c != context]
    if operator == "approach_peer":
        made = [f"{cls}/{i}/{context}" for i in interactions]
    elif operator == "reshape_and_approach":
        made = [f"{cls}/{i}/{c}" for i in interactions for c in contexts]
    elif operator == "mirror":
        made = [f"{cls}/{MIRRORED[interaction]}/{context}"] if interaction in MIRRORED else []
    else:
        made = [f"{cls}/{interaction}/{c}" for c in contexts]
    return {target_of(v, operator): v for v in made}


def target_of(key: str, operator: str) -> str:
    """The target of a targeted ``operator`` that variant ``key`` stands at: its interaction
    (``approach_peer``, ``mirror``), its terrain context (``reshape_terrain``), or both
    (``reshape_and_approach``, ``INTERACTION/CONTEXT``) — what a child aimed there should
    show."""
    _, interaction, context = key.split("/")
    if operator in ("approach_peer", "mirror"):
        return interaction
    if operator == "reshape_terrain":
        return context
    return f"{interaction}/{context}"


def _other_target(parent: Parent, operator: str, rng: np.random.Generator) -> str:
    """A target other than the parent's own interaction or context."""
    others = list(neighbours(parent.variant, operator))
    return others[int(rng.integers(len(others)))]


def _approach_peer(
    robots: list[dict[str, Any]],
    occupied: npt.NDArray[np.bool_],
    ground: _Ground,
    parent: Parent,
    target: str,
    rng: np.random.Generator,
    peer: int | None = None,
) -> Edit | None:
    """The focus peer (or peer ``peer``; ``len(robots)``: a new one) sent through the
    failure's place in interaction ``target``: a start up to ``APPROACH_M`` away on the side
    the interaction comes from, as far as the ground is clear, a leg through the place and on,
    and a departure timed to arrive when the agent did."""
    if parent.failure_pose is None:
        return None
    x, y, heading = parent.failure_pose
    if peer is None:
        peer = focus_peer(robots, (x, y))
    if peer is None or peer == len(robots):
        # A failure no peer took part in, in a situation with none: one is brought in, a
        # robot of the agent's build under the peers' controller.
        peer = len(robots)
        robots.append(
            {
                "id": peer,
                "role": "peer",
                "body": dict(robots[0]["body"]),
                "controller": {"name": "straight", "params": {}},
            }
        )
    robot = robots[peer]
    params = dict(robot["controller"].get("params") or {})
    # Where the peer comes from (bearing from the place) and the course it drives.
    side = {
        "head_on": (0.0, math.pi),
        "crossing_left": (math.pi / 2, -math.pi / 2),
        "crossing_right": (-math.pi / 2, math.pi / 2),
        "from_behind": (math.pi, 0.0),
        "overtaking": (0.0, 0.0),
        "stopped": (0.0, 0.0),
    }[target]
    bearing, course = heading + side[0], heading + side[1]
    near = 0.8 if target in ("stopped", "overtaking") else APPROACH_M[0]
    # An overtaken peer starts ahead on the agent's way and goes on along it: room for both.
    onward_m = ONWARD_M if target == "overtaking" else 0.0
    # Where they meet: the failure's place, or the nearest point the agent drove through on the
    # way there with room for the peer to come from its side and go on (a failure against a
    # wall leaves none at the place itself).
    meeting = ground.meeting(
        (x, y), heading + math.pi, MEET_BACK_M, bearing, near + onward_m, course
    )
    if meeting is None:
        return None
    (x, y), room = meeting
    farthest = min(room - onward_m, 2.0 if target == "stopped" else APPROACH_M[1])
    distance = float(rng.uniform(near, farthest))
    sx, sy = x + distance * math.cos(bearing), y + distance * math.sin(bearing)
    if target == "overtaking":
        on = (sx, sy)
        waypoints = []
    else:
        on = (x, y)
        waypoints = [[x, y]]
    onward = ground.run(on, course, APPROACH_M[1])
    if onward < ONWARD_M:
        return None
    beyond = float(rng.uniform(ONWARD_M, onward))
    waypoints.append([on[0] + beyond * math.cos(course), on[1] + beyond * math.sin(course)])
    start_s, speed = _timing(parent, (x, y), (sx, sy), distance, target, rng)
    params["speed_m_s"] = min(SPEED_RANGE[1], max(SPEED_RANGE[0] / 5, speed))
    params["start_s"] = START_S_MAX if target == "stopped" else round(start_s, 3)
    robot["controller"]["params"] = params
    robot["start"] = {"x_m": sx, "y_m": sy, "heading_rad": math.remainder(course, math.tau)}
    robot["waypoints"] = waypoints
    robot["at_end"] = "stop"
    return robots, occupied


def _timing(
    parent: Parent,
    meeting: tuple[float, float],
    start: tuple[float, float],
    distance: float,
    target: str,
    rng: np.random.Generator,
) -> tuple[float, float]:
    """When a peer staged from ``start``, ``distance`` from ``meeting``, departs and how fast
    it drives (seconds into the run, m/s): it sets off before the agent comes within range of
    where it waits (else they meet with the peer standing) and reaches the meeting when the
    agent does — by the parent's track where it has one (the agent's run is its parent's until
    it sees the peer), else for an agent cruising at :data:`AGENT_M_S` that reached it when
    the failure began."""
    failure_s = parent.failure_s or 0.0
    track = parent.track
    if track is None:
        meet_s, agent_m_s = failure_s, AGENT_M_S
        seen_s = failure_s - (distance + IN_RANGE_M) / AGENT_M_S
    else:
        meet_s = track.arrival_s(meeting)
        agent_m_s = max(track.speed_m_s(meet_s), STAGED_MIN_M_S)
        in_range = track.in_range_s(start, meet_s)
        seen_s = meet_s - (distance + IN_RANGE_M) / agent_m_s if in_range is None else in_range
    start_s = max(0.0, seen_s - float(rng.uniform(0, 2)))
    if target == "overtaking":
        # Slower than the agent, and still moving as it reads to the observer.
        top = AGENT_M_S / 2 if track is None else max(agent_m_s / 2, STAGED_MIN_M_S)
        low = SPEED_RANGE[0] / 5 if track is None else 1.2 * MOVING_M_S
        return start_s, float(rng.uniform(low, top))
    if target == "from_behind":
        speed = float(rng.uniform(2 * agent_m_s, SPEED_RANGE[1]))
        if track is None:
            return max(0.0, failure_s - distance / (speed - AGENT_M_S)), speed
        # It catches the agent up at the meeting.
        return max(0.0, meet_s - distance / speed), speed
    speed = distance / max(meet_s - start_s, 1e-3)
    if track is not None and not STAGED_MIN_M_S <= speed <= SPEED_RANGE[1]:
        # Too slow to read as moving, or faster than a peer drives: it stands in view a while.
        speed = min(max(speed, STAGED_MIN_M_S), SPEED_RANGE[1])
        start_s = max(0.0, meet_s - distance / speed)
    return start_s, speed


@dataclass(frozen=True)
class _Ground:
    """Where a staged peer has room: each cell's distance to the nearest wall, walked along a
    line in half-cell steps."""

    clear: npt.NDArray[np.float64]
    resolution: float

    @staticmethod
    def of(occupied: npt.NDArray[np.bool_], resolution: float) -> _Ground:
        distance = ndimage.distance_transform_edt(~occupied)
        return _Ground(np.asarray(distance, dtype=np.float64) * resolution, resolution)

    def _along(
        self, start: tuple[float, float], heading: float, most: float
    ) -> Iterator[tuple[float, bool]]:
        """(distance, whether the ground there is :data:`PEER_CLEAR_M` clear of walls) at
        each step from ``start`` along ``heading`` up to ``most``."""
        rows, cols = self.clear.shape
        step = self.resolution / 2
        for k in range(int(most / step) + 1):
            d = k * step
            point = (start[0] + d * math.cos(heading), start[1] + d * math.sin(heading))
            r, c = _cell(self.clear, self.resolution, point)
            yield d, 0 <= r < rows and 0 <= c < cols and bool(self.clear[r, c] >= PEER_CLEAR_M)

    def run(self, start: tuple[float, float], heading: float, most: float) -> float:
        """How far from ``start`` along ``heading`` (up to ``most``) the ground stays clear (0
        if it is not clear at the start)."""
        for d, is_clear in self._along(start, heading, most):
            if not is_clear:
                return max(0.0, d - self.resolution / 2)
        return most

    def meeting(
        self,
        start: tuple[float, float],
        back: float,
        most: float,
        bearing: float,
        near: float,
        course: float,
    ) -> tuple[tuple[float, float], float] | None:
        """The first point from ``start`` along ``back`` (up to ``most``) with clear ground
        at least ``near`` along ``bearing`` (where a peer comes from) and :data:`ONWARD_M`
        along ``course`` (where it goes on), and the room along ``bearing`` there; None if
        none."""
        for d, is_clear in self._along(start, back, most):
            if not is_clear:
                continue
            point = (start[0] + d * math.cos(back), start[1] + d * math.sin(back))
            room = self.run(point, bearing, APPROACH_M[1])
            if room >= near and self.run(point, course, ONWARD_M) >= ONWARD_M:
                return point, room
        return None


def _reshape_terrain(
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
    window = _centres(
        occupied.shape,
        resolution,
        int(changed[0].min()),
        int(changed[0].max()) + 1,
        int(changed[1].min()),
        int(changed[1].max()) + 1,
    )
    for point in _route(robots[0]):
        _restore_near(occupied, before, window, (point, point), POINT_CLEAR_M)
    for robot in robots[1:]:
        for leg in itertools.pairwise(_route(robot)):
            _restore_near(occupied, before, window, leg, doorway)
    return robots, occupied


def _restore_near(
    occupied: npt.NDArray[np.bool_],
    before: npt.NDArray[np.bool_],
    window: tuple[slice, slice, npt.NDArray[np.float64], npt.NDArray[np.float64]],
    leg: tuple[tuple[float, float], tuple[float, float]],
    reach: float,
) -> None:
    """Cells of ``window`` (:func:`_centres`) within ``reach`` of ``leg`` go back to what they
    were ``before``."""
    rows, cols, px, py = window
    (ax, ay), (bx, by) = leg
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = np.zeros_like(px) if length2 == 0 else ((px - ax) * dx + (py - ay) * dy) / length2
    t = np.clip(t, 0.0, 1.0)
    near = (px - ax - t * dx) ** 2 + (py - ay - t * dy) ** 2 <= reach * reach
    occupied[rows, cols] = np.where(near, before[rows, cols], occupied[rows, cols])


def _centres(
    shape: tuple[int, ...], resolution: float, r0: int, r1: int, c0: int, c1: int
) -> tuple[slice, slice, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Rows r0..r1 and columns c0..c1 of a map of ``shape`` (row 0 north), with the x and y of
    their cells' centres in metres (the inverse of :func:`_cell`)."""
    rr, cc = np.mgrid[r0:r1, c0:c1]
    xs = (cc + 0.5) * resolution
    ys = (shape[0] - rr - 0.5) * resolution
    return slice(r0, r1), slice(c0, c1), xs, ys


def _span(a: float, b: float) -> tuple[float, float]:
    return min(a, b), max(a, b)


def _leg_heading(robot: dict[str, Any], point: tuple[float, float]) -> float:
    """The heading of the robot's route leg nearest ``point``."""
    route = _route(robot)
    legs = list(itertools.pairwise(route)) or [(route[0], route[0])]
    a, b = min(legs, key=lambda leg: _segment_distance(point, *leg))
    return math.atan2(b[1] - a[1], b[0] - a[0])


def _read_at(child: str, parent: Parent) -> str:
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
        r, c = _cell(self.occupied, self.resolution, self.origin)
        k = math.ceil(reach / self.resolution) + 1
        r0, r1, c0, c1 = max(0, r - k), min(rows, r + k + 1), max(0, c - k), min(cols, c + k + 1)
        window_rows, window_cols, xs, ys = _centres(
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
    nearest = peers_by_distance(robots, focus)
    return nearest[0] if nearest else None


def peers_by_distance(robots: list[dict[str, Any]], focus: tuple[float, float]) -> list[int]:
    """The peers (indices into ``robots``), the one whose route passes nearest ``focus``
    first."""
    distance = {}
    for i, robot in enumerate(robots[1:], start=1):
        route = _route(robot)
        distance[i] = min(
            (_segment_distance(focus, a, b) for a, b in itertools.pairwise(route)),
            default=math.hypot(focus[0] - route[0][0], focus[1] - route[0][1]),
        )
    return sorted(distance, key=lambda i: (distance[i], i))


def _apply(
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
            start["x_m"], _, start["heading_rad"] = _mirrored(
                width, start["x_m"], start["y_m"], start["heading_rad"]
            )
            robot["waypoints"] = [[width - x, y] for x, y in robot["waypoints"]]
    else:
        raise ValueError(f"unknown situation operator `{operator}`")
    return robots, occupied


def _cell(
    occupied: npt.NDArray[Any], resolution: float, point: tuple[float, float]
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
