"""Spec loading: a spec arrives as a file path, TOML text or a dict, and goes to the core.

The core parses, resolves presets and validates (the Rust types are the one source of truth);
this module only decides which of the three forms it was given.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sitgen import _core

SpecLike = str | Path | Mapping[str, Any]
"""A spec: a path to a TOML file, TOML text, or a dict of sections."""


def spec_source(spec: SpecLike) -> tuple[str, str]:
    """Return (kind, text) for the core: kind is "file", "toml" or "json".

    A string is a file path when it names an existing file, or when it is a single line
    ending in ``.toml`` (so that a mistyped path reports a missing file, not a TOML error);
    otherwise it is TOML text.
    """
    if isinstance(spec, Path):
        return "file", str(spec)
    if isinstance(spec, str):
        single_line = "\n" not in spec and "=" not in spec
        if single_line and (spec.endswith(".toml") or Path(spec).is_file()):
            return "file", spec
        return "toml", spec
    return "json", json.dumps(spec)


def load_spec(spec: SpecLike) -> dict[str, Any]:
    """The resolved spec (preset applied, defaults filled) as a dict; raises SpecError."""
    kind, text = spec_source(spec)
    resolved: dict[str, Any] = json.loads(_core.resolve_spec(kind, text))
    return resolved


def preset_names() -> list[str]:
    """Names of the built-in terrain presets."""
    return _core.preset_names()


def preset_spec(name: str) -> dict[str, Any]:
    """A spec that starts from preset ``name`` with nothing overridden."""
    return {"terrain": {"preset": name}}


def read_utf8(path: Path, what: str) -> str:
    """The text of the file ``what`` (a situation file, a run spec, …); SpecError naming the
    file and the first byte that is not UTF-8 (an unreadable file raises OSError)."""
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as e:
        raise _core.SpecError(f"{path}: not a {what}: byte {e.start} is not UTF-8 text") from None
