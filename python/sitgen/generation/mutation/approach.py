"""``approach_peer``: a peer staged through where the parent's failure began, in another
interaction; and the *crowd* that may come with it.

What it does: :func:`approach_peer` sends the peer whose route passes nearest the failure (or
a new one, of the agent's build under the peers' controller, where the situation has none)
through the failure's place in interaction ``target`` (:data:`APPROACHES`): head-on from
ahead, crossing from the left or the right, from behind (faster than the agent), overtaken
(slow, ahead, going the same way), or stopped in the way. It starts up to
:data:`APPROACH_M` away on the side the interaction comes from, as far as the ground is clear
(:class:`Ground`), on a straight leg through the place, and departs (``straight``'s
``start_s``) early enough to be moving when the agent comes in range, at the speed that brings
it there when the agent came there, both read from the parent's :class:`Track` (else timed for
an agent cruising at :data:`AGENT_M_S`); a stopped one never departs (:data:`START_S_MAX`).
The meeting point is the first one back along the agent's way (up to :data:`MEET_BACK_M`) with
room for the peer to come from its side and go on. :func:`staged_crowd` adds one more peer from
each other side of :data:`CROWD`, so that four robots come into the agent's view at once; a
side with no room to start is left out.

Why: a targeted operator changes one coordinate of the parent's variant (its interaction) on
purpose, toward a neighbouring variant the search has not seen; the agent is slow where it
fails, so a staged peer timed for a cruising agent stood in view as the agent came by and
most such children missed their aim.

Parameters: :data:`APPROACH_M` (1.5, 6.0) m, :data:`AGENT_M_S` 0.4 m/s, :data:`MEET_BACK_M`
1.5 m, :data:`PEER_CLEAR_M` 0.6 m, :data:`ONWARD_M` 0.5 m, :data:`STAGED_MIN_M_S` 0.1 m/s,
:data:`CROWD_TRIES` 6.

Source: the interaction types of sitgen's coverage space (docs/coverage.md), staged as
scenario-based testing stages encounters.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.generation.mutation.local import SPEED_RANGE
from sitgen.generation.mutation.parent import IN_RANGE_M, Parent
from sitgen.generation.mutation.places import Edit, cell, focus_peer, peers_by_distance

APPROACHES = ("head_on", "crossing_left", "crossing_right", "from_behind", "overtaking", "stopped")
"""Interactions ``approach_peer`` can stage (coverage's interaction types but ``hidden``)."""


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


ONWARD_M = 0.5
"""How far a staged peer's leg must go on past where it meets the agent (an overtaken one: past
where it starts, ahead of the agent)."""


@dataclass(frozen=True)
class Placing:
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


def staged_crowd(
    robots: list[dict[str, Any]],
    ground: Ground,
    parent: Parent,
    staged: str,
    staged_peer: int | None,
    rng: np.random.Generator,
    placing: Placing,
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
            changed = approach_peer(
                copy.deepcopy(robots), placing.occupied, ground, parent, interaction, rng, peer
            )
            if changed is not None and placing.fits(changed[0]):
                robots = changed[0]
                others = others[1:]
                break
    return robots


def approach_peer(
    robots: list[dict[str, Any]],
    occupied: npt.NDArray[np.bool_],
    ground: Ground,
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
    # The staged peer's departure is timed (``start_s``): it runs ``straight``, whatever it
    # ran before, with the params it had if it ran that already.
    if robot["controller"].get("name") != "straight":
        robot["controller"] = {"name": "straight", "params": {}}
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
class Ground:
    """Where a staged peer has room: each cell's distance to the nearest wall, walked along a
    line in half-cell steps."""

    clear: npt.NDArray[np.float64]
    resolution: float

    @staticmethod
    def of(occupied: npt.NDArray[np.bool_], resolution: float) -> Ground:
        # scipy.ndimage takes 0.35 s to import: a command that only reads a search's store
        # (report, failures) does not pay it.
        from scipy import ndimage

        distance = ndimage.distance_transform_edt(~occupied)
        return Ground(np.asarray(distance, dtype=np.float64) * resolution, resolution)

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
            r, c = cell(self.clear, self.resolution, point)
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
