"""A search's genomes and their variation: a situation as the genes of its campaign's
``[vary]`` entries and its seeds, and the operators that make a child of an elite (a new
mission on its map, tuned genes, a new map)."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sitgen.execution.jobs import (
    CampaignSpec,
    draw_genes,
    job_seed,
    vary_order,
)

if TYPE_CHECKING:
    pass


P_CHOICE = 0.2


"""Probability that a child draws a choice gene anew instead of taking its parent's."""


OPERATORS = {"new_mission": 0.5, "tune": 0.3, "new_map": 0.2}


"""How a child is varied from its elite, and how often: ``new_mission`` keeps the elite's map
(its terrain genes and terrain seed) and draws the robots anew on it (a new mission seed; the
other genes varied); ``tune`` varies every gene and keeps both seeds; ``new_map`` draws a new
map of varied terrain genes and keeps the mission's draws."""


SIGMA_ISO = 0.05


"""Iso+LineDD's isotropic noise, in each real gene's range scaled to [0, 1]."""


SIGMA_LINE = 0.2


"""Iso+LineDD's step along the line between the two parents."""


@dataclass(frozen=True)
class Genome:
    """A situation to run: one gene per ``[vary]`` entry (in :func:`vary_order`), the seed of
    its terrain's draws, the seed of its mission's draws (placement, routes, peers) and the
    run's own seed (sensor noise; the situation seed where a stage has no seed of its own)."""

    genes: tuple[int | float, ...]
    seed: int
    terrain_seed: int
    mission_seed: int

    def as_dict(self, spec: CampaignSpec) -> dict[str, Any]:
        paths = [path for path, _ in vary_order(spec)]
        return {
            "seed": self.seed,
            "terrain_seed": self.terrain_seed,
            "mission_seed": self.mission_seed,
            "draws": dict(zip(paths, self.genes, strict=True)),
        }

    @staticmethod
    def from_dict(spec: CampaignSpec, data: dict[str, Any]) -> Genome:
        draws = data["draws"]
        return Genome(
            tuple(draws[path] for path, _ in vary_order(spec)),
            int(data["seed"]),
            int(data["terrain_seed"]),
            int(data["mission_seed"]),
        )


def to_unit(kind: str, args: list[Any], gene: int | float) -> float:
    """A gene scaled to [0, 1] over its distribution's range (a choice: its index's middle)."""
    if kind == "choice":
        return (int(gene) + 0.5) / len(args)
    lo, hi = float(args[0]), float(args[1])
    if kind == "int":
        return (int(gene) - lo + 0.5) / (hi - lo + 1)
    return 0.5 if hi == lo else (float(gene) - lo) / (hi - lo)


def from_unit(kind: str, args: list[Any], u: float) -> int | float:
    lo, hi = args
    if kind == "int":
        return int(lo + min(hi - lo, math.floor(u * (hi - lo + 1))))
    return float(lo + u * (hi - lo))


def fresh(spec: CampaignSpec, seed: int, index: int) -> Genome:
    """Run ``index``'s fresh genome: exactly the campaign's job ``index``."""
    own = job_seed(seed, index)
    return Genome(tuple(draw_genes(spec, seed, index)), own, own, own)


def new_seed(seed: int, index: int, stage: str) -> int:
    """A new seed for ``stage`` of a varied child at run ``index`` (63 bits, apart from job
    seeds and from the other stages')."""
    digest = hashlib.sha256(f"{seed}:{index}:search:{stage}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def _is_terrain(path: str) -> bool:
    return path.startswith("situation.terrain.")


def vary(
    spec: CampaignSpec,
    seed: int,
    index: int,
    first: Genome,
    second: Genome,
    rng: np.random.Generator,
) -> tuple[str, Genome]:
    """A child of two elites by one of :data:`OPERATORS` (drawn by their weights), and the
    operator's name. Real genes vary by Iso+LineDD, a choice is drawn anew with probability
    :data:`P_CHOICE`; the child always has a run seed of its own, so no run repeats."""
    names = list(OPERATORS)
    weights = np.array(list(OPERATORS.values()))
    operator = names[int(rng.choice(len(names), p=weights / weights.sum()))]
    line = rng.normal()
    genes: list[int | float] = []
    for (path, dist), a, b in zip(vary_order(spec), first.genes, second.genes, strict=True):
        kind, args = next(iter(dist.items()))
        if operator == "new_mission" and _is_terrain(path):
            genes.append(a)  # the same map
        elif kind == "choice":
            genes.append(int(rng.integers(len(args))) if rng.random() < P_CHOICE else a)
        else:
            ua, ub = to_unit(kind, args, a), to_unit(kind, args, b)
            u = ua + SIGMA_ISO * rng.normal() + SIGMA_LINE * line * (ub - ua)
            genes.append(from_unit(kind, args, float(np.clip(u, 0.0, 1.0))))
    terrain_seed = new_seed(seed, index, "terrain") if operator == "new_map" else first.terrain_seed
    mission_seed = (
        new_seed(seed, index, "mission") if operator == "new_mission" else first.mission_seed
    )
    return operator, Genome(tuple(genes), new_seed(seed, index, "run"), terrain_seed, mission_seed)
