"""sitgen: procedurally generated situations for testing robot navigation software.

Public API (see ARCHITECTURE.md for the pipeline):

- :func:`generate_terrain` — a terrain map from a spec (path, TOML text or dict) and a seed;
- :func:`perlin` — Ken Perlin's improved noise, bit for bit the 2002 reference;
- :class:`Grid` — an occupancy map with its resolution, size and coverage;
- :exc:`SpecError`, :exc:`GenerationFailed` — what bad specs and failed generation raise.
"""

from sitgen._core import GenerationFailed, SpecError, __version__, perlin
from sitgen.config import load_spec, preset_names
from sitgen.terrain import Grid, Stage, generate_terrain

__all__ = [
    "GenerationFailed",
    "Grid",
    "SpecError",
    "Stage",
    "__version__",
    "generate_terrain",
    "load_spec",
    "perlin",
    "preset_names",
]
