"""Requirements as a user writes them: ``--require 'NAME: FORMULA'`` on the command line,
``[[requirement]]`` tables in a file (``--requirements FILE.toml``) or in a campaign or run
spec, gathered into a run spec's ``requirement`` list for the core to compile and judge
(docs/requirements.md). Nothing here evaluates a formula: the core does."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sitgen import _core

FIELDS = ("name", "formula", "weight")


def parse_require(item: str) -> dict[str, Any]:
    """One ``--require`` item, ``NAME: FORMULA``, as a requirement table. A name holds no
    ``:``, so the first one ends it (an interval's ``[0:5]`` stays in the formula)."""
    name, sep, formula = item.partition(":")
    if not sep or not name.strip() or not formula.strip():
        raise _core.SpecError(f"--require: `{item}` is not NAME: FORMULA")
    return {"name": name.strip(), "formula": formula.strip()}


def read_requirements(path: Path) -> list[dict[str, Any]]:
    """The ``[[requirement]]`` tables of TOML file ``path``; SpecError naming the file and the
    table for anything else."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise _core.SpecError(f"--requirements: {path}: {e.strerror or e}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise _core.SpecError(f"--requirements: {path}: not TOML: {e}") from None
    extra = [k for k in data if k != "requirement"]
    if extra:
        raise _core.SpecError(
            f"{path}: {extra[0]}: unknown field; a requirements file holds [[requirement]] tables"
        )
    return checked_tables(data.get("requirement", []), str(path))


def checked_tables(tables: Any, where: str) -> list[dict[str, Any]]:
    """``tables`` if it is a list of requirement tables with only their fields; SpecError
    naming ``where`` and the table otherwise (the core checks each field's value)."""
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise _core.SpecError(f"{where}: requirement: expected [[requirement]] tables")
    for i, t in enumerate(tables):
        unknown = [k for k in t if k not in FIELDS]
        if unknown:
            raise _core.SpecError(
                f"{where}: requirement[{i}].{unknown[0]}: unknown field; expected {FIELDS}"
            )
    return [dict(t) for t in tables]


def gathered(require: list[str] | None, files: list[Path] | None) -> list[dict[str, Any]]:
    """The requirements of each ``--requirements FILE`` then of each ``--require``."""
    tables = [t for f in files or [] for t in read_requirements(f)]
    return tables + [parse_require(item) for item in require or []]


def with_requirements(
    run_spec: Mapping[str, Any] | None, tables: list[dict[str, Any]]
) -> dict[str, Any]:
    """``run_spec`` with ``tables`` after its own requirements; one of the same name as one of
    its own replaces it (the command line speaks last)."""
    spec = dict(run_spec or {})
    if not tables:
        return spec
    given = {t["name"] for t in tables}
    own = [r for r in spec.get("requirement", []) if r.get("name") not in given]
    spec["requirement"] = own + tables
    return spec


def verdicts(raw: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A record's requirement verdicts with their robustness as a float (the core writes ±∞
    as ``"inf"``/``"-inf"``; None stays None where ``error`` says why)."""
    return [
        {**v, "robustness": None if v["robustness"] is None else float(v["robustness"])}
        for v in raw
    ]


def verdicts_text(given: list[dict[str, Any]]) -> str:
    """One line a requirement: its verdict, robustness, and when a violation began and what
    decided it, e.g. ``requirement slow_near_peer: VIOLATED, robustness -0.213 (from 12.3 s;
    decided over 12.3-13.1 s)``."""
    lines = []
    for v in given:
        rho = v["robustness"]
        if rho is None:
            lines.append(f"requirement {v['name']}: no verdict: {v.get('error')}\n")
            continue
        verdict = "VIOLATED" if v["violated"] else "satisfied"
        where = ""
        if v["violated"]:
            a, b = v.get("interval_s") or (0.0, 0.0)
            where = f" (from {v['first_violation_s']:.1f} s; decided over {a:.1f}-{b:.1f} s)"
        lines.append(f"requirement {v['name']}: {verdict}, robustness {rho:.4g}{where}\n")
    return "".join(lines)


def verdicts_json(given: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Verdicts as JSON carries them: ±∞ robustness as ``"inf"``/``"-inf"``, as the core
    writes it (JSON has no infinity)."""

    def number(x: float | None) -> float | str | None:
        return x if x is None or abs(x) != float("inf") else ("inf" if x > 0 else "-inf")

    return [{**v, "robustness": number(v["robustness"])} for v in given]
