"""The cross-check: a situation run by sitgen and by the real Stage 4.3, compared.

The situation is exported for Stage with how it is run (``Situation.export(..., run=...)``),
Stage runs it headless with sitgen's controller plugin (``integrations/stage/``), which drives
every robot with the robot's own sitgen controller (``sitgen serve-controller``) and logs each
step, and the core compares that log with sitgen's own run (``sitgen_core::crosscheck``):
pose divergence, first stalls, both event logs from sitgen's monitor, and Stage's scans against
sitgen's laser from the same poses. ``docs/stage.md`` says which differences are by design.
"""

from __future__ import annotations

import contextlib
import json
import os
import shlex
import signal
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sitgen import _core
from sitgen.controllers.host import MAX_LINE_BYTES
from sitgen.world.config import spec_json
from sitgen.world.situation import Situation

#: Where ``integrations/stage/build.sh`` builds Stage and the plugin, from the repository root.
DEFAULT_BUILD = Path("target") / "stage"
#: The plugin's file name (Stage's loader adds ``.so``).
PLUGIN_FILE = "sitgen_stage.so"
#: The plugin's log, in the export folder.
LOG_FILE = "stage-log.jsonl"


class StageError(RuntimeError):
    """Stage could not be run, or its run did not finish."""


@dataclass(frozen=True)
class StageTool:
    """A built Stage binary and the folder holding the ``sitgen_stage`` plugin."""

    stage: Path
    plugin_dir: Path

    @classmethod
    def find(cls, stage: Path, plugin_dir: Path | None = None) -> StageTool:
        """The Stage at ``stage`` with the plugin in ``plugin_dir`` (default: Stage's own plugin
        folder, ``PREFIX/lib/Stage-4.3``, where ``build.sh`` installs it); one-line errors
        name what is missing."""
        if not (stage.is_file() and os.access(stage, os.X_OK)):
            raise StageError(f"--stage: {stage} is not an executable Stage binary")
        if plugin_dir is None:
            prefix = stage.resolve().parent.parent
            found = sorted(prefix.glob(f"lib*/Stage-*/{PLUGIN_FILE}"))
            if not found:
                raise StageError(
                    f"--plugin: no {PLUGIN_FILE} under {prefix}/lib*/Stage-*; build it with "
                    "integrations/stage/build.sh or name its folder with --plugin"
                )
            plugin_dir = found[0].parent
        if not (plugin_dir / PLUGIN_FILE).is_file():
            raise StageError(f"--plugin: no {PLUGIN_FILE} in {plugin_dir}")
        return cls(stage, plugin_dir)


def controller_command() -> str:
    """The command the plugin starts for each robot: this interpreter's sitgen, so Stage's
    controllers are exactly the ones this process would run."""
    return shlex.join([sys.executable, "-m", "sitgen", "serve-controller"])


def run_stage(
    situation: Situation,
    run_spec: Mapping[str, Any],
    tool: StageTool,
    folder: Path,
    timeout_s: float = 600.0,
) -> str:
    """Export ``situation`` into ``folder``, run it in Stage to its time limit, and return the
    plugin's log (JSON Lines)."""
    situation.export(folder, "stage", run=run_spec)
    log = folder / LOG_FILE
    log.unlink(missing_ok=True)
    env = {
        **os.environ,
        "STAGEPATH": str(tool.plugin_dir),
        "SITGEN_STAGE_CONTROLLER": controller_command(),
        "SITGEN_STAGE_LOG": LOG_FILE,
        # A Stage installed into a prefix of its own finds libstage there.
        "LD_LIBRARY_PATH": os.pathsep.join(
            [str(tool.stage.resolve().parent.parent / "lib"), os.environ.get("LD_LIBRARY_PATH", "")]
        ),
    }
    # Stage runs in a process group of its own, with the controllers its plugin starts: the
    # whole group ends with the run, whether Stage finished, hung or sitgen was interrupted.
    stage = subprocess.Popen(
        [str(tool.stage), "-g", "situation.world"],
        cwd=folder,
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        stdout, stderr = stage.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise StageError(f"Stage did not finish within {timeout_s:g} s") from None
    finally:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(stage.pid, signal.SIGKILL)
        stage.wait()
    if stage.returncode != 0 or not log.is_file():
        tail = (stderr.strip().splitlines() or stdout.strip().splitlines() or [""])[-1]
        raise StageError(f"Stage exited with code {stage.returncode}: {tail}")
    return log.read_text()


def crosscheck(
    situation: Situation,
    run_spec: Mapping[str, Any],
    tool: StageTool,
    folder: Path | None = None,
    timeout_s: float = 600.0,
) -> dict[str, Any]:
    """Run ``situation`` in sitgen and in Stage and compare them; the report as a dict (see
    ``sitgen_core::crosscheck::Report``). ``folder`` keeps Stage's world and log (default: a
    temporary folder, removed after)."""
    resolved = _core.check_run_spec(spec_json(dict(run_spec), "run"))
    where = (
        nullcontext(str(folder))
        if folder is not None
        else tempfile.TemporaryDirectory(prefix="sitgen-stage-")
    )
    with where as path:
        Path(path).mkdir(parents=True, exist_ok=True)
        log = run_stage(situation, run_spec, tool, Path(path), timeout_s)
    report: dict[str, Any] = json.loads(_core.crosscheck_stage(situation.to_json(), resolved, log))
    return report


def serve_controller(situation: Situation, run_spec: Mapping[str, Any], robot: int) -> int:
    """Answer controller-protocol messages on stdin with robot ``robot``'s built-in controller,
    one reply line per message on stdout, until ``end`` or the end of input. A bad message
    (not the protocol, an observation before ``reset``, a line over
    :data:`~sitgen.controllers.host.MAX_LINE_BYTES`) gets ``{"error": …}`` and ends the loop.
    Returns the exit code: 0 after ``end`` or the end of input, 1 after a bad message."""
    served = _core.ServedController(situation.to_json(), spec_json(dict(run_spec), "run"), robot)
    out = sys.stdout
    reset = False

    def refuse(why: str) -> int:
        out.write(json.dumps({"error": f"robot {robot}: {why}"}) + "\n")
        out.flush()
        return 1

    while raw := sys.stdin.buffer.readline(MAX_LINE_BYTES + 1):
        if len(raw) > MAX_LINE_BYTES:
            return refuse(f"a line longer than {MAX_LINE_BYTES} bytes")
        line = raw.decode("utf-8", "replace")
        if not line.strip():
            continue
        kind = _message_type(line)
        if kind == "observation" and not reset:
            return refuse("an observation before reset")
        reset = reset or kind == "reset"
        try:
            reply = served.answer(line)
        except ValueError as e:
            return refuse(str(e))
        if reply is None:
            return 0
        out.write(reply + "\n")
        out.flush()
    return 0


def _message_type(line: str) -> str | None:
    """A protocol message's ``type`` (None where the line is not a JSON object: the core
    answers it with the reason)."""
    try:
        message = json.loads(line)
    except ValueError:
        return None
    return message.get("type") if isinstance(message, dict) else None


def _fmt_s(t: float | None) -> str:
    return "never" if t is None else f"{t:.1f} s"


def report_text(report: Mapping[str, Any]) -> str:
    """The report for a person: outcomes, divergence per robot, stalls, events, scans."""
    lines = [f"situation {report['situation']}"]
    lines.append(f"start poses: Stage within {report['start_pose_error_m'] * 1000:.2f} mm")
    for name in ("sitgen", "stage"):
        side = report[name]
        lines.append(
            f"{name:>6}: {side['outcome']} after {side['steps']} steps, score "
            f"{side['score']:g}, failure {side['failure'] or '-'}, {len(side['events'])} events"
        )
    lines.append("divergence (position error; first over 1 cm / 10 cm / 1 m; first stall):")
    stalls = zip(report["sitgen"]["first_stall"], report["stage"]["first_stall"], strict=True)
    for d, (a, b) in zip(report["divergence"], stalls, strict=True):
        at = {round(t): e for t, e, _ in d["series"]}
        shown = ", ".join(f"{t} s {at[t]:.3f} m" for t in (1, 5, 10, 30) if t in at)
        over = " / ".join(_fmt_s(t) for t in d["first_over_s"])
        lines.append(
            f"  robot {d['id']}: {shown}; max {d['max_position_m']:.3f} m; over {over}; "
            f"stall sitgen {a if a is not None else '-'} / Stage {b if b is not None else '-'}"
        )
    lines.append("events (kind robot other: sitgen / Stage, first start):")
    for m in report["events"]:
        other = "-" if m["other"] is None else m["other"]
        first = " / ".join(_fmt_s(t) for t in m["first_s"])
        lines.append(f"  {m['kind']} {m['robot']} {other}: {m['sitgen']} / {m['stage']} ({first})")
    s = report["scans"]
    both = s["beams"] - s["both_max"] - s["stage_only_hit"] - s["sitgen_only_hit"]
    lines.append(
        f"scans (Stage against sitgen's laser from the same poses): {s['scans']} scans, "
        f"{s['beams']} beams; both open {s['both_max']}, both hit {both}, only Stage hit "
        f"{s['stage_only_hit']}, only sitgen hit {s['sitgen_only_hit']} "
        f"({s['sitgen_only_hit_near_max']} in the last tenth of the range)"
    )
    lines.append(
        f"  where both hit: median {s['median_abs_m'] * 100:.2f} cm, 95% "
        f"{s['p95_abs_m'] * 100:.2f} cm, max {s['max_abs_m'] * 100:.2f} cm, "
        f"{s['within_3cm'] * 100:.1f}% within 3 cm"
    )
    lines.append(
        f"  same robots seen in {s['same_robots_seen']} of {s['scans']} scans; only Stage "
        f"{s['seen_only_by_stage'] or '-'}; only sitgen {s['seen_only_by_sitgen'] or '-'}"
    )
    return "\n".join(lines) + "\n"
