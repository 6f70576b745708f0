"""Campaign specs and their jobs: what a campaign runs, as pure functions of (spec, seed, i).

A campaign spec (TOML) has a base situation spec (``[situation]``), a base run spec
(``[run]``) and distributions (``[vary]``) keyed by dotted paths into either:

- ``{ choice = [a, b, …] }`` one of the values; ``{ uniform = [lo, hi] }`` a real number;
  ``{ int = [lo, hi] }`` an integer, both ends included; ``{ scale = [lo, hi] }`` the value the
  spec already has (after its preset is applied) times a uniform factor;
- a path step that names a list of tables selects the table of that ``kind``:
  ``situation.terrain.filters.coverage.target`` is the coverage filter's target.

Job ``i`` of a campaign with seed ``S`` draws its values from its own stream (numpy's PCG64
seeded with (S, i)) and uses situation seed = run seed = 63 bits of sha256("S:i"): every job
is a pure function of (spec, S, i), so the results do not depend on the worker count, the
backend, the order of completion or on interruptions; a run kept as a summary is made whole
again from its job (:mod:`sitgen.triage.recall`).

Before any run, the first :data:`CHECKED_JOBS` jobs are built and checked and every controller
the spec can name is checked (a built-in name, a ``cmd:`` program that exists, a ``python:``
class that loads): a bad spec stops the campaign with the field named.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import tomllib
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.conformance import resets
from sitgen.controllers.deadlines import ControllerError
from sitgen.controllers.user import check_controller_name, is_user_controller
from sitgen.world.config import load_spec, spec_json
from sitgen.world.requirements import checked_tables, with_requirements
from sitgen.world.situation import Situation, situation_of

DISTRIBUTIONS = ("choice", "uniform", "int", "scale")
SECTIONS = ("n", "situation", "run", "vary", "requirement")
MAX_RUNS = 1_000_000_000
"""Most runs a campaign may ask for (jobs are streamed, so memory does not grow with it)."""
CHECKED_JOBS = 10_000
"""Jobs built and checked before any run (about a second's work)."""
MAX_WORKERS_PER_CORE = 4
"""Local workers allowed per core: more only adds memory and contention."""
MAX_RAY_WORKERS = 4096
"""Batches a Ray campaign may keep in flight (twice this many, as ``workers`` says)."""


def paper_campaign_text() -> str:
    """The default campaign: the paper's experiment."""
    return resources.files("sitgen").joinpath("paper_campaign.toml").read_text()


@dataclass(frozen=True)
class CampaignSpec:
    """A parsed campaign spec."""

    situation: dict[str, Any]
    run: dict[str, Any]
    vary: dict[str, dict[str, Any]]
    n: int = 500
    source: dict[str, Any] = field(default_factory=dict)
    """The spec as written (stored with the campaign)."""


def parse_campaign(text: str | None, origin: str = "campaign spec") -> CampaignSpec:
    """Parse and check a campaign spec (TOML; None for the paper's). Raises SpecError naming the
    field."""
    if text is None:
        text, origin = paper_campaign_text(), "paper campaign"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise _core.SpecError(f"{origin}: TOML syntax error: {e}") from None
    return campaign_from_data(data)


def campaign_from_data(data: dict[str, Any]) -> CampaignSpec:
    """Check a campaign spec given as a dict of sections. Raises SpecError naming the field."""
    for key in data:
        if key not in SECTIONS:
            raise _core.SpecError(f"{key}: unknown campaign field; expected one of {SECTIONS}")
    n = data.get("n", 500)
    if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= MAX_RUNS:
        raise _core.SpecError(f"n: {n!r} is not a whole number of runs in [0, {MAX_RUNS}]")
    for section in ("situation", "run", "vary"):
        if not isinstance(data.get(section, {}), dict):
            raise _core.SpecError(f"{section}: expected a table")
    if "requirement" in data:
        # A campaign's [[requirement]] tables are its runs': they travel in the run spec.
        data = dict(data)
        tables = checked_tables(data.pop("requirement"), "campaign")
        data["run"] = with_requirements(data.get("run"), tables)
    vary: dict[str, dict[str, Any]] = data.get("vary", {})
    for path, dist in vary.items():
        where = f"vary.{path!r}"
        if not path.startswith(("situation.", "run.")):
            raise _core.SpecError(f"{where}: a path starts with situation. or run.")
        if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
            raise _core.SpecError(
                f"{where}: expected one of {{ choice = [...] }}, {{ uniform = [lo, hi] }}, "
                "{ int = [lo, hi] }, { scale = [lo, hi] }"
            )
        kind, args = next(iter(dist.items()))
        if not isinstance(args, list) or not args:
            raise _core.SpecError(f"{where}.{kind}: expected a non-empty list")
        if kind != "choice":
            numeric = all(
                isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a)
                for a in args
            )
            if len(args) != 2 or not numeric or args[0] > args[1]:
                raise _core.SpecError(
                    f"{where}.{kind}: expected [lo, hi] finite numbers with lo <= hi"
                )
        if kind == "int" and not all(isinstance(a, int) for a in args):
            raise _core.SpecError(f"{where}.int: expected [lo, hi] whole numbers")
    return CampaignSpec(
        situation=data.get("situation", {}),
        run=data.get("run", {}),
        vary=vary,
        n=n,
        source=data,
    )


def job_seed(seed: int, index: int) -> int:
    """The situation and run seed of job ``index`` (63 bits, so SQLite stores it as is)."""
    digest = hashlib.sha256(f"{seed}:{index}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def draw_gene(rng: np.random.Generator, kind: str, args: list[Any]) -> int | float:
    """One draw of a ``[vary]`` distribution, as a gene: ``choice`` the index of the value,
    ``uniform`` and ``int`` the value, ``scale`` the factor."""
    if kind == "choice":
        return int(rng.integers(len(args)))
    if kind == "int":
        return int(rng.integers(args[0], args[1] + 1))
    return float(rng.uniform(args[0], args[1]))


def express_gene(kind: str, args: list[Any], gene: int | float, current: Any) -> Any:
    """The value a gene gives the field whose value is ``current``."""
    if kind == "choice":
        return args[int(gene)]
    if kind != "scale":
        return gene
    if not isinstance(current, int | float):
        raise ValueError(f"scale needs a number there, found {current!r}")
    return float(current * gene)


def _set(tree: dict[str, Any], path: str, value: Callable[[Any], Any]) -> None:
    """Replace the value at dotted ``path`` by ``value(old)``; a step naming a list of tables
    selects the table of that ``kind``; missing tables are created."""
    steps = path.split(".")
    node: Any = tree
    for i, step in enumerate(steps):
        last = i == len(steps) - 1
        if isinstance(node, list):
            matches = [t for t in node if isinstance(t, dict) and t.get("kind") == step]
            if not matches:
                raise ValueError(f"no `{step}` in the list at {'.'.join(steps[:i])}")
            if last:
                raise ValueError("a list item cannot be replaced whole")
            node = matches[0]
            continue
        if not isinstance(node, dict):
            raise ValueError(f"{'.'.join(steps[:i])} is not a table")
        if last:
            node[step] = value(node.get(step))
        else:
            node = node.setdefault(step, {})


@dataclass(frozen=True)
class Job:
    """One run of a campaign."""

    index: int
    seed: int
    situation: dict[str, Any]
    """The resolved situation spec (as written, if it could not be built)."""
    run: dict[str, Any]
    """The run spec."""
    error: str | None = None
    """Why the job could not be built (its draws made a bad spec); it is stored, not run."""
    run_seed: int | None = None
    """The run's sensor-noise seed, where it is not the situation's seed (a stored run's
    perturbed copies, :mod:`sitgen.triage.robustness`)."""

    @property
    def noise_seed(self) -> int:
        """The seed the run draws its sensor noise from."""
        return self.seed if self.run_seed is None else self.run_seed

    @property
    def in_python(self) -> bool:
        """Whether the Python layer drives some robot of this job's run: a user controller
        for its agent or a peer (so the job runs in a process pool, not the core's threads)."""
        robots = self.situation.get("robots")
        if isinstance(robots, list):
            peers = [r.get("controller", {}).get("name") for r in robots if r.get("role") == "peer"]
        else:
            peers = [name for _, name in _mission_peer_names(self.situation.get("mission", {}))]
        return any(isinstance(n, str) and is_user_controller(n) for n in [self.controller, *peers])

    def built(self) -> Situation:
        """The job's situation: given whole, or generated from its spec and seed. Raises the
        core's GenerationFailed or SpecError where it cannot be made."""
        return situation_of(self.situation, self.seed)

    @property
    def controller(self) -> str:
        """The agent's controller: the run spec's, else the situation's mission's; a seeded
        fault follows its name after a ``+``."""
        mission = self.situation.get("mission", {}).get("agent_controller", {})
        controller = self.run.get("controller", mission)
        name: str = controller.get("name", "snd_follow")
        fault = controller.get("fault")
        return f"{name}+{fault}" if fault else name


def vary_order(spec: CampaignSpec) -> list[tuple[str, dict[str, Any]]]:
    """The ``[vary]`` entries in the order they are drawn and applied: presets first, so that
    later paths (and ``scale``) see the preset's values."""
    return sorted(spec.vary.items(), key=lambda kv: not kv[0].endswith(".preset"))


def draw_genes(spec: CampaignSpec, seed: int, index: int) -> list[int | float]:
    """Job ``index``'s draws, one gene per :func:`vary_order` entry."""
    rng = np.random.Generator(np.random.PCG64([seed, index]))
    return [draw_gene(rng, *next(iter(dist.items()))) for _, dist in vary_order(spec)]


def build_job(spec: CampaignSpec, seed: int, index: int) -> Job:
    """Job ``index``: its draws applied to the base specs, the situation spec resolved and
    checked. Raises SpecError naming the field."""
    return express_job(spec, index, job_seed(seed, index), draw_genes(spec, seed, index))


def express_job(spec: CampaignSpec, index: int, seed: int, genes: Sequence[int | float]) -> Job:
    """The job whose situation and run seed is ``seed`` and whose ``[vary]`` fields take
    ``genes`` (one per :func:`vary_order` entry). Raises SpecError naming the field."""
    situation = copy.deepcopy(spec.situation)
    run = copy.deepcopy(spec.run)
    resolved = False
    for (path, dist), gene in zip(vary_order(spec), genes, strict=True):
        if not resolved and not path.endswith(".preset"):
            situation = _resolve(situation, index)
            resolved = True
        section, _, rest = path.partition(".")
        kind, args = next(iter(dist.items()))

        def value(old: Any, kind: str = kind, args: list[Any] = args, gene: Any = gene) -> Any:
            return express_gene(kind, args, gene, old)

        try:
            _set(situation if section == "situation" else run, rest, value)
        except ValueError as e:
            raise _core.SpecError(f"vary.{path!r}: {e}") from None
    situation = _resolve(situation, index)
    # Stored as the core resolves it, its profile's fields written out: the store says what ran.
    run = json.loads(_core.check_run_spec(spec_json(run, "run")))
    return Job(index=index, seed=seed, situation=situation, run=run)


def _resolve(situation: dict[str, Any], index: int) -> dict[str, Any]:
    try:
        return load_spec(situation)
    except _core.SpecError as e:
        raise _core.SpecError(f"situation.{e} (job {index})") from None


def build_jobs(spec: CampaignSpec, seed: int, n: int) -> list[Job]:
    """Jobs 0 … n − 1, built and checked (for small campaigns and tests; campaigns stream)."""
    return [build_job(spec, seed, i) for i in range(n)]


def stream_jobs(spec: CampaignSpec, seed: int, indices: Iterable[int]) -> Iterator[Job]:
    """The jobs of ``indices``, built one at a time as they are asked for; a job whose draws
    make a bad spec comes with its ``error`` set instead of stopping the campaign."""
    for i in indices:
        try:
            yield build_job(spec, seed, i)
        except _core.SpecError as e:
            situation = copy.deepcopy(spec.situation)
            yield Job(i, job_seed(seed, i), situation, copy.deepcopy(spec.run), f"spec: {e}")


def controller_names(spec: CampaignSpec) -> list[tuple[str, str]]:
    """Every (field, controller name) the campaign can give its agent."""
    found: list[tuple[str, str]] = []
    mission = spec.situation.get("mission", {})
    bases = {
        "run.controller.name": spec.run.get("controller", {}).get("name"),
        "situation.mission.agent_controller.name": mission.get("agent_controller", {}).get("name"),
    }
    for path, base in bases.items():
        if isinstance(base, str):
            found.append((path, base))
        dist = spec.vary.get(path, {})
        choices = dist.get("choice", [])
        found += [(f"vary.{path!r}.choice", c) for c in choices if isinstance(c, str)]
    return found


def peer_controller_names(spec: CampaignSpec) -> list[tuple[str, str]]:
    """Every (field, controller name) the campaign can give its peers."""
    path = "situation.mission.peer_controller.name"
    found = _mission_peer_names(spec.situation.get("mission", {}))
    choices = spec.vary.get(path, {}).get("choice", [])
    found += [(f"vary.{path!r}.choice", c) for c in choices if isinstance(c, str)]
    return found


def _mission_peer_names(mission: dict[str, Any]) -> list[tuple[str, str]]:
    """The (field, controller name) a mission spec gives its peers: ``peer_controller`` and
    each of ``peer_controllers``."""
    found: list[tuple[str, str]] = []
    base = mission.get("peer_controller", {}).get("name")
    if isinstance(base, str):
        found.append(("situation.mission.peer_controller.name", base))
    for i, c in enumerate(mission.get("peer_controllers", [])):
        if isinstance(c, dict) and isinstance(c.get("name"), str):
            found.append((f"situation.mission.peer_controllers[{i}].name", c["name"]))
    return found


def runs_in_python(spec: CampaignSpec) -> bool:
    """Whether some run of the campaign has a controller the Python layer drives (its agent's
    or a peer's): its runs then go to a process pool, not the core's threads."""
    names = [*controller_names(spec), *peer_controller_names(spec)]
    return any(is_user_controller(name) for _, name in names)


def check_campaign(
    spec: CampaignSpec, seed: int, n: int, stop: Callable[[], bool] | None = None
) -> None:
    """Everything that can be checked before any run: the first :data:`CHECKED_JOBS` jobs
    build, and every controller the spec names can be used. Raises SpecError naming the
    field."""
    for i in range(min(n, CHECKED_JOBS)):
        if stop is not None and i % 256 == 0 and stop():
            return
        build_job(spec, seed, i)
    checked: set[tuple[str, str]] = set()
    mission = spec.situation.get("mission", {})
    for path, name in [*controller_names(spec), *peer_controller_names(spec)]:
        params = _params_at(spec, mission, path)
        if (name, json.dumps(params, sort_keys=True)) in checked:
            continue
        checked.add((name, json.dumps(params, sort_keys=True)))
        _core.check_controller(name, path)
        try:
            check_controller_name(name, params)
        except ControllerError as e:
            raise _core.SpecError(f"{path}: {e}") from None
    mission = spec.situation.get("mission", {})
    path = "run.controller" if "controller" in spec.run else "situation.mission.agent_controller"
    table = spec.run.get("controller") or mission.get("agent_controller") or {}
    check_kept_alive(spec, seed, table, path)


KEEP_ALIVE_CHECK_STEPS = 30
"""Control periods of each run that checks a node kept alive across runs resets."""


def check_kept_alive(spec: CampaignSpec, seed: int, table: dict[str, Any], path: str) -> None:
    """Where the agent's controller table ``table`` (the field ``path``) keeps its ``ros2:``
    node alive across runs (``keep_alive``), check that the node runs the campaign's first
    situation after its second as a fresh node runs it (:func:`sitgen.conformance.resets`:
    three short runs, two node starts); else every run after a worker's first would be another
    than the run it stands for. Raises SpecError naming the field."""
    if not table.get("keep_alive"):
        return
    try:
        first, second = build_job(spec, seed, 0), build_job(spec, seed, 1)
        situation, before = first.built(), second.built()
    except (_core.GenerationFailed, _core.SpecError):
        return  # stored as its job's error, like any job that cannot be built
    check = resets(table, situation, before, KEEP_ALIVE_CHECK_STEPS, first.run)
    if not check.ok:
        raise _core.SpecError(f"{path}.keep_alive: controller `{table['name']}`: {check.detail}")


def _params_at(spec: CampaignSpec, mission: dict[str, Any], path: str) -> Any:
    """The params of the controller table the field ``path`` names a controller in (those a
    ``vary`` choice of the agent's controller gets are the run spec's)."""
    if path.startswith(("run.", "vary.'run.")):
        return spec.run.get("controller", {}).get("params")
    if path.startswith(("situation.mission.peer_controller.", "vary.'situation.mission.peer_c")):
        return mission.get("peer_controller", {}).get("params")
    if path.startswith("situation.mission.peer_controllers["):
        index = int(path.split("[", 1)[1].split("]", 1)[0])
        return mission["peer_controllers"][index].get("params")
    return None


def check_workers(workers: int | None, backend: str) -> int:
    """The worker count to use: the cores by default, else ``workers`` if within the cap
    (:data:`MAX_WORKERS_PER_CORE` per core locally, :data:`MAX_RAY_WORKERS` on Ray)."""
    cores = os.cpu_count() or 1
    if workers is None:
        return cores
    most = MAX_RAY_WORKERS if backend == "ray" else MAX_WORKERS_PER_CORE * cores
    if not 1 <= workers <= most:
        where = "on Ray" if backend == "ray" else f"here ({MAX_WORKERS_PER_CORE} per core)"
        raise _core.SpecError(f"--workers: {workers} is not in [1, {most}], the most {where}")
    return workers
