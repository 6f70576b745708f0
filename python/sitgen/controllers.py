"""User controllers: a Python class, or any program speaking a JSON-lines protocol.

Both plug in as the agent's controller, named like the built-in ones:

- ``python:module:Class`` (``module`` importable from the current directory or a path to a
  ``.py`` file): an object with ``reset(info)`` and ``act(obs) -> (v, omega)``;
- ``cmd:program args…``: a program started without a shell, spoken to in lockstep, one JSON
  object per line each way (docs/controller-protocol.md), with a per-step wall-clock timeout.

Anything that goes wrong inside a controller — an exception, a crash, a hang, a reply that is
not a command — raises :exc:`ControllerError` with a one-line reason; a run turns it into an
``error`` outcome, and the next run starts a fresh controller.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import json
import os
import selectors
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from sitgen.sim import Observation

STEP_TIMEOUT_S = 1.0
"""Default wall-clock time a program has to answer one observation."""
START_TIMEOUT_S = 10.0
"""Default wall-clock time a program has to start and answer the reset message (an
interpreter's start-up can take seconds on a loaded machine)."""


class ControllerError(Exception):
    """A controller failed: the message is one line saying how and when."""


@runtime_checkable
class Controller(Protocol):
    """What a Python controller implements."""

    def reset(self, info: dict[str, Any]) -> None:
        """Start a run: ``info`` has ``robot_id``, ``start`` (x, y, heading), ``waypoints``,
        ``at_end``, ``body``, ``laser`` (with ``angles``), ``dt_s`` and the velocity limits."""

    def act(self, obs: Observation) -> tuple[float, float]:
        """The command (v m/s, omega rad/s) for this observation."""


class UserController:
    """A user controller behind the interface a run drives: reset, act, close."""

    name: str

    def reset(self, info: dict[str, Any]) -> None:
        raise NotImplementedError

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        raise NotImplementedError

    def close(self) -> None:
        """End the run; releases any process."""


def _command(value: Any, source: str) -> tuple[float, float]:
    """A (v, omega) pair from what a controller returned; NaN passes (the run rejects it)."""
    try:
        v, omega = value
        return float(v), float(omega)
    except (TypeError, ValueError):
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        raise ControllerError(f"{source} returned {shown}; expected (v, omega) numbers") from None


def _observation(obs: Mapping[str, Any]) -> Observation:
    return Observation(
        ranges=obs["ranges"],
        angles=obs["angles"],
        pose=obs["pose"],
        velocity=obs["velocity"],
        stalled=obs["stalled"],
        time=obs["time"],
        tracks=tuple(obs["tracks"]),
        waypoints_reached=obs.get("waypoints_reached", 0),
    )


class PythonController(UserController):
    """An object with ``reset(info)`` and ``act(obs)``; exceptions become ControllerError."""

    def __init__(self, target: Any, name: str) -> None:
        self.name = name
        for method in ("reset", "act"):
            if not callable(getattr(target, method, None)):
                raise ControllerError(f"controller {name} has no method `{method}`")
        self._target = target

    def reset(self, info: dict[str, Any]) -> None:
        try:
            self._target.reset(info)
        except Exception as e:  # a user's bug must end this run only
            raise ControllerError(f"controller {self.name} raised in reset: {_exc(e)}") from e

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        try:
            value = self._target.act(_observation(obs))
        except Exception as e:  # a user's bug must end this run only
            raise ControllerError(
                f"controller {self.name} raised at {obs['time']:.1f} s: {_exc(e)}"
            ) from e
        return _command(value, f"controller {self.name} at {obs['time']:.1f} s")

    def close(self) -> None:
        close = getattr(self._target, "close", None)
        if callable(close):
            # Closing is best effort: the run's outcome is already set.
            with contextlib.suppress(Exception):
                close()


def _exc(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


def _load_python(spec: str) -> PythonController:
    """``module:Class`` or ``path/to/file.py:Class``."""
    name = f"`python:{spec}`"
    module_name, sep, attr = spec.rpartition(":")
    if not sep or not module_name or not attr:
        raise ControllerError(f"controller {name}: expected python:MODULE:CLASS")
    try:
        if module_name.endswith(".py"):
            path = Path(module_name)
            loader_spec = importlib.util.spec_from_file_location(path.stem, path)
            if loader_spec is None or loader_spec.loader is None or not path.is_file():
                raise ControllerError(f"controller {name}: no file {path}")
            module = importlib.util.module_from_spec(loader_spec)
            loader_spec.loader.exec_module(module)
        else:
            if os.getcwd() not in sys.path:
                sys.path.insert(0, os.getcwd())
            module = importlib.import_module(module_name)
        cls = getattr(module, attr)
        return PythonController(cls(), name)
    except ControllerError:
        raise
    except AttributeError:
        raise ControllerError(f"controller {name}: module has no `{attr}`") from None
    except Exception as e:  # an import or constructor failure is the controller's fault
        raise ControllerError(f"controller {name} failed to load: {_exc(e)}") from e


class ProcessController(UserController):
    """A program in lockstep over stdin/stdout, one JSON object per line each way."""

    def __init__(
        self,
        command_line: str,
        step_timeout_s: float = STEP_TIMEOUT_S,
        start_timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        self.name = f"`cmd:{command_line}`"
        self._argv = shlex.split(command_line)
        if not self._argv:
            raise ControllerError("controller `cmd:`: no program given")
        self._step_timeout_s = step_timeout_s
        self._start_timeout_s = start_timeout_s
        self._proc: subprocess.Popen[bytes] | None = None
        self._buffer = b""
        # Where the program's stderr goes: a pipe nobody reads could fill and hang it; the
        # last line is quoted when it dies. Closed in close().
        self._stderr = tempfile.TemporaryFile()  # noqa: SIM115
        self._selector = selectors.DefaultSelector()

    def reset(self, info: dict[str, Any]) -> None:
        try:
            self._proc = subprocess.Popen(
                self._argv,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=self._stderr,
            )
        except OSError as e:
            raise ControllerError(f"controller {self.name} could not start: {e}") from e
        assert self._proc.stdout is not None
        os.set_blocking(self._proc.stdout.fileno(), False)
        self._selector.register(self._proc.stdout, selectors.EVENT_READ)
        self._exchange({"type": "reset", **info}, self._start_timeout_s, "on reset")

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        message = {
            "type": "observation",
            "time": obs["time"],
            "pose": list(obs["pose"]),
            "velocity": list(obs["velocity"]),
            "stalled": obs["stalled"],
            "waypoints_reached": obs.get("waypoints_reached", 0),
            "ranges": np.asarray(obs["ranges"]).tolist(),
            "tracks": [
                {"id": t["id"], "position": list(t["position"]), "velocity": list(t["velocity"])}
                for t in obs["tracks"]
            ],
        }
        when = f"at {obs['time']:.1f} s"
        reply = self._exchange(message, self._step_timeout_s, when)
        v, omega = reply.get("v"), reply.get("omega")
        if not all(isinstance(x, int | float) and not isinstance(x, bool) for x in (v, omega)):
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: expected "
                f'{{"v": number, "omega": number}}, got {_short(json.dumps(reply))}'
            )
        return float(v), float(omega)  # type: ignore[arg-type]

    def _exchange(self, message: dict[str, Any], timeout_s: float, when: str) -> dict[str, Any]:
        proc = self._proc
        assert proc is not None and proc.stdin is not None
        try:
            proc.stdin.write(json.dumps(message).encode() + b"\n")
            proc.stdin.flush()
        except (BrokenPipeError, OSError):
            raise ControllerError(self._died(when)) from None
        line = self._read_line(timeout_s, when)
        try:
            reply = json.loads(line)
        except ValueError:
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: not JSON: "
                f"{_short(line.decode(errors='replace'))}"
            ) from None
        if not isinstance(reply, dict):
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: expected a JSON "
                f"object, got {_short(line.decode(errors='replace'))}"
            )
        return reply

    def _read_line(self, timeout_s: float, when: str) -> bytes:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        deadline = time.monotonic() + timeout_s
        while b"\n" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not self._selector.select(left):
                if proc.poll() is not None:
                    raise ControllerError(self._died(when))
                raise ControllerError(
                    f"controller {self.name} did not reply within {timeout_s:g} s {when}"
                )
            chunk = os.read(proc.stdout.fileno(), 1 << 16)
            if not chunk:
                proc.wait()
                raise ControllerError(self._died(when))
            self._buffer += chunk
        line, _, self._buffer = self._buffer.partition(b"\n")
        return line.strip()

    def _died(self, when: str) -> str:
        assert self._proc is not None
        try:
            code = self._proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            code = None
        self._stderr.seek(0)
        tail = self._stderr.read().decode(errors="replace").strip().splitlines()
        said = f": {_short(tail[-1])}" if tail else ""
        how = f"exited with code {code}" if code is not None else "closed its output"
        return f"controller {self.name} {how} {when}{said}"

    def close(self) -> None:
        proc = self._proc
        if proc is not None:
            try:
                if proc.poll() is None and proc.stdin is not None:
                    proc.stdin.write(b'{"type": "end"}')
                    proc.stdin.write(b"\n")
                    proc.stdin.close()
                proc.wait(timeout=1.0)
            except (OSError, subprocess.TimeoutExpired):
                proc.kill()
                proc.wait()
            self._selector.close()
            if proc.stdout is not None:
                proc.stdout.close()
        self._stderr.close()
        self._proc = None


def _short(text: str) -> str:
    return repr(text if len(text) <= 80 else text[:77] + "...")


def load_controller(name: str | Any, step_timeout_s: float = STEP_TIMEOUT_S) -> UserController:
    """The user controller ``name`` names (``python:…``, ``cmd:…``), or wrap an object with
    ``reset`` and ``act``. Raises ControllerError if it cannot be loaded."""
    if not isinstance(name, str):
        return PythonController(name, f"`{type(name).__name__}`")
    if name.startswith("python:"):
        return _load_python(name.removeprefix("python:"))
    if name.startswith("cmd:"):
        return ProcessController(name.removeprefix("cmd:"), step_timeout_s)
    raise ControllerError(f"controller `{name}` is neither python:… nor cmd:…")


def is_user_controller(name: Any) -> bool:
    """Whether ``name`` is run by Python (``python:``, ``cmd:``, or an object)."""
    return not isinstance(name, str) or name.startswith(("python:", "cmd:"))
