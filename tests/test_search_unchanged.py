"""Reorganising the search leaves it the same search: a mutation search and a MAP-Elites
search store the same runs as the digests checked in before the work
(``tests/data/reference_searches.json``).

Each stored run is digested with what makes it that run: its number, generation, parents and
genes (the way it was made: operator, aim, genome), its situation's content hash, its event log
and its score. A mismatch names the first run that differs. The digests are rewritten by
``python -m tests.test_search_unchanged`` — only for a change meant to change what a search
does, said in its commit."""

from __future__ import annotations

import hashlib
import json
import sqlite3
import tempfile
from pathlib import Path
from typing import Any

from sitgen.generation.search import run_search
from sitgen.generation.search.plan import BATCH, INITIAL, SearchPlan
from tests.conftest import ROOT
from tests.test_search import spec_of

DIGESTS = ROOT / "tests" / "data" / "reference_searches.json"

SEARCHES = {
    "mutation": (SearchPlan("mutation"), 2, INITIAL + 3 * BATCH),
    "map-elites": (SearchPlan("map-elites"), 4, INITIAL + 2 * BATCH),
}
"""Name -> plan, seed and budget of each reference search, on test_search's small spec."""


def digests() -> dict[str, list[str]]:
    """Each reference search's stored runs, one digest each, in run order."""
    out: dict[str, list[str]] = {}
    for name, (plan, seed, budget) in SEARCHES.items():
        with tempfile.TemporaryDirectory() as tmp:
            db = Path(tmp) / "search.db"
            run_search(spec_of(), db, seed=seed, budget=budget, plan=plan, workers=2)
            with sqlite3.connect(db) as c:
                rows = c.execute(
                    "SELECT r.id, r.generation, r.parents, r.genes, s.content_hash, "
                    "r.events_jsonl, r.score FROM runs r "
                    "JOIN situations s ON s.id = r.situation_id ORDER BY r.id"
                ).fetchall()
        out[name] = [hashlib.sha256(json.dumps(list(r)).encode()).hexdigest() for r in rows]
    return out


def test_searches_store_the_runs_of_the_checked_in_digests() -> None:
    expected: dict[str, list[str]] = json.loads(DIGESTS.read_text())
    got = digests()
    for name, runs in expected.items():
        assert len(got[name]) == len(runs), name
        first = next(
            (i for i, (a, b) in enumerate(zip(got[name], runs, strict=True)) if a != b), None
        )
        assert first is None, f"{name}: run {first} and on differ from the reference search"


def main() -> None:
    written: dict[str, Any] = digests()
    DIGESTS.write_text(json.dumps(written, indent=1) + "\n")
    print(f"wrote {DIGESTS}: " + ", ".join(f"{k} {len(v)} runs" for k, v in written.items()))


if __name__ == "__main__":
    main()
