"""The store's SQLite connection: errors that name the store's file, and the test for a
store a process may not write to."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path
from typing import Any


class Connection(sqlite3.Connection):
    """A store's connection: an error from SQLite (a full disk, a damaged page) names the
    store's file, whichever command met it. It stays an ``sqlite3.Error`` of the same kind, so
    whatever catches one still does."""

    path = ""

    def _named(self, e: sqlite3.Error) -> sqlite3.Error:
        return type(e)(f"{self.path}: {e}")

    def execute(self, *args: Any, **kwargs: Any) -> sqlite3.Cursor:
        try:
            return super().execute(*args, **kwargs)
        except sqlite3.Error as e:
            raise self._named(e) from None

    def executemany(self, *args: Any, **kwargs: Any) -> sqlite3.Cursor:
        try:
            return super().executemany(*args, **kwargs)
        except sqlite3.Error as e:
            raise self._named(e) from None

    def executescript(self, *args: Any, **kwargs: Any) -> sqlite3.Cursor:
        try:
            return super().executescript(*args, **kwargs)
        except sqlite3.Error as e:
            raise self._named(e) from None

    def commit(self) -> None:
        try:
            super().commit()
        except sqlite3.Error as e:
            raise self._named(e) from None

    def __exit__(self, *args: Any) -> Any:
        try:
            return super().__exit__(*args)
        except sqlite3.Error as e:
            raise self._named(e) from None


def read_only_part(path: Path) -> Path | None:
    """The store's file or its folder where this process may not write to it, else None."""
    for part in (path, path.parent):
        if part.exists() and not os.access(part, os.W_OK):
            return part
    return None
