"""What a search is, before it runs: its options (strategy, measures, objective, the
mutation strategy's ``--class`` and ``--like``), checked against its spec (:func:`plan_search`);
the archive's measures (:class:`Measure`); how runs fall into generations; and the constants of
every strategy, stored with a search so that a resumed search is the same search.

Strategies: ``mutation`` (the default: situation operators on failing runs,
:mod:`sitgen.generation.mutation`), ``map-elites`` (quality diversity over the spec's fields and
seeds, :mod:`sitgen.generation.genome`), ``random`` (the campaign's own generation) and
``coverage`` (fields drawn toward uncovered cells, :mod:`sitgen.generation.guidance`). Which is
for what, and why mutation is the default: docs/search.md.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sitgen import _core
from sitgen.execution.jobs import (
    CampaignSpec,
)
from sitgen.generation.genome import (
    OPERATORS,
    P_CHOICE,
    SIGMA_ISO,
    SIGMA_LINE,
)
from sitgen.generation.guidance import (
    GUIDE_EPSILON,
    GUIDE_PRIOR_RUNS,
    GUIDE_STRATA,
)
from sitgen.generation.mutation import OPERATORS as SITUATION_OPERATORS
from sitgen.generation.mutation import TARGETED
from sitgen.triage.failures import check_class
from sitgen.triage.failures import classes as failure_classes
from sitgen.triage.variants import NO_PEER, interaction_context

STRATEGIES = ("mutation", "map-elites", "random", "coverage")
DEFAULT_STRATEGY = "mutation"
"""What ``sitgen search`` runs unless told: the strategy that finds the most robust failure
variants for a budget (docs/search.md, "Which strategy")."""


OBJECTIVES = ("score", "threshold")


"""``score``: the run's score (the most dangerous run per cell); ``threshold``: the paper's
aim of fewer low scores, min(score, threshold) / threshold, so every run at or above the
threshold is as good as any other and the search spends itself on filling cells."""


MEASURES = ("failure_class", "terrain", "peers", "min_clearance", "approach_side", "variant")


DEFAULT_MEASURES = ("failure_class", "terrain")


MUTATION_MEASURES = ("failure_class", "variant")
"""The mutation strategy's default: the archive's cells are the robust-distinct-failure space
(class × interaction/context, :mod:`sitgen.triage.variants`)."""


LOW_SCORE_POINTS = 10.0


"""The paper's low score (§4.2: the share of runs under 10 points)."""


INITIAL = 32


"""Runs of generation 0: the campaign's first jobs, before any variation."""


BATCH = 16


"""Runs per later generation (fixed, so the runs do not depend on the worker count)."""


FRESH_SHARE = 0.125


"""Share of a later generation's runs drawn fresh (the campaign's job of that index)."""


ARM_PRIOR_RUNS = 2.0
"""Weight, in runs, of every arm's Beta prior, whose mean is the share of new finds pooled over
all arms so far (empirical Bayes): a way not yet tried is drawn as about as good as the search
is doing, not as a coin flip."""
SCREENED_WEIGHT = {"robust": 1.0, "untested": 0.5, "knife_edge": 0.1}
"""An elite's weight as a parent by what the screen knows of its variant."""
FRONTIER_FLOOR = 0.1
"""An elite's weight as a parent where every variant the targeted operators could aim at from
its own has been shown (:meth:`Archive._frontier`), against 1.1 where none has."""
ARM_CONTEXTS = ("fresh", "confirmed", "unconfirmed")
"""What an arm's record is kept per: a fresh job, or an operator on a parent whose variant the
screen had confirmed robust when the child was made (a child that keeps that variant finds
nothing new) or had not (it may be the run that confirms it)."""
LOCAL = "local"
"""The arm of the local operators (every situation operator but the targeted ones), drawn as
one: each changes the situation a little and mostly keeps its parent's variant, so their
yields of new variants are alike and low, and learned as an arm each they took over half of a
500-evaluation search's runs before curiosity had told them apart (benches/search-notes.md)."""
MUTATION_TRIES = 3
"""Operators the mutation strategy tries on one parent before it runs a fresh job instead (a
directed search, which has none, tries them all)."""


CLEARANCE_CELLS = 5


"""Cells of the ``min_clearance`` measure below the monitor's default unsafe-proximity distance,
0.5 m (and one more for runs with no near miss)."""


CLEARANCE_STEP_M = 0.5 / CLEARANCE_CELLS


STRETCH_SHARE = 0.25
"""Share of a mutation search's children (not one from ``--like``) whose mission also goes on past
its goal (:func:`sitgen.generation.mutation.extended`). The operators change the walls and peers
round the place a parent failed at, so without it no child drives a route longer or more winding
than its parent's, and what shows only late in a long mission (a heading that drifts with the
turning done, a long route's bookkeeping) is met no more often than in fresh jobs."""
FRESH_STRETCH_SHARE = 0.5
"""Share of a mutation search's fresh jobs (one from ``--like`` has none) whose mission also
goes on past its goal, as :data:`STRETCH_SHARE` does for children. A fresh job aims at no
variant, so a later, more severe failure in the longer mission hides nothing it was made to
show, while the longer mission meets what shows only late (a heading that drifts with the
turning done, a long route's bookkeeping, a route that doubles back)."""
CROWD_SHARE = 0.25
"""Chance that a mutation search's staged approach (not one from ``--like``) is met by a crowd, one
more peer from each other side (``mutate``'s ``crowd``): a single staged peer never puts four robots
in the agent's view at once."""

MAX_BUDGET = 1_000_000


@dataclass(frozen=True)
class Measure:
    """One behaviour descriptor: a cell per label, read from a stored run."""

    name: str
    labels: tuple[str, ...]

    def label(self, run: dict[str, Any]) -> str:
        """The run's label on this measure, given its :func:`_view`."""
        if self.name == "failure_class":
            return str(run["failure_class"] or "none")
        if self.name == "terrain":
            return str(run["terrain"])
        if self.name == "peers":
            return str(min(len(self.labels) - 1, int(run["peers"] or 0)))
        if self.name == "variant":
            key = run["variant"]
            return "none" if key is None else interaction_context(key)
        if self.name == "min_clearance":
            clearance = run["min_clearance_m"]
            if clearance is None:
                return self.labels[-1]
            return self.labels[min(CLEARANCE_CELLS - 1, int(clearance / CLEARANCE_STEP_M))]
        return str(run["bearing"] or "none")

    def cell(self, run: dict[str, Any]) -> int:
        """The run's cell (a terrain the spec does not name, as one given whole: the first)."""
        label = self.label(run)
        return self.labels.index(label) if label in self.labels else 0


def _terrains(spec: CampaignSpec) -> tuple[str, ...]:
    dist = spec.vary.get("situation.terrain.preset", {})
    if "choice" in dist:
        return tuple(str(c) for c in dist["choice"])
    return (str(spec.situation.get("terrain", {}).get("preset") or "the spec's terrain"),)


def _most_peers(spec: CampaignSpec) -> int:
    most = int(spec.situation.get("mission", {}).get("peers_max", 5))
    dist = spec.vary.get("situation.mission.peers_max", {})
    for args in dist.values():
        most = max([most, *(int(a) for a in args if isinstance(a, int | float))])
    return most


def measures_for(spec: CampaignSpec, names: Sequence[str]) -> list[Measure]:
    """The measures ``names`` for searching ``spec``. Raises SpecError naming the option."""
    if not names:
        raise _core.SpecError(f"--measures: name one or two of {', '.join(MEASURES)}")
    if len(names) > 2 or len(set(names)) != len(names):
        raise _core.SpecError(
            f"--measures: {','.join(names)}: give one or two different measures (a grid "
            "of more dimensions has more cells than a budget can fill)"
        )
    out = []
    for name in names:
        if name == "failure_class":
            labels: tuple[str, ...] = ("none", *(k for k, _ in failure_classes()))
        elif name == "terrain":
            labels = _terrains(spec)
        elif name == "peers":
            labels = tuple(str(k) for k in range(_most_peers(spec) + 1))
        elif name == "min_clearance":
            near = (f"< {CLEARANCE_STEP_M * (k + 1):.1f} m" for k in range(CLEARANCE_CELLS))
            labels = (*near, "no near miss")
        elif name == "approach_side":
            labels = ("none", "front", "left", "right", "rear")
        elif name == "variant":
            dimensions = dict(_core.coverage_dimensions())
            interactions = (*dimensions["interaction"], NO_PEER)
            contexts = dimensions["context"]
            labels = ("none", *(f"{i}/{c}" for i in interactions for c in contexts))
        else:
            raise _core.SpecError(
                f"--measures: unknown measure `{name}`; expected some of {', '.join(MEASURES)}"
            )
        out.append(Measure(name, labels))
    return out


@dataclass(frozen=True)
class Like:
    """The run a directed search starts from: its situation, how it was run, and its failure."""

    source: str
    """``DB:RUN`` as given."""
    situation: str
    """Its situation (JSON)."""
    run_spec: dict[str, Any]
    run_seed: int
    failure_class: str
    failure_at: dict[str, Any] | None
    failure_cell: str | None
    """The interaction cell its failure began in (None: no peer took part)."""
    failure_s: float | None
    """When its failure began, seconds into the run."""


@dataclass(frozen=True)
class SearchPlan:
    """What a search does besides the campaign spec, seed and budget (stored with it: a resumed
    search must be the same search)."""

    strategy: str = DEFAULT_STRATEGY
    measures: tuple[str, ...] = DEFAULT_MEASURES
    objective: str = "score"
    threshold: float = LOW_SCORE_POINTS
    target_class: str | None = None
    """``--class``: the mutation strategy varies only runs of this failure class (once it has
    one), toward more variants of it."""
    like: Like | None = None
    """``--like``: the mutation strategy starts from this run and varies its descendants."""
    requirement: str | None = None
    """``--requirement``: falsify this requirement: the objective is how near to violating it
    (or how far past) each run came, from its robustness (docs/requirements.md)."""

    @staticmethod
    def from_dict(data: dict[str, Any]) -> SearchPlan:
        """The plan a store holds (its variation constants are this sitgen's)."""
        like = data.get("like")
        return SearchPlan(
            data["strategy"],
            tuple(data["measures"]),
            data["objective"],
            data["threshold"],
            data.get("target_class"),
            None if like is None else Like(**like),
            data.get("requirement"),
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "strategy": self.strategy,
            "measures": list(self.measures),
            "objective": self.objective,
            "threshold": self.threshold,
            # Only where given, so that the plan of a search without one reads as before.
            **({"requirement": self.requirement} if self.requirement is not None else {}),
            "initial": INITIAL,
            "batch": BATCH,
            "fresh_share": FRESH_SHARE,
            "p_choice": P_CHOICE,
            "operators": OPERATORS,
            "sigma_iso": SIGMA_ISO,
            "sigma_line": SIGMA_LINE,
            **(
                {
                    "situation_operators": list(SITUATION_OPERATORS),
                    "arm_prior_runs": ARM_PRIOR_RUNS,
                    "arm_contexts": list(ARM_CONTEXTS),
                    "arm_families": [*TARGETED, LOCAL],
                    "screened_weight": SCREENED_WEIGHT,
                    "frontier_floor": FRONTIER_FLOOR,
                    "mutation_tries": MUTATION_TRIES,
                    "stretch_share": STRETCH_SHARE,
                    "fresh_stretch_share": FRESH_STRETCH_SHARE,
                    "crowd_share": CROWD_SHARE,
                    "target_class": self.target_class,
                    "like": None if self.like is None else dataclasses.asdict(self.like),
                }
                if self.strategy == "mutation"
                else {}
            ),
            **(
                {
                    "guide_strata": GUIDE_STRATA,
                    "guide_epsilon": GUIDE_EPSILON,
                    "guide_prior_runs": GUIDE_PRIOR_RUNS,
                }
                if self.strategy == "coverage"
                else {}
            ),
        }


def plan_search(
    spec: CampaignSpec,
    strategy: str = DEFAULT_STRATEGY,
    measures: Sequence[str] = DEFAULT_MEASURES,
    objective: str = "score",
    threshold: float = LOW_SCORE_POINTS,
    target_class: str | None = None,
    like: Like | None = None,
    requirement: str | None = None,
) -> SearchPlan:
    """Check a search's options against its spec. Raises SpecError naming the option."""
    if requirement is not None:
        names = [r.get("name") for r in spec.run.get("requirement", [])]
        if requirement not in names:
            given = ", ".join(str(n) for n in names) or "none (give one with --require)"
            raise _core.SpecError(
                f"--requirement: no requirement called {requirement!r}; the spec's are {given}"
            )
    if strategy not in STRATEGIES:
        raise _core.SpecError(f"--strategy: `{strategy}` is not one of {', '.join(STRATEGIES)}")
    if (target_class is not None or like is not None) and strategy != "mutation":
        option = "--class" if target_class is not None else "--like"
        raise _core.SpecError(
            f"{option}: directs the mutation strategy (the default), not --strategy {strategy}"
        )
    if target_class is not None:
        check_class(target_class)
    if strategy == "mutation" and tuple(measures) == DEFAULT_MEASURES:
        measures = MUTATION_MEASURES
    if objective not in OBJECTIVES:
        raise _core.SpecError(f"--objective: `{objective}` is not one of {', '.join(OBJECTIVES)}")
    if not (math.isfinite(threshold) and threshold > 0):
        raise _core.SpecError(f"--threshold: {threshold} is not a positive number of points")
    measures_for(spec, measures)
    if like is not None and target_class is None:
        target_class = like.failure_class
    return SearchPlan(
        strategy, tuple(measures), objective, float(threshold), target_class, like, requirement
    )


def generation_of(index: int) -> int:
    """The generation of run ``index``."""
    return 0 if index < INITIAL else 1 + (index - INITIAL) // BATCH


def generation_runs(generation: int) -> range:
    """The run indices of a generation (before the budget truncates it)."""
    if generation == 0:
        return range(INITIAL)
    start = INITIAL + (generation - 1) * BATCH
    return range(start, start + BATCH)
