"""MAP-Elites' archive of elites: a grid of cells over the behaviour measures, each holding the
run of the highest objective seen there.

What it does: :meth:`Elites.add` takes a generation's runs as one batch and puts into each
cell the batch's best run (the first of equal ones) where it beats the cell's elite strictly;
:meth:`Elites.by_cell` gives the elites in cell order (row-major over the measures), and
:meth:`Elites.stats` the filled cells, the QD score (the sum of the elites' objectives) and the
best objective.

Why here: the grid is all a search needs of a MAP-Elites archive (its variation is sitgen's own,
:mod:`sitgen.generation.mutation` and :mod:`sitgen.generation.genome`, since a situation's
genome is not a real vector for an emitter to vary). pyribs' ``GridArchive``, which did this
before, brought scikit-learn, numba and pandas with it: 4 s to import at every search's start
and about 150 MB to install. Its batch rule is kept exactly (a search stores the same runs:
``tests/test_search_unchanged.py``).

Parameters: ``dims``, the number of cells along each measure.

Source: Mouret & Clune, "Illuminating search spaces by mapping elites" (2015), the archive of
Algorithm 1; pyribs 0.12 ``GridArchive.add`` (the batch rule, with its default learning rate 1
and no threshold).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Elite:
    """A cell's elite."""

    objective: float
    run_id: int


class Elites:
    """A grid of ``dims`` cells, each with at most one elite."""

    def __init__(self, dims: Sequence[int]) -> None:
        self.dims = tuple(int(d) for d in dims)
        self._cells: dict[tuple[int, ...], Elite] = {}

    @property
    def empty(self) -> bool:
        return not self._cells

    def add(self, cells: Sequence[tuple[int, ...]], elites: Sequence[Elite]) -> None:
        """A batch: ``elites[i]`` in cell ``cells[i]`` (a cell index on each measure, clipped
        into the grid)."""
        best: dict[tuple[int, ...], Elite] = {}
        for cell, elite in zip(cells, elites, strict=True):
            at = tuple(min(max(int(c), 0), d - 1) for c, d in zip(cell, self.dims, strict=True))
            if at not in best or elite.objective > best[at].objective:
                best[at] = elite
        for at, elite in best.items():
            held = self._cells.get(at)
            if held is None or elite.objective > held.objective:
                self._cells[at] = elite

    def by_cell(self) -> list[tuple[tuple[int, ...], Elite]]:
        """Every filled cell and its elite, in cell order."""
        return sorted(self._cells.items())

    def stats(self) -> tuple[int, float, float | None]:
        """Filled cells, QD score (the sum of the elites' objectives, in cell order) and the
        best objective (None while empty)."""
        objectives = [e.objective for _, e in self.by_cell()]
        return len(objectives), float(sum(objectives)), max(objectives, default=None)
