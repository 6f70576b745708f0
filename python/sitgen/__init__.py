"""sitgen: procedurally generated situations for testing robot navigation software.

Public API (see ARCHITECTURE.md for the pipeline):

- :func:`generate_terrain` — a terrain map from a spec (path, TOML text or dict) and a seed;
- :func:`generate_situation` — a complete :class:`Situation` (map, robots, routes);
- :func:`load_map` — a :class:`Grid` from ROS YAML, PNG/PGM, MovingAI ``.map`` or BARN ``.npy``;
- :func:`shortest_path` — A* with the MovingAI movement rules;
- :class:`World` — the simulator: ``observe``, ``step``, ``state``;
- :class:`RouteFollower` — a route followed as sitgen's peers follow one (start, waypoints,
  then ``at_end``), for a controller of one's own;
- :func:`run` — one situation driven to its end, watched and scored: a :class:`RunRecord`;
- :func:`perlin` — Ken Perlin's improved noise, bit for bit the 2002 reference;
- :class:`Grid` — an occupancy map with its resolution, size and coverage;
- :exc:`SpecError`, :exc:`GenerationFailed` — what bad specs and failed generation raise.
"""

from sitgen._core import GenerationFailed, RouteFollower, SpecError, __version__, perlin
from sitgen.run import RunRecord, run
from sitgen.world.config import load_spec, preset_names
from sitgen.world.maps import load_map, shortest_path
from sitgen.world.sim import Observation, World
from sitgen.world.situation import Pose, Robot, Situation, generate_situation
from sitgen.world.terrain import Grid, Stage, generate_terrain

__all__ = [
    "GenerationFailed",
    "Grid",
    "Observation",
    "Pose",
    "Robot",
    "RouteFollower",
    "RunRecord",
    "Situation",
    "SpecError",
    "Stage",
    "World",
    "__version__",
    "generate_situation",
    "generate_terrain",
    "load_map",
    "load_spec",
    "perlin",
    "preset_names",
    "run",
    "shortest_path",
]
