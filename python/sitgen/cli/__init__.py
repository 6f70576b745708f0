"""The ``sitgen`` command: one module per command group, registered on the app in
:mod:`sitgen.cli.app` when imported here; ``sitgen`` runs :func:`main`."""

from sitgen.cli import campaigns, judging, runs, searching, triage, verdicts, world
from sitgen.cli.app import app, main

__all__ = [
    "app",
    "campaigns",
    "judging",
    "main",
    "runs",
    "searching",
    "triage",
    "verdicts",
    "world",
]
