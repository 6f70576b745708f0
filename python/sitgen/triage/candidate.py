"""What shrinking edits and what it gives: a :class:`Candidate` situation (the grid and the
robots), the :class:`Target` every kept candidate must still fail, the :class:`Measure` of a
situation's size and the :class:`ShrinkResult` (:mod:`sitgen.triage.shrink` does the shrinking)."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.world.situation import Situation


@dataclass(frozen=True)
class Target:
    """What a candidate must keep: the run's failure class is ``failure_class`` or, with
    ``shown``, ``failure_class`` is among the classes its events show (to shrink toward a
    failure that a more severe one hides)."""

    failure_class: str
    shown: bool = False

    def met(self, probe: dict[str, Any]) -> bool:
        if not probe["ok"]:
            return False
        if self.shown:
            return any(key == self.failure_class for key, _ in probe["first_s"])
        return bool(probe["class"] == self.failure_class)

    def time_s(self, probe: dict[str, Any]) -> float:
        """When the first event of the class began in ``probe``'s run."""
        return float(dict(probe["first_s"])[self.failure_class])


@dataclass(frozen=True)
class Measure:
    """How big a situation is, as the summary compares them."""

    peers: int
    obstacle_cells: int
    route_length_m: float
    """The agent's route: start, then its waypoints."""
    time_to_failure_s: float
    """Simulated seconds to the first event of the class."""
    map_m: tuple[float, float]
    """Width and height, metres."""


@dataclass
class ShrinkResult:
    """A shrink: the original and the smallest situation found that still fails the same way."""

    original: Situation
    minimal: Situation
    failure_class: str
    run_spec: dict[str, Any]
    run_seed: int
    before: Measure
    after: Measure
    probes: int
    """Runs made: the original's, every valid candidate's, and the runs that find where
    robots stood or drove (a restart's partial run counts as one)."""
    skipped: int
    """Invalid candidates skipped without a run."""
    wall_s: float
    reductions: list[str] = field(default_factory=list)
    """What helped, in order, e.g. ``peers 5 → 1``."""
    exhausted: bool = False
    """Whether the probe budget ran out before shrinking was done."""

    def summary(self) -> dict[str, Any]:
        return {
            "class": self.failure_class,
            "before": asdict(self.before),
            "after": asdict(self.after),
            "probes": self.probes,
            "skipped": self.skipped,
            "wall_s": round(self.wall_s, 3),
            "reductions": self.reductions,
            "exhausted": self.exhausted,
        }

    def store_row(self) -> dict[str, Any]:
        """The columns of the store's ``shrinks`` table (docs/store.md)."""
        return {
            "failure_class": self.failure_class,
            "situation": self.minimal.to_json(),
            "run_spec": json.dumps(self.run_spec, sort_keys=True),
            "run_seed": self.run_seed,
            "before": json.dumps(asdict(self.before)),
            "after": json.dumps(asdict(self.after)),
            "reductions": json.dumps(self.reductions),
            "probes": self.probes,
            "skipped": self.skipped,
            "wall_s": self.wall_s,
            "sitgen_version": _core.__version__,
        }


@dataclass(frozen=True)
class Candidate:
    """A situation as shrinking edits it: the occupancy grid and the robots (as in the file)."""

    occupied: npt.NDArray[np.bool_]
    robots: tuple[dict[str, Any], ...]

    @cached_property
    def key(self) -> str:
        h = hashlib.sha256(self.occupied.tobytes())
        h.update(repr(self.occupied.shape).encode())
        h.update(json.dumps(self.robots, sort_keys=True).encode())
        return h.hexdigest()

    def with_robots(self, robots: Sequence[dict[str, Any]]) -> Candidate:
        """These robots, numbered in order (the agent first)."""
        return replace(self, robots=tuple({**r, "id": i} for i, r in enumerate(robots)))
