"""Spec loading: a spec arrives as a file path, TOML text or a dict, and goes to the core.

The core parses, resolves presets and validates (the Rust types are the one source of truth);
this module only decides which of the three forms it was given.
"""

from __future__ import annotations

import json
import math
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
    return "json", spec_json(spec)


def spec_json(data: Mapping[str, Any], root: str = "") -> str:
    """``data`` (a spec, a run spec) as JSON for the core. JSON has no NaN or infinity, so a
    non-finite number anywhere in it is a SpecError naming its field (``run.time_limit_s: nan
    is not a finite number``) rather than a parse error somewhere in the text."""
    try:
        return json.dumps(data, allow_nan=False)
    except ValueError:
        path, value = _first_non_finite(data) or ("", math.nan)
        where = ".".join(p for p in (root, path) if p)
        raise _core.SpecError(f"{where}: {value!r} is not a finite number") from None


def _named(key: Any) -> str:
    """A key as a field path names it: as written, what is not printable escaped (``a\\nb``),
    as the core names it, so that the error stays one line."""
    text = str(key)
    return text if text.isprintable() else text.encode("unicode_escape").decode("ascii")


def _first_non_finite(data: Any, path: str = "") -> tuple[str, float] | None:
    """The dotted path and value of the first NaN or infinity in ``data``, or None."""
    if isinstance(data, float):
        return None if math.isfinite(data) else (path, data)
    if isinstance(data, Mapping):
        items = [(f"{path}.{_named(k)}" if path else _named(k), v) for k, v in data.items()]
    elif isinstance(data, list | tuple):
        items = [(f"{path}[{i}]", v) for i, v in enumerate(data)]
    else:
        return None
    for inner, value in items:
        if (found := _first_non_finite(value, inner)) is not None:
            return found
    return None


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
