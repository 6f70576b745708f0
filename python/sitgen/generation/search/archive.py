"""The search's archive and how each generation's runs are chosen from it.

A search keeps an *archive*: a grid of cells by behaviour descriptors (*measures*; by default
the run's failure class × its terrain kind, for mutation failure class × variant), each cell
holding the highest-objective run seen there (by default the run's score):
:class:`sitgen.generation.search.elites.Elites`.

MAP-Elites draws each child by varying elites chosen uniformly over the filled cells (so a rare
failure is built on as often as a common one) with the genome's operators
(:mod:`sitgen.generation.genome`: Iso+LineDD on the real genes, one stage's seed at a time). The
mutation strategy chooses, for each child, a *way* (a fresh campaign job, a targeted operator,
or the local operators as one arm) by Thompson sampling on each way's record of new robust
variants, kept per parent context, and a parent among the elites weighted by novelty, by what
the screen knows of its variant and by how much of its variant's neighbourhood is unseen
(:meth:`Archive._ask_mutation`); the child is :func:`sitgen.generation.mutation.mutate`'s.
``--strategy coverage`` draws every later generation's genes toward uncovered cells
(:mod:`sitgen.generation.guidance`).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.execution.jobs import (
    CampaignSpec,
    Job,
    express_job,
    job_seed,
)
from sitgen.generation.genome import (
    Genome,
    fresh,
    vary,
)
from sitgen.generation.guidance import (
    guide_weights,
    guided_genes,
)
from sitgen.generation.mutation import OPERATORS as SITUATION_OPERATORS
from sitgen.generation.mutation import TARGETED, mutate, neighbours
from sitgen.generation.mutation.mirror import as_made_by
from sitgen.generation.mutation.parent import Parent, cut_past_failure, extended
from sitgen.generation.search.elites import Elite, Elites
from sitgen.generation.search.plan import (
    ARM_PRIOR_RUNS,
    CROWD_SHARE,
    FRESH_SHARE,
    FRESH_STRETCH_SHARE,
    FRONTIER_FLOOR,
    LOCAL,
    MUTATION_TRIES,
    SCREENED_WEIGHT,
    STRETCH_SHARE,
    Like,
    SearchPlan,
    generation_runs,
    measures_for,
)
from sitgen.store import Store
from sitgen.triage.robustness import RERUNS
from sitgen.triage.variants import Screen, variant
from sitgen.world.situation import Situation, generate_situation


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
    """Sum of the elites' objectives (the QD score, offset 0: objectives are ≥ 0)."""
    best: float
    """Best objective."""


class Archive:
    """The search's archive: the elites over the plan's measures, and the genome of every run
    told to it."""

    def __init__(self, spec: CampaignSpec, seed: int, plan: SearchPlan) -> None:
        self.spec, self.seed, self.plan = spec, seed, plan
        self.measures = measures_for(spec, plan.measures)
        self.grid = Elites([len(m.labels) for m in self.measures])
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

    def objective(self, run: dict[str, Any]) -> float:
        """What the search maximises of a run: with ``--requirement`` how near to violating
        the requirement it came or how far past (:func:`falsification`), else its score (or
        the paper's threshold of it)."""
        if self.plan.requirement is not None:
            return falsification(run["robustness"].get(self.plan.requirement))
        score = float(run["score"])
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
            [self.cells(r) for r in placed],
            [Elite(self.objective(r), int(r["id"])) for r in placed],
        )

    def elites(self) -> list[int]:
        """The elites' run ids, by cell."""
        return [e.run_id for _, e in self.grid.by_cell()]

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
        job = job_of(self.spec, plain)
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
        cells, qd_score, best = self.grid.stats()
        return ArchiveStats(cells, qd_score, 0.0 if best is None else best)


def _family(operator: str) -> str:
    """The arm a way of making a run is drawn and recorded under: :data:`LOCAL` for a local
    operator, else the way itself (``fresh``, a targeted operator)."""
    return LOCAL if operator in SITUATION_OPERATORS and operator not in TARGETED else operator


def _like_coverage(like: Like) -> dict[str, Any]:
    """The part of the ``--like`` run's coverage record that places its failure."""
    return {"failure_at": like.failure_at, "failure_cell": like.failure_cell}


@functools.cache
def _aimable(key: str) -> frozenset[str]:
    """The variants the targeted operators can aim at from variant ``key`` (fixed per key, and
    asked for every elite at every draw of a parent)."""
    return frozenset(v for op in TARGETED for v in neighbours(key, op).values())


def job_of(spec: CampaignSpec, child: Child) -> Job:
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


def elite_grid(archive: Archive) -> list[list[dict[str, Any] | None]]:
    """The archive as rows (first measure) × columns (second measure, or one column): each
    cell its elite's run id and objective, or None."""
    labels = [m.labels for m in archive.measures]
    rows = len(labels[0])
    cols = len(labels[1]) if len(labels) > 1 else 1
    grid: list[list[dict[str, Any] | None]] = [[None] * cols for _ in range(rows)]
    for cell, elite in archive.grid.by_cell():
        row, col = cell[0], cell[1] if cols > 1 else 0
        grid[row][col] = {"run": elite.run_id, "objective": elite.objective}
    return grid


def falsification(robustness: float | None) -> float:
    """A requirement's robustness as a falsifying search's objective: larger the nearer a run
    came to violating it, and past 1 by how far it went (1 / (1 + ρ) for ρ ≥ 0, 1 − ρ below),
    never negative (the elites' QD score sums objectives from 0); a run without a verdict
    scores 0."""
    if robustness is None or math.isnan(robustness):
        return 0.0
    if robustness >= 0:
        return 1.0 / (1.0 + robustness)
    return 1.0 + min(-robustness, 1e6)
