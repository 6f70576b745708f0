"""What the store hands out and takes in, and its errors: a run's row, a judgement, run ids,
JSON packing, the scoring a rescored store reads through."""

from __future__ import annotations

import hashlib
import json
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

MAX_RUN_ID = 2**63 - 1


"""The largest run id (SQLite's INTEGER is a signed 64-bit number)."""


def is_run_id(value: object) -> bool:
    """Whether ``value`` can be a run id: an integer (not a bool) in [0, 2^63 - 1]. Every place
    a run id enters (the command line, the judging page, a judgements file) goes through the
    store's readers, which treat anything else as a run the store does not hold."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_RUN_ID


WORSE = ("a", "b", "equal")


"""What a judgement says: run ``a`` is more dangerous, run ``b`` is, or neither."""


@dataclass(frozen=True)
class Judgement:
    """One pairwise judgement: which of runs ``a`` and ``b`` is more dangerous (the store's
    ``judgements`` rows; :mod:`sitgen.triage.weights` fits penalties to them)."""

    a: int
    b: int
    worse: str
    who: str = ""
    at: str = ""
    """When, ISO 8601 UTC."""

    def as_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "worse": self.worse, "who": self.who, "at": self.at}


class Scoring(Protocol):
    """What rescoring a store needs of a scoring table (:class:`sitgen.triage.weights.Weights`)."""

    def score(self, stored: Mapping[str, Any], failure_class: str | None) -> float: ...

    def breakdown(self, stored: Mapping[str, Any]) -> dict[str, dict[str, float]]: ...


class StoreError(Exception):
    """A store that cannot be used (wrong file, other campaign, newer schema)."""


class StoreMissing(StoreError):
    """No store where one was named: a mistyped path or a folder (bad input, not damage)."""


def require_store(path: Path) -> None:
    """Raise StoreMissing unless ``path`` is a file: reading a mistyped path must not create
    an empty store."""
    if path.is_dir():
        raise StoreMissing(f"{path}: is a folder, not a campaign store")
    if not path.is_file():
        raise StoreMissing(f"{path}: no such campaign store")


@dataclass(frozen=True)
class RunRow:
    """One stored run, as produced by a campaign."""

    id: int
    situation_seed: int
    situation_spec: dict[str, Any]
    situation_json: str | None
    run_spec: dict[str, Any]
    run_seed: int
    controller: str
    record: dict[str, Any] | None
    """The run record (outcome, reason, score, events, …); None if generation failed."""
    error: str | None
    events_jsonl: str
    trajectory: bytes | None
    robots: int
    generation: int | None = None
    """The search generation that made it (None for a campaign's run)."""
    parents: tuple[int, ...] | None = None
    """The runs a search mutated to make it (empty for a fresh draw; None in a campaign)."""
    genes: dict[str, Any] | None = None
    """A search's genome for it: each varied field's draw and the situation seed."""
    keep: bool = True
    """Store the run whole (its situation, specs, event log and trajectory), or only its
    summary (a campaign's run: its specs follow from the campaign, and the rest comes back by
    re-simulation, :mod:`sitgen.triage.recall`)."""


def pack_json(value: Any) -> bytes:
    """A JSON value as a stored column holds a long one: sorted-key JSON, zlib'd (a run's
    coverage: its cell names repeat, and shrink to about two fifths)."""
    return zlib.compress(json.dumps(value, sort_keys=True).encode(), 9)


def unpack_json(stored: str | bytes) -> Any:
    """A JSON column's value: zlib'd (:func:`pack_json`) or, as stores before version 7 hold
    it, text."""
    return json.loads(zlib.decompress(stored) if isinstance(stored, bytes) else stored)


def events_digest(events_jsonl: str) -> str:
    """The digest a stored run keeps of its event log: what re-simulation must reproduce."""
    return hashlib.sha256(events_jsonl.encode()).hexdigest()


def main_events(breakdown: dict[str, Any]) -> str:
    """The kinds that earned points, most points first: ``collision×2, unsafe_proximity×1``."""
    ordered = sorted(breakdown.items(), key=lambda kv: (-kv[1]["points"], kv[0]))
    return ", ".join(f"{kind}×{line['count']}" for kind, line in ordered)
