"""Rows of a table as a command prints them for a machine: JSON (every field) or CSV (chosen
columns). ``rank``, ``failures`` and ``coverage`` share it."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from typing import Any, TextIO


def write_rows(
    rows: list[dict[str, Any]], columns: Sequence[str], format: str, out: TextIO
) -> None:
    """Write rows as ``json`` (a list of objects, every field) or ``csv`` (``columns``)."""
    if format == "json":
        json.dump(rows, out, indent=2)
        out.write("\n")
        return
    writer = csv.DictWriter(out, fieldnames=list(columns), extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
