"""Situation operators: small, local changes to a situation itself, for a search that keeps what
its parent failed at and varies how.

What it does: :func:`mutate` makes a child situation from a parent by one operator, drawn from
:data:`OPERATORS`, aimed where the parent's failure began (its ``failure_at`` pose, and the
peer whose route passes nearest it): the ten local ones in :mod:`.local` (a peer moved,
turned, retimed or sped up; a waypoint shifted, inserted or deleted; an obstacle added,
removed or moved; :mod:`.mirror`), and four
that aim at a *target*, a neighbouring variant (``sitgen.triage.variants``) of the parent's
failure the search has not seen yet (drawn at random when none is given): ``mirror``
(:mod:`.mirror`), ``approach_peer`` (:mod:`.approach`), ``reshape_terrain`` (:mod:`.terrain`)
and ``reshape_and_approach`` (both). A staged approach may be met by a crowd
(:func:`.approach.staged_crowd`, with the search's ``CROWD_SHARE``); the child's mission is cut
past its parent's failure and may go on past its goal (:mod:`.parent`).

Every child is checked as a shrink's candidates are (the core's ``shrink_check``: a valid
situation, every robot starting clear, peer legs clear on the dilated map); an operator that
cannot make a valid child in ``TRIES`` draws gives None, and the search draws afresh.

Why: varying a campaign spec's parameters and seeds redraws the whole situation, so a child
keeps its parent's failure class only 16-19 % of the time (``make bench-search``); an operator
on the situation leaves the rest of the encounter as it was. The local operators mostly repeat
their parent's variant, too; the targeted ones change one or two coordinates of it on
purpose (the interaction, the terrain context, or both; ``mirror`` the side a crossing comes
from) and leave the rest, so that a search for distinct failures gets new ones at a higher
rate than random generation.

Parameters: :data:`TRIES` (8 draws of an operator before it gives None); each operator's own in
its module.

Source: the situation operators of search-based testing of automated vehicles (e.g. Gambi et
al., AsFault; Riccio & Tonella, DeepJanus' local mutations of the input) applied to sitgen's
situations.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Collection
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.generation.mutation.approach import (
    APPROACHES,
    Ground,
    Placing,
    approach_peer,
    staged_crowd,
)
from sitgen.generation.mutation.local import apply_local
from sitgen.generation.mutation.mirror import MIRRORED
from sitgen.generation.mutation.parent import Parent, focus_of
from sitgen.generation.mutation.places import focus_peer
from sitgen.generation.mutation.terrain import CONTEXTS, DOORWAY_SLACK_M, read_at, reshape_terrain

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


TRIES = 8


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
    chance that a staged approach is met by a crowd (:func:`staged_crowd`)."""
    original = parent.situation.to_json()
    robots: list[dict[str, Any]] = json.loads(original)["robots"]
    grid = parent.situation.grid
    occupied = np.ascontiguousarray(grid.occupied, dtype=bool)
    focus = focus_of(parent, robots, rng)
    margin = _core.shrink_leg_margin(original)
    doorway = float(parent.situation.spec["mission"]["plan_margin_m"]) + DOORWAY_SLACK_M
    aimable = neighbours(parent.variant, operator) if operator in TARGETED else {}
    if target is None and aimable:
        target = _other_target(parent, operator, rng)
        accept = list(aimable)
    ground = Ground.of(occupied, grid.resolution) if operator == "approach_peer" else None
    # The terrain contexts a child may read as: the one aimed at, or another the caller wants.
    contexts = {target, *accept}
    if operator == "reshape_and_approach":
        assert target is not None
        interaction = target.split("/")[0]
        contexts = {t.split("/")[1] for t in (target, *accept) if t.split("/")[0] == interaction}
    for _ in range(TRIES):
        if operator == "approach_peer":
            assert target is not None and ground is not None
            changed = approach_peer(copy.deepcopy(robots), occupied, ground, parent, target, rng)
        elif operator == "reshape_terrain":
            assert target is not None
            changed = reshape_terrain(
                robots, occupied, grid.resolution, parent, target, rng, doorway
            )
        elif operator == "reshape_and_approach":
            assert target is not None
            interaction, context = target.split("/")
            walls = reshape_terrain(
                robots, occupied, grid.resolution, parent, context, rng, doorway
            )
            if walls is None:
                return None
            reshaped = walls[1]
            ground = Ground.of(reshaped, grid.resolution)
            changed = approach_peer(
                copy.deepcopy(robots), reshaped, ground, parent, interaction, rng
            )
            if changed is None:
                continue  # these walls leave the peer no room: other walls may
        else:
            changed = apply_local(
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
        if reshapes and read_at(child, parent) not in contexts:
            continue
        if ground is not None and crowd and rng.random() < crowd:
            assert target is not None
            interaction = target.split("/")[0]
            # The peer staged is the one the approach took: the parent's focus peer, if any.
            assert parent.failure_pose is not None
            staged_peer = focus_peer(robots, parent.failure_pose[:2])
            crowd_at = Placing(original, new_occupied, grid.resolution, margin)
            return crowd_at.situation(
                staged_crowd(new_robots, ground, parent, interaction, staged_peer, rng, crowd_at)
            )
        return child
    return None


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
