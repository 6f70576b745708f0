"""Search toward distinct failures: quality-diversity generation (MAP-Elites) over a campaign
spec's varied fields and the situation seed, compared with random generation at the same budget.

The paper (§6) notes that random generation "would spend most of its time generating safe
situations" and asks for a generator tuned to give fewer low scores without losing diversity.
A search keeps an *archive*: a grid of cells by behaviour descriptors (*measures*; by default the
run's failure class × its terrain kind), each cell holding the highest-objective run seen there
(by default the run's score). Each generation draws its situations by varying elites chosen
uniformly over the filled cells, so a rare failure is built on as often as a common one.

A situation's *genome* is one gene per ``[vary]`` entry of the campaign spec (the draw a
campaign makes: a choice's index, a real or whole value, a scale factor) and the situation seed.
Variation (:func:`vary`) follows Vassiliades & Mouret's Iso+LineDD on the real genes (Gaussian
noise plus a step along the line to a second elite, in each gene's range scaled to [0, 1]) and
resamples a choice with probability :data:`P_CHOICE`. A seed has no locality (any change of it,
or of a map's size, redraws everything it drives), so the genome keeps one seed per stage and
the :data:`OPERATORS` change one stage at a time: most often the elite's very map with the
robots drawn anew on it. The
archive is ``ribs``' ``GridArchive`` (elitist insertion per cell, QD statistics); the variation
is written here because ribs' emitters vary real vectors and a situation's genome is not one.

Runs are numbered like a campaign's jobs. Run ``i`` of generation 0 (the first :data:`INITIAL`)
and every *fresh* run (a share :data:`FRESH_SHARE` of each later generation, which keeps
exploring) is exactly the campaign's job ``i`` with the same seed; ``--strategy random`` makes
every run fresh, so it *is* the campaign. Generation ``g ≥ 1`` holds the next :data:`BATCH`
runs and is drawn from the archive as generations ``< g`` left it, with a stream seeded by
(seed, run index): a search is a pure function of (spec, seed, options), whatever the worker
count, and a budget only truncates it. Each run is stored as it ends (its generation, parents
and genes with it); the same command resumes, rebuilding the archive from the store.

``--strategy coverage`` steers toward situation coverage instead (docs/coverage.md): every
later generation draws each ``[vary]`` gene level by level, in proportion to the coverage
:func:`credit` of the runs drawn at that level, with the campaign job's seeds.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sitgen import _core
from sitgen.controllers.user import is_user_controller
from sitgen.execution.campaign import Executor, run_row, started_at
from sitgen.execution.jobs import (
    CampaignSpec,
    Job,
    campaign_from_data,
    check_campaign,
    check_workers,
    controller_names,
    express_job,
    job_seed,
)
from sitgen.generation.genome import (
    OPERATORS,
    P_CHOICE,
    SIGMA_ISO,
    SIGMA_LINE,
    Genome,
    fresh,
    solution,
    vary,
)
from sitgen.generation.guidance import (
    GUIDE_EPSILON,
    GUIDE_PRIOR_RUNS,
    GUIDE_STRATA,
    guide_weights,
    guided_genes,
)
from sitgen.generation.mutation import OPERATORS as SITUATION_OPERATORS
from sitgen.generation.mutation import (
    TARGETED,
    Parent,
    as_made_by,
    cut_past_failure,
    extended,
    mutate,
    neighbours,
)
from sitgen.store import KINDS, Store, StoreError, unpack_json
from sitgen.triage.failures import check_class
from sitgen.triage.failures import classes as failure_classes
from sitgen.triage.recall import regenerate, stored_run
from sitgen.triage.robustness import RERUNS
from sitgen.triage.variants import NO_PEER, Screen, interaction_context, variant
from sitgen.world.situation import Situation, generate_situation

if TYPE_CHECKING:
    from ribs.archives import GridArchive


STRATEGIES = ("map-elites", "random", "coverage", "mutation")


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
500-evaluation search's runs before curiosity had told them apart (docs/search.md)."""
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

    strategy: str = "map-elites"
    measures: tuple[str, ...] = DEFAULT_MEASURES
    objective: str = "score"
    threshold: float = LOW_SCORE_POINTS
    target_class: str | None = None
    """``--class``: the mutation strategy varies only runs of this failure class (once it has
    one), toward more variants of it."""
    like: Like | None = None
    """``--like``: the mutation strategy starts from this run and varies its descendants."""

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
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "strategy": self.strategy,
            "measures": list(self.measures),
            "objective": self.objective,
            "threshold": self.threshold,
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
    strategy: str = "map-elites",
    measures: Sequence[str] = DEFAULT_MEASURES,
    objective: str = "score",
    threshold: float = LOW_SCORE_POINTS,
    target_class: str | None = None,
    like: Like | None = None,
) -> SearchPlan:
    """Check a search's options against its spec. Raises SpecError naming the option."""
    if strategy not in STRATEGIES:
        raise _core.SpecError(f"--strategy: `{strategy}` is not one of {', '.join(STRATEGIES)}")
    if (target_class is not None or like is not None) and strategy != "mutation":
        option = "--class" if target_class is not None else "--like"
        raise _core.SpecError(f"{option}: directs the mutation strategy (--strategy mutation)")
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
    return SearchPlan(strategy, tuple(measures), objective, float(threshold), target_class, like)


def generation_of(index: int) -> int:
    """The generation of run ``index``."""
    return 0 if index < INITIAL else 1 + (index - INITIAL) // BATCH


def generation_runs(generation: int) -> range:
    """The run indices of a generation (before the budget truncates it)."""
    if generation == 0:
        return range(INITIAL)
    start = INITIAL + (generation - 1) * BATCH
    return range(start, start + BATCH)


@dataclass(frozen=True)
class Child:
    """One run a generation asks for."""

    index: int
    genome: Genome
    parents: tuple[int, ...]
    """The elites it was varied from (none for a fresh run)."""
    operator: str
    """How: one of :data:`OPERATORS` or :data:`SITUATION_OPERATORS`, or ``fresh``."""
    situation: str | None = None
    """A mutation's situation (JSON), run as given; None: the genome's job."""
    run_seed: int | None = None
    """Its sensor-noise seed where it is not the genome's (a directed search's: the run it
    started from)."""
    aim: str | None = None
    """A targeted operator's target (interaction, terrain context or both; None: drawn by
    the operator), kept so that whether children meet what they were aimed at can be
    counted (``make bench-search``)."""

    def stored_genes(self, spec: CampaignSpec) -> dict[str, Any]:
        aim = {} if self.aim is None else {"aim": self.aim}
        return {"operator": self.operator, **aim, **self.genome.as_dict(spec)}


@dataclass(frozen=True)
class ArchiveStats:
    """How full and how good an archive is."""

    cells: int
    """Cells filled."""
    qd_score: float
    """Sum of the elites' objectives (ribs' QD score, offset 0: objectives are ≥ 0)."""
    best: float
    """Best objective."""


class Archive:
    """The search's archive: ``ribs``' GridArchive over the plan's measures, with each elite's
    run id and the genome of every run told to it."""

    def __init__(self, spec: CampaignSpec, seed: int, plan: SearchPlan) -> None:
        from ribs.archives import GridArchive

        self.spec, self.seed, self.plan = spec, seed, plan
        self.measures = measures_for(spec, plan.measures)
        dims = [len(m.labels) for m in self.measures]
        self.grid: GridArchive = GridArchive(
            solution_dim=max(1, len(spec.vary)),
            dims=dims,
            ranges=[(0.0, float(d)) for d in dims],
            extra_fields={"run_id": ((), np.int64)},
        )
        self.genomes: dict[int, Genome] = {}
        self.covered: list[tuple[Genome, tuple[str, ...]]] = []
        """Each run's genome and the coverage cells it exercised (errors left out)."""
        self.told = 0
        """Runs told (errors included)."""
        self.parent_of: Callable[[int], Parent] | None = None
        """The mutation strategy's view of a stored run (set by :func:`run_search`)."""
        self.classes: dict[int, str | None] = {}
        """Each run's failure class (errors left out)."""
        self.cell_runs: dict[tuple[int, ...], int] = {}
        """Runs told per cell (the mutation strategy's novelty: a rarely reached cell's elite
        is varied more often)."""
        self.cell_of: dict[int, tuple[int, ...]] = {}
        self.variant_of: dict[int, str | None] = {}
        self.variants_seen: set[str] = set()
        """Every failure variant among the runs told."""
        self.arm_runs: dict[tuple[str, str], int] = {}
        """Runs told per way of making them (``fresh`` or a situation operator), in its
        :data:`ARM_CONTEXTS` context."""
        self.arm_new: dict[tuple[str, str], int] = {}
        """Of those, runs that found a new variant: one that recurred under perturbation where
        runs are screened (:attr:`screen`), else one not seen before."""
        self.confirmed_at_ask: frozenset[str] = frozenset()
        """The variants confirmed robust when this generation's children were made."""
        self.screen: Screen | None = None
        """The mutation strategy's screen of its runs (set by :func:`run_search`): each new
        variant's run rerun in perturbed copies by the yardstick's rule, so that the search is
        rewarded for robust failures and varies them rather than knife-edge ones."""

    def objective(self, score: float) -> float:
        if self.plan.objective == "threshold":
            return min(score, self.plan.threshold) / self.plan.threshold
        return score

    def cells(self, run: dict[str, Any]) -> tuple[int, ...]:
        """The run's cell on each measure."""
        return tuple(m.cell(run) for m in self.measures)

    def tell(self, runs: Sequence[dict[str, Any]]) -> None:
        """Add one generation's runs (their :func:`_view`, in index order); runs that could
        not be made are remembered but not placed."""
        for run in runs:
            self.genomes[run["id"]] = run["genome"]
            if run["outcome"] != "error":
                self.covered.append((run["genome"], run["cells"]))
                self.classes[run["id"]] = run["failure_class"]
                cell = self.cells(run)
                self.cell_of[run["id"]] = cell
                self.variant_of[run["id"]] = run["variant"]
                self.cell_runs[cell] = self.cell_runs.get(cell, 0) + 1
                key, arm = run["variant"], (self._arm_context(run), _family(run["operator"]))
                self.arm_runs[arm] = self.arm_runs.get(arm, 0) + 1
                if self._new_find(run["id"], key):
                    self.arm_new[arm] = self.arm_new.get(arm, 0) + 1
                if key is not None:
                    self.variants_seen.add(key)
        self.told += len(runs)
        placed = [r for r in runs if r["outcome"] != "error"]
        if not placed:
            return
        self.grid.add(
            np.stack([solution(self.spec, r["genome"]) for r in placed]),
            np.array([self.objective(r["score"]) for r in placed]),
            np.array([[c + 0.5 for c in self.cells(r)] for r in placed]),
            run_id=np.array([r["id"] for r in placed], dtype=np.int64),
        )

    def elites(self) -> list[int]:
        """The elites' run ids, by cell."""
        if self.grid.empty:
            return []
        data = self.grid.data(["index", "run_id"])
        pairs = zip(data["index"].tolist(), data["run_id"].tolist(), strict=True)
        return [int(r) for _, r in sorted(pairs)]

    def ask(self, generation: int) -> list[Child]:
        """Generation ``generation``'s runs (all of them; the budget truncates)."""
        if self.plan.strategy == "mutation":
            return self._ask_mutation(generation)
        elites = self.elites()
        children = []
        guide = (
            guide_weights(self.spec, self.covered)
            if self.plan.strategy == "coverage" and generation > 0
            else None
        )
        for index in generation_runs(generation):
            rng = np.random.Generator(np.random.PCG64([self.seed, index, 1]))
            if guide is not None:
                genes = guided_genes(self.spec, guide, rng)
                own = job_seed(self.seed, index)
                children.append(Child(index, Genome(genes, own, own, own), (), "guided"))
                continue
            is_fresh = (
                generation == 0
                or self.plan.strategy == "random"
                or not elites
                or rng.random() < FRESH_SHARE
            )
            if is_fresh:
                children.append(Child(index, fresh(self.spec, self.seed, index), (), "fresh"))
                continue
            a = elites[int(rng.integers(len(elites)))]
            b = elites[int(rng.integers(len(elites)))]
            operator, genome = vary(
                self.spec, self.seed, index, self.genomes[a], self.genomes[b], rng
            )
            children.append(Child(index, genome, (a,) if a == b else (a, b), operator))
        return children

    def _ask_mutation(self, generation: int) -> list[Child]:
        """The mutation strategy: each child is a fresh job or one situation operator away
        from an elite, the choice a curious one (:meth:`_arm`); elites drawn by novelty (of the
        target class's cells, once there are any) and frontier. Generation 0 is the campaign's
        first jobs (:meth:`_fresh`: some stretched), or the ``--like`` run and mutants of it (no
        fresh jobs in a directed search from ``--like``). A child's mission ends a waypoint past
        where its parent failed (:func:`cut_past_failure`), then may go on anew."""
        like = self.plan.like
        elites = self.elites()
        if self.screen is not None:
            self.confirmed_at_ask = frozenset(self.screen.robust)
        if self.plan.target_class is not None:
            targeted = [e for e in elites if self.classes.get(e) == self.plan.target_class]
            elites = targeted or elites
        children = []
        for index in generation_runs(generation):
            rng = np.random.Generator(np.random.PCG64([self.seed, index, 2]))
            genome = fresh(self.spec, self.seed, index)
            if like is not None and index == 0:
                children.append(Child(index, genome, (), "like", like.situation, like.run_seed))
                continue
            if like is None and (generation == 0 or not elites):
                children.append(self._fresh(index))
                continue
            if like is not None and (generation == 0 or not elites):
                parent_id, parent = -1, self.like_parent()
            else:
                parent_id = elites[self._novel(elites, rng)]
                assert self.parent_of is not None
                parent = self.parent_of(parent_id)
                genome = self.genomes[parent_id]
            child, operator, aim = None, "fresh", None
            # A mirrored child is its parent met from the other side: only worth a run where
            # that side is a variant not seen yet (a crossing from the left or right).
            unaimed = like is None and not self._unseen(parent, "mirror")
            tried: set[str] = {"mirror"} if unaimed else set()
            context = self._parent_context(parent.variant)
            # A directed search has no fresh jobs to fall back on: it tries every operator.
            for _ in range(MUTATION_TRIES if like is None else len(SITUATION_OPERATORS)):
                operator = self._arm(rng, tried, like is None, context)
                if operator == "fresh":
                    break
                tried.add(operator)
                crowd = CROWD_SHARE if like is None else 0.0
                aim, others = self._targets(parent, operator, rng)
                child = mutate(parent, operator, rng, aim, others, crowd)
                if child is not None:
                    break
            run_seed = None if like is None else like.run_seed
            if child is None and like is not None:
                # No operator could change this parent: it is run again as it is.
                child, operator = parent.situation.to_json(), "like"
            if child is None:
                children.append(self._fresh(index))
            else:
                if operator != "like":
                    child = cut_past_failure(child, as_made_by(parent, operator))
                if like is None and rng.random() < STRETCH_SHARE:
                    child = extended(child, rng)
                parents = (parent_id,) if parent_id >= 0 else ()
                aimed = aim if operator in TARGETED else None
                children.append(Child(index, genome, parents, operator, child, run_seed, aimed))
        return children

    def _fresh(self, index: int) -> Child:
        """Run ``index``'s fresh job for a mutation search not from ``--like``: the campaign's
        job, its mission going on past its goal in :data:`FRESH_STRETCH_SHARE` of them (the job
        as it is where it cannot be made here or no route goes on)."""
        genome = fresh(self.spec, self.seed, index)
        plain = Child(index, genome, (), "fresh")
        rng = np.random.Generator(np.random.PCG64([self.seed, index, 3]))
        if rng.random() >= FRESH_STRETCH_SHARE:
            return plain
        job = _job(self.spec, plain)
        if job.error is not None:
            return plain
        try:
            situation = generate_situation(job.situation, seed=job.seed)
        except (_core.GenerationFailed, _core.SpecError):
            return plain
        made = situation.to_json()
        stretched = extended(made, rng)
        return plain if stretched == made else Child(index, genome, (), "fresh", stretched)

    def _new_find(self, run_id: int, key: str | None) -> bool:
        if key is None:
            return False
        if self.screen is not None:
            return self.screen.robust.get(key) == run_id
        return key not in self.variants_seen

    def screen_runs(self, store: Store, runs: Sequence[dict[str, Any]]) -> None:
        """Test the runs (in run order) whose variant the screen wants, before they are told."""
        if self.screen is None:
            return
        for run in runs:
            key = run["variant"]
            if self.screen.wants(key):
                self.screen.test(store, int(run["id"]), key, 0, RERUNS)

    def _parent_context(self, key: str | None) -> str:
        """The :data:`ARM_CONTEXTS` context of a child of a parent of variant ``key``."""
        return "confirmed" if key in self.confirmed_at_ask else "unconfirmed"

    def _arm_context(self, run: dict[str, Any]) -> str:
        """The context a told run was made in (its parent's, as when it was made: a stored
        run, or the ``--like`` run for a child with none)."""
        if run["operator"] not in SITUATION_OPERATORS:
            return "fresh"
        if run["parents"]:
            return self._parent_context(self.variant_of.get(run["parents"][0]))
        like = self.plan.like
        assert like is not None
        return self._parent_context(variant(like.failure_class, _like_coverage(like)))

    def _arm(
        self, rng: np.random.Generator, tried: set[str], fresh_allowed: bool, context: str
    ) -> str:
        """Curiosity over the ways to make a child (``fresh`` and each situation operator on a
        parent in ``context``): Thompson sampling on the share of each one's runs that found
        a new variant (robust, where runs are screened), Beta(prior + found, prior + runs -
        found) with an empirical prior (:data:`ARM_PRIOR_RUNS`), so the search spends its runs
        on what finds new failures, whichever that turns out to be for the controller under
        test; ``tried``: ways already tried for this child."""
        untried = [a for a in SITUATION_OPERATORS if a not in tried]
        arms = [("fresh", "fresh")] if fresh_allowed else []
        arms += [(context, f) for f in dict.fromkeys(map(_family, untried))]
        found, runs = sum(self.arm_new.values()), sum(self.arm_runs.values())
        share = (found + 1) / (runs + 2)
        a0, b0 = ARM_PRIOR_RUNS * share, ARM_PRIOR_RUNS * (1 - share)
        draws = [
            rng.beta(
                a0 + self.arm_new.get(a, 0), b0 + self.arm_runs.get(a, 0) - self.arm_new.get(a, 0)
            )
            for a in arms
        ]
        family = arms[int(np.argmax(draws))][1]
        if family != LOCAL:
            return family
        local = [a for a in untried if _family(a) == LOCAL]
        return local[int(rng.integers(len(local)))]

    def _targets(
        self, parent: Parent, operator: str, rng: np.random.Generator
    ) -> tuple[str | None, list[str]]:
        """For a targeted operator, a neighbour of the parent's variant (its interaction, its
        terrain context, or both changed) not seen yet, if there is one (None lets it draw), and the
        other unseen ones, which a child may make instead."""
        unseen = self._unseen(parent, operator)
        if not unseen:
            return None, []
        aim = int(rng.integers(len(unseen)))
        return unseen[aim], unseen[:aim] + unseen[aim + 1 :]

    def _unseen(self, parent: Parent, operator: str) -> list[str]:
        """The targets of ``operator`` from the parent's variant (:func:`neighbours`) whose
        variant no run has shown yet (none for an operator that aims at nothing)."""
        if parent.variant is None or operator not in TARGETED:
            return []
        targets = neighbours(parent.variant, operator)
        return [t for t, key in targets.items() if key not in self.variants_seen]

    def _novel(self, elites: list[int], rng: np.random.Generator) -> int:
        """An elite's position, drawn with weight 1/runs of its cell (novelty: the rarer a
        failure variant has been, the more often it is varied), times its variant's
        robustness where runs are screened (:data:`SCREENED_WEIGHT`): a knife-edge failure's
        children mostly fail otherwise or not at all; and times its frontier
        (:meth:`_frontier`)."""
        weights = np.array(
            [
                self._robust_weight(e)
                * self._frontier(e)
                / self.cell_runs.get(self.cell_of.get(e, ()), 1)
                for e in elites
            ]
        )
        return int(rng.choice(len(elites), p=weights / weights.sum()))

    def _frontier(self, run_id: int) -> float:
        """:data:`FRONTIER_FLOOR` + the share of the variants the targeted operators can aim
        at from the elite's variant (:func:`neighbours`) that no run has shown yet: a parent
        all of whose neighbours are known gives children aimed at nothing new (1 for a run
        that did not fail: it has no variant to aim from)."""
        key = self.variant_of.get(run_id)
        if key is None:
            return 1.0
        targets = _aimable(key)
        unseen = sum(v not in self.variants_seen for v in targets)
        return FRONTIER_FLOOR + unseen / len(targets)

    def _robust_weight(self, run_id: int) -> float:
        key = self.variant_of.get(run_id)
        if self.screen is None or key is None:
            return 1.0
        if key in self.screen.robust:
            return SCREENED_WEIGHT["robust"]
        if self.screen.attempts.get(key, 0) > 0:
            return SCREENED_WEIGHT["knife_edge"]
        return SCREENED_WEIGHT["untested"]

    def like_parent(self) -> Parent:
        """The ``--like`` run as a parent."""
        like = self.plan.like
        assert like is not None
        return Parent.of(
            Situation(like.situation, check_start=False),
            _like_coverage(like),
            {"class": like.failure_class, "features": {"start_s": like.failure_s}},
        )

    def stats(self) -> ArchiveStats:
        s = self.grid.stats
        best = s.obj_max if s.num_elites and s.obj_max is not None else 0.0
        return ArchiveStats(int(s.num_elites), float(s.qd_score), float(best))


def _family(operator: str) -> str:
    """The arm a way of making a run is drawn and recorded under: :data:`LOCAL` for a local
    operator, else the way itself (``fresh``, a targeted operator)."""
    return LOCAL if operator in SITUATION_OPERATORS and operator not in TARGETED else operator


def _like_coverage(like: Like) -> dict[str, Any]:
    """The part of the ``--like`` run's coverage record that places its failure."""
    return {"failure_at": like.failure_at, "failure_cell": like.failure_cell}


def _view(store: Store, spec: CampaignSpec, ids: Sequence[int]) -> list[dict[str, Any]]:
    """What the archive reads of stored runs ``ids`` (one query; in run order)."""
    marks = ", ".join("?" for _ in ids)
    rows = store.db.execute(
        "SELECT r.id, r.outcome, r.score, r.failure_class, r.failure, r.min_clearance_m, "
        "r.genes, r.coverage, r.parents, s.terrain, s.peers FROM runs r "
        "JOIN situations s ON s.id = r.situation_id "
        f"WHERE r.id IN ({marks}) ORDER BY r.id",
        list(ids),
    )
    out = []
    for (
        run_id,
        outcome,
        score,
        cls,
        failure,
        clearance,
        genes,
        coverage,
        parents,
        terrain,
        peers,
    ) in rows:
        features = json.loads(failure)["features"] if failure else {}
        gene_data = None if genes is None else json.loads(genes)
        record = unpack_json(coverage) if coverage else None
        out.append(
            {
                "id": run_id,
                "outcome": outcome,
                "score": score,
                "failure_class": cls,
                "bearing": features.get("bearing"),
                "min_clearance_m": clearance,
                "genome": None if gene_data is None else Genome.from_dict(spec, gene_data),
                "cells": tuple(record["cells"]) if record else (),
                "variant": variant(cls, record),
                "operator": None if gene_data is None else gene_data.get("operator"),
                "parents": json.loads(parents) if parents else [],
                "terrain": terrain,
                "peers": peers,
            }
        )
    return out


@dataclass(frozen=True)
class SearchProgress:
    """Where a search stands (for a progress bar)."""

    runs: int
    budget: int
    cells: int
    classes: int
    """Failure classes found so far."""
    best: float
    """Best objective in the archive."""


@dataclass(frozen=True)
class SearchResult:
    """What a search call did."""

    ran: int
    total: int
    interrupted: bool
    wall_s: float
    cells: int
    qd_score: float


@functools.cache
def _aimable(key: str) -> frozenset[str]:
    """The variants the targeted operators can aim at from variant ``key`` (fixed per key, and
    asked for every elite at every draw of a parent)."""
    return frozenset(v for op in TARGETED for v in neighbours(key, op).values())


def _job(spec: CampaignSpec, child: Child) -> Job:
    """The child's job (a stage whose seed is not the run's gets it in its spec); one whose
    genes make a bad spec carries its error."""
    g = child.genome
    if child.situation is not None:
        situation = json.loads(child.situation)
        return Job(child.index, g.seed, situation, dict(spec.run), run_seed=child.run_seed)
    try:
        job = express_job(spec, child.index, g.seed, g.genes)
    except _core.SpecError as e:
        return Job(child.index, g.seed, dict(spec.situation), dict(spec.run), f"spec: {e}")
    for stage, own in (("terrain", g.terrain_seed), ("mission", g.mission_seed)):
        if own != g.seed:
            job.situation.setdefault(stage, {})["seed"] = own
    return job


def run_search(
    spec: CampaignSpec,
    db: str | Path,
    seed: int = 0,
    budget: int = 500,
    plan: SearchPlan | None = None,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    on_progress: Callable[[SearchProgress], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> SearchResult:
    """Run (or resume) a search of ``budget`` runs into store ``db``. The spec, options and
    controllers are checked before any run; ``stop()`` is checked after every run, and the
    runs in flight are kept."""
    if not 1 <= budget <= MAX_BUDGET:
        raise _core.SpecError(f"--budget: {budget} is not in [1, {MAX_BUDGET}]")
    plan = plan or SearchPlan()
    plan = plan_search(
        spec,
        plan.strategy,
        plan.measures,
        plan.objective,
        plan.threshold,
        plan.target_class,
        plan.like,
    )
    workers = check_workers(workers, backend)
    started = time.perf_counter()
    check_campaign(spec, seed, budget, stop)
    if stop is not None and stop():
        return SearchResult(0, 0, True, time.perf_counter() - started, 0, 0.0)
    user = any(is_user_controller(name) for _, name in controller_names(spec))
    with Store(db, create=True) as store:
        store.lock_for_writing()
        store.start_campaign(
            spec.source, seed, budget, _core.__version__, started_at(), search=plan.as_dict()
        )
        done = store.done_ids()
        archive = Archive(spec, seed, plan)
        archive.parent_of = lambda run_id: parent_of(store, run_id)
        if plan.strategy == "mutation":
            archive.screen = Screen(workers if backend == "local" else 1)
        executor = Executor(workers, backend, address, user=user)
        classes_seen = {
            c for (c,) in store.db.execute("SELECT DISTINCT failure_class FROM runs") if c
        }
        ran = 0
        interrupted = False

        def progress() -> None:
            if on_progress is not None:
                s = archive.stats()
                on_progress(SearchProgress(len(done), budget, s.cells, len(classes_seen), s.best))

        progress()
        generation = 0
        while generation_runs(generation).start < budget:
            children = [c for c in archive.ask(generation) if c.index < budget]
            views = _view(store, spec, [c.index for c in children if c.index in done])
            _check_stored(store, children, views)
            todo = [c for c in children if c.index not in done]
            if todo and not interrupted:
                by_index = {c.index: c for c in todo}
                for job, result in executor.results([_job(spec, c) for c in todo]):
                    child = by_index[job.index]
                    row = dataclasses.replace(
                        run_row(job, result),
                        generation=generation,
                        parents=child.parents,
                        genes=child.stored_genes(spec),
                    )
                    # One transaction per run: a kill loses only the runs in flight.
                    store.add_runs([row])
                    done.add(job.index)
                    ran += 1
                    failure = (row.record or {}).get("failure")
                    if failure:
                        classes_seen.add(failure["class"])
                    progress()
                    if stop is not None and stop():
                        executor.stop()
            if any(c.index not in done for c in children):
                interrupted = True
                break
            views += _view(store, spec, [c.index for c in todo])
            views.sort(key=lambda v: int(v["id"]))
            archive.screen_runs(store, views)
            archive.tell(views)
            generation += 1
        total = store.run_count()
        stats = archive.stats()
    return SearchResult(
        ran, total, interrupted, time.perf_counter() - started, stats.cells, stats.qd_score
    )


def parent_of(store: Store, run_id: int) -> Parent:
    """Stored run ``run_id`` as a parent of the mutation strategy."""
    return stored_parent(store, run_id)[1]


def stored_parent(store: Store, run_id: int) -> tuple[dict[str, Any], Parent, dict[str, Any]]:
    """Stored run ``run_id`` (:func:`stored_run`), as a parent (its situation, kept or made
    again, and where its failure began), and its coverage record."""
    row = stored_run(store, run_id)
    if row["situation"] is not None:
        situation = Situation(row["situation"], check_start=False)
    else:
        situation = regenerate(row)
    coverage, failure, time_s, steps = store.db.execute(
        "SELECT coverage, failure, time_s, steps FROM runs WHERE id = ?", (run_id,)
    ).fetchone()
    record: dict[str, Any] = unpack_json(coverage) if coverage else {}
    parent = Parent.of(
        situation,
        record,
        json.loads(failure) if failure else None,
        store.trajectory(run_id) if failure else None,
        time_s / steps if steps else None,
    )
    return row, parent, record


def _check_stored(store: Store, children: list[Child], views: list[dict[str, Any]]) -> None:
    """A resumed generation must ask for what was stored (``views``): a store written by
    another sitgen (other variation) cannot be resumed without mixing two searches."""
    asked = {c.index: c.genome for c in children}
    for view in views:
        if view["genome"] != asked[view["id"]]:
            raise StoreError(
                f"{store.path}: run {view['id']} is not the run this search asks for there "
                "(written by another sitgen?); give a new --db"
            )


@dataclass
class SearchReplay:
    """A stored search replayed generation by generation: the archive it ends with and the
    figures over budget."""

    archive: Archive
    curve: list[dict[str, float]] = field(default_factory=list)
    """After each generation: runs, QD score, failure classes found."""


def replay(store: Store) -> SearchReplay:
    """Rebuild a stored search's archive, and its figures over budget. Raises StoreError if
    the store holds no search."""

    raw = store.plan("search")
    campaign = store.campaign()
    if raw is None or campaign is None:
        raise StoreError(
            f"{store.path}: holds a {KINDS[store.kind()]}, not a search (sitgen search)"
        )
    spec = campaign_from_data(campaign["spec"])
    plan = SearchPlan.from_dict(raw)
    archive = Archive(spec, campaign["seed"], plan)
    out = SearchReplay(archive)
    stored = store.done_ids()
    classes: set[str] = set()
    generation = 0
    while ids := [i for i in generation_runs(generation) if i in stored]:
        runs = _view(store, spec, ids)
        archive.tell(runs)
        classes.update(r["failure_class"] for r in runs if r["failure_class"])
        out.curve.append(
            {
                "runs": archive.told,
                "qd_score": archive.stats().qd_score,
                "classes": len(classes),
            }
        )
        generation += 1
    return out


def elite_grid(archive: Archive) -> list[list[dict[str, Any] | None]]:
    """The archive as rows (first measure) × columns (second measure, or one column): each
    cell its elite's run id and objective, or None."""
    labels = [m.labels for m in archive.measures]
    rows = len(labels[0])
    cols = len(labels[1]) if len(labels) > 1 else 1
    grid: list[list[dict[str, Any] | None]] = [[None] * cols for _ in range(rows)]
    if archive.grid.empty:
        return grid
    data = archive.grid.data(["index", "run_id", "objective"])
    cells = archive.grid.int_to_grid_index(data["index"])
    elites = zip(cells.tolist(), data["run_id"].tolist(), data["objective"].tolist(), strict=True)
    for cell, r, o in elites:
        row, col = cell[0], cell[1] if cols > 1 else 0
        grid[row][col] = {"run": int(r), "objective": float(o)}
    return grid


def like_run(source: str) -> Like:
    """``--like DB:RUN``: the stored run a directed search starts from (it must have failed).
    Raises SpecError naming the option."""
    db, _, run = source.rpartition(":")
    if not db or not run.isdigit():
        raise _core.SpecError(f"--like: `{source}` is not DB:RUN (a store and a run id in it)")
    if not Path(db).is_file():
        raise _core.SpecError(f"--like: {db}: no such store")
    with Store(db) as store:
        row, parent, record = stored_parent(store, int(run))
    if row["failure"] is None:
        raise _core.SpecError(f"--like: run {run} of {db} did not fail")
    return Like(
        source,
        parent.situation.to_json(),
        row["run_spec"],
        int(row["run_seed"]),
        str(row["failure"]["class"]),
        record.get("failure_at"),
        record.get("failure_cell"),
        row["failure"]["features"].get("start_s"),
    )
