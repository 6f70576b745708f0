"""The process a ``python:MODULE:CLASS`` controller runs in.

A Python controller runs in a child process of its own, spoken to over the JSON-lines
controller protocol (docs/controller-protocol.md) exactly like a ``cmd:`` program, so that
whatever it does — loop forever, call ``sys.exit``, ``os._exit``, crash the interpreter,
exhaust memory — ends only its own run, with the same per-step timeout as a program and
nothing left behind. ``python -c "from sitgen.controllers.host import main; main()" MODULE:CLASS
[PARAMS]``, PARAMS the class's keyword arguments as a JSON object.

Failures the host can see (the class does not load, ``reset`` or ``act`` raises, ``act``
returns something that is not a pair of numbers, ``sys.exit`` is called) are answered with
``{"error": "…"}``, a one-line reason that the run reports; anything else shows as the process
dying or not replying in time.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from sitgen.world.sim import Observation

MAX_LINE_BYTES = 1 << 20
"""Longest line of the controller protocol either side reads (a message is a few kilobytes:
even 10,000 beams are about 200 KB); a longer one is a broken peer, refused before it costs
memory."""


def die_with_parent() -> None:
    """Ask Linux to kill this process when its parent dies (PR_SET_PDEATHSIG), so that a
    killed sitgen leaves no controller or worker behind; a no-op elsewhere."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    pr_set_pdeathsig = 1
    try:
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return


def exception_line(e: BaseException) -> str:
    """``Type: first line of the message``; the type alone where the message cannot be had
    (an exception whose ``__str__`` itself raises, or exits)."""
    try:
        text = str(e).strip().splitlines()
    except BaseException:  # a user's exception: its text is best effort
        text = []
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


def _short(value: Any) -> str:
    try:
        shown = repr(value)
    except BaseException:  # a user's object: its text is best effort
        shown = f"a {type(value).__name__}"
    return shown if len(shown) <= 80 else shown[:77] + "..."


_CLASSES: dict[tuple[str, str], Any] = {}
"""Classes loaded in this process, by folder and ``module:Class`` target: a pool worker imports
a user's module once, however many runs it makes (each run gets a fresh instance)."""


def find_class(target: str) -> Any:
    """The class (or factory) ``module:Class`` or ``path/to/file.py:Class`` names, imported once
    per process; raises ValueError with the one-line reason (the text after the controller's
    name)."""
    key = (os.getcwd(), target)
    if key in _CLASSES:
        return _CLASSES[key]
    module_name, sep, attr = target.rpartition(":")
    if not sep or not module_name or not attr:
        raise ValueError("expected python:MODULE:CLASS")
    try:
        if module_name.endswith(".py"):
            path = Path(module_name)
            spec = importlib.util.spec_from_file_location(path.stem, path)
            if spec is None or spec.loader is None or not path.is_file():
                raise ValueError(f"no file {path}")
            module = importlib.util.module_from_spec(spec)
            # In sys.modules as an import would put it (unless the name is taken), so that
            # pickle finds its functions and classes: a class using multiprocessing needs it.
            sys.modules.setdefault(spec.name, module)
            try:
                spec.loader.exec_module(module)
            except BaseException:
                if sys.modules.get(spec.name) is module:
                    del sys.modules[spec.name]
                raise
        else:
            if os.getcwd() not in sys.path:
                sys.path.insert(0, os.getcwd())
            module = importlib.import_module(module_name)
    except ValueError:
        raise
    except BaseException as e:  # an import that fails in any way is the controller's fault
        raise ValueError(f"failed to load: {exception_line(e)}") from None
    if not hasattr(module, attr):
        raise ValueError(f"module has no `{attr}`")
    _CLASSES[key] = getattr(module, attr)
    return _CLASSES[key]


def instantiate(factory: Any, params: Mapping[str, float] | None = None) -> Any:
    """A new controller from ``factory`` (a class found by :func:`find_class`), given the
    controller's ``params`` as keyword arguments, checked for ``reset`` and ``act``; raises
    ValueError with the one-line reason."""
    try:
        instance = factory(**dict(params or {}))
    except BaseException as e:  # so is a constructor that fails
        raise ValueError(f"failed to load: {exception_line(e)}") from None
    for method in ("reset", "act"):
        if not callable(getattr(instance, method, None)):
            raise ValueError(f"has no method `{method}`")
    return instance


def load_class(target: str, params: Mapping[str, float] | None = None) -> Any:
    """An instance of ``module:Class`` or ``path/to/file.py:Class`` made with ``params``;
    raises ValueError with the one-line reason (the text after the controller's name)."""
    return instantiate(find_class(target), params)


class BadReply(Exception):
    """``act`` returned something that is not a command."""


def command(value: Any, when: str) -> tuple[float, float]:
    """A (v, omega) pair from what ``act`` returned; NaN passes (the run rejects it). Text is
    not a pair of numbers, though ``"12"`` unpacks into two characters that convert."""
    if isinstance(value, (str, bytes, bytearray)):
        raise BadReply(f"{when} returned {_short(value)}; expected (v, omega) numbers")
    try:
        v, omega = value
        return float(v), float(omega)
    except (TypeError, ValueError):
        raise BadReply(f"{when} returned {_short(value)}; expected (v, omega) numbers") from None


def _observation(message: dict[str, Any], laser: dict[str, Any]) -> Any:

    return Observation(
        ranges=np.asarray(message["ranges"], dtype=np.float64),
        angles=laser["angles"],
        max_range=laser["range_m"],
        pose=tuple(message["pose"]),
        velocity=tuple(message["velocity"]),
        stalled=message["stalled"],
        time=message["time"],
        tracks=tuple(
            {"id": t["id"], "position": tuple(t["position"]), "velocity": tuple(t["velocity"])}
            for t in message["tracks"]
        ),
        waypoints_reached=message.get("waypoints_reached", 0),
    )


def serve(
    target: str, inbox: IO[str], outbox: IO[str], params: Mapping[str, float] | None = None
) -> int:
    """Answer the protocol's messages from ``inbox`` on ``outbox`` until ``end``, for an
    instance of ``target`` made with ``params``."""

    def reply(message: dict[str, Any]) -> None:
        outbox.write(json.dumps(message) + "\n")
        outbox.flush()

    try:
        controller, failure = load_class(target, params), None
    except ValueError as e:
        controller, failure = None, str(e)
    laser: dict[str, Any] = {}
    for line in inbox:
        message = json.loads(line)
        kind = message.get("type")
        if kind == "end":
            break
        if failure is not None:
            reply({"error": failure})
            return 1
        if kind == "probe":
            reply({"ready": True})
            continue
        when = "in reset" if kind == "reset" else f"at {message.get('time', 0.0):.1f} s"
        try:
            if kind == "reset":
                laser = {
                    "angles": np.asarray(message["laser"]["angles"], dtype=np.float64),
                    "range_m": float(message["laser"]["range_m"]),
                }
                controller.reset({k: v for k, v in message.items() if k != "type"})
                reply({"ready": True})
            else:
                v, omega = command(controller.act(_observation(message, laser)), when)
                reply({"v": v, "omega": omega})
        except BadReply as e:
            reply({"error": str(e)})
            return 1
        except SystemExit as e:
            reply({"error": f"called sys.exit({e.code!r}) {when}"})
            return 1
        except BaseException as e:  # a user's bug must end this run only
            reply({"error": f"raised {when}: {exception_line(e)}"})
            return 1
    return 0


def main() -> None:
    die_with_parent()
    # The protocol owns the real stdout; anything the controller prints goes to stderr.
    outbox = os.fdopen(os.dup(sys.stdout.fileno()), "w")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    sys.stdout = sys.stderr
    params = json.loads(sys.argv[2]) if len(sys.argv) > 2 else None
    sys.exit(serve(sys.argv[1], sys.stdin, outbox, params))


if __name__ == "__main__":
    main()
