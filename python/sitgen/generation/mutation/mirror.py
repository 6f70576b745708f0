"""``mirror``: the whole situation mirrored left to right.

What it does: every robot's start, heading and waypoints and the map mirrored about the map's
vertical midline (the operator itself is applied with the local ones, :mod:`.local`), so a
failure met in a crossing from the left is met from the right (:data:`MIRRORED`; every other
interaction and terrain context reads the same either way round). :func:`as_made_by` places a
parent's failure where a mirrored child has it, so the child is cut past it correctly.

Why: it is the one operator whose child's variant can be told before it runs. The encounter is
the same with left and right swapped, and the agent's controller, the monitor and the failure
classes have no side of their own, so the child mostly fails as its parent did, in the other
side's variant (87 % kept their parent's class, 62 % confirmed a new robust variant:
benches/search-notes.md, *Mirrored crossings*). A search draws it only for a parent whose
mirrored variant no run has shown (a directed search for any parent).

Parameters: none.

Source: symmetry of the encounter; a situation operator in the spirit of DeepJanus' local
mutations (Riccio & Tonella 2020).
"""

from __future__ import annotations

import dataclasses
import math

from sitgen.generation.mutation.parent import Parent

MIRRORED = {"crossing_left": "crossing_right", "crossing_right": "crossing_left"}
"""The interaction a mirrored encounter is met in: every other reads the same either way."""


def as_made_by(parent: Parent, operator: str) -> Parent:
    """``parent`` with its failure where a child made by ``operator`` has it: mirrored left to
    right for ``mirror`` (without its track, which is the unmirrored run's), else where it
    was."""
    if operator != "mirror" or parent.failure_pose is None:
        return parent
    grid = parent.situation.grid
    pose = mirrored(grid.occupied.shape[1] * grid.resolution, *parent.failure_pose)
    return dataclasses.replace(parent, failure_pose=pose, track=None)


def mirrored(width: float, x: float, y: float, heading: float) -> tuple[float, float, float]:
    """A pose on a map ``width`` metres wide, mirrored left to right."""
    return width - x, y, math.remainder(math.pi - heading, math.tau)
