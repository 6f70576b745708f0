"""User controllers by name: ``python:module:Class``, ``cmd:program args…``,
``ros2:command args…`` and ``navground:BEHAVIOR`` (or any object with ``reset`` and ``act``),
loaded and checked here so that the rest of sitgen asks one place what a name means
(docs/controller-protocol.md, docs/ros2.md, docs/navground.md)."""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from typing import Any

from sitgen.controllers.deadlines import STEP_TIMEOUT_S, ControllerError
from sitgen.controllers.external import (
    ProcessController,
    UserController,
    command_argv,
    program_path,
)
from sitgen.controllers.host import find_class, instantiate
from sitgen.controllers.inprocess import InProcessController
from sitgen.controllers.navground import PREFIX as NAVGROUND_PREFIX
from sitgen.controllers.navground import STEP_TIMEOUT_S as NAVGROUND_STEP_TIMEOUT_S
from sitgen.controllers.navground import NavgroundController
from sitgen.controllers.ros2.controller import PREFIX as ROS2_PREFIX
from sitgen.controllers.ros2.controller import Ros2Controller, check_ros2_name, kept_node

USER_PREFIXES = ("python:", "cmd:", ROS2_PREFIX, NAVGROUND_PREFIX)
"""How a user controller's name starts (the core runs every other name itself)."""


def load_controller(
    name: str | Any,
    step_timeout_s: float | None = None,
    params: Mapping[str, float] | None = None,
    in_process: bool = False,
    keep_alive: bool = False,
) -> UserController:
    """The user controller ``name`` names (``python:…``, ``cmd:…``, ``ros2:…``; ``params``
    are a class's keyword arguments, a ROS 2 node's parameters; a program reads them in its
    reset message), or wrap an object with ``reset`` and ``act`` (called in
    this process). ``in_process``: a ``python:`` class is loaded and called in this process,
    a disposable pool worker (:mod:`sitgen.controllers.inprocess`), not in a host process of
    its own. ``keep_alive``: a ``ros2:`` node is the one kept alive in this process for such
    runs (:func:`sitgen.controllers.ros2.kept_node`). Raises ControllerError if it cannot be
    started. ``step_timeout_s``: processor seconds per step (None: the kind's default)."""
    if not isinstance(name, str):
        return InProcessController(
            name, f"`{type(name).__name__}`", step_timeout_s or STEP_TIMEOUT_S
        )
    shown = f"`{name}`"
    if name.startswith(NAVGROUND_PREFIX):
        # A navground behaviour is a Python class of sitgen's, on the path a `python:` class
        # takes: called in a pool worker, in a host process of its own elsewhere. Its steps
        # take milliseconds, and a crowd's can take far more; only a step that hangs ends its
        # run unless the user says otherwise.
        name = f"python:{navground_target(name)}"
        step_timeout_s = step_timeout_s or NAVGROUND_STEP_TIMEOUT_S
    step_timeout_s = step_timeout_s or STEP_TIMEOUT_S
    if name.startswith("python:") and in_process:
        target = name.removeprefix("python:")
        return InProcessController(target, shown, step_timeout_s, True, params)
    if name.startswith("python:"):
        # Not `-m`: the package imports the host module, and runpy would warn that it ran a
        # module already imported.
        start = "from sitgen.controllers.host import main; main()"
        host = [sys.executable, "-c", start, name.removeprefix("python:")]
        if params:
            host.append(json.dumps(dict(params)))
        return ProcessController(host, shown, step_timeout_s, host=True)
    if name.startswith("cmd:"):
        command_line = name.removeprefix("cmd:")
        argv = command_argv(command_line, f"`{name}`")
        return ProcessController(argv, f"`{name}`", step_timeout_s)
    if name.startswith(ROS2_PREFIX) and keep_alive:
        return kept_node(name.removeprefix(ROS2_PREFIX), f"`{name}`", params, step_timeout_s)
    if name.startswith(ROS2_PREFIX):
        return Ros2Controller(name.removeprefix(ROS2_PREFIX), f"`{name}`", params, step_timeout_s)
    raise ControllerError(f"controller `{name}` is none of python:…, cmd:…, ros2:…, navground:…")


def load_peer_controller(
    name: str,
    shown: str,
    params: Mapping[str, float] | None,
    isolated: bool,
    step_timeout_s: float | None = None,
) -> InProcessController:
    """A peer's controller (``python:…`` or ``navground:…``, the only kinds a peer may run),
    called in this process, ``shown`` in its errors; ``isolated``: this process is a
    disposable pool worker; ``step_timeout_s``: processor seconds per step (None: the kind's
    default). Raises ControllerError if it cannot be loaded."""
    if name.startswith(NAVGROUND_PREFIX):
        target, timeout_s = navground_target(name), NAVGROUND_STEP_TIMEOUT_S
    elif name.startswith("python:"):
        target, timeout_s = name.removeprefix("python:"), STEP_TIMEOUT_S
    else:
        raise ControllerError(
            f"controller {shown}: a peer's controller is built in, python: or navground:"
        )
    controller = InProcessController(target, shown, step_timeout_s or timeout_s, isolated, params)
    controller.load()
    return controller


def navground_target(name: str) -> str:
    """The ``module:Class`` target that runs the ``navground:BEHAVIOR`` controller ``name``;
    ControllerError naming the form where no behaviour is given."""
    behavior = name.removeprefix(NAVGROUND_PREFIX)
    if not behavior.strip():
        raise ControllerError(
            f"controller `{name}` expected navground:BEHAVIOR (HL, ORCA, HRVO, SocialForce, or "
            "one a plugin registers)"
        )
    return f"{NavgroundController.__module__}:{behavior}"


def check_controller_name(name: str, params: Mapping[str, float] | None = None) -> None:
    """Check, before any run, that a user controller can be used: a ``cmd:`` program that
    exists, a ``python:`` class that loads with ``params`` (in a host process, within the
    start timeout), a
    ``ros2:`` program that exists with the ROS 2 wheels installed. Raises ControllerError with
    the reason; built-in names are the core's to check."""
    if name.startswith("cmd:"):
        program_path(command_argv(name.removeprefix("cmd:"), f"`{name}`"), f"`{name}`")
    elif name.startswith(ROS2_PREFIX):
        check_ros2_name(name)
    elif name.startswith(NAVGROUND_PREFIX):
        try:  # cheap to make here: the behaviour's name and parameters are checked
            instantiate(find_class(navground_target(name)), params)
        except ValueError as e:
            raise ControllerError(f"controller `{name}` {e}") from None
    elif name.startswith("python:"):
        controller = load_controller(name, params=params)
        try:
            controller.load()
        finally:
            controller.close()


def is_user_controller(name: Any) -> bool:
    """Whether ``name`` is run by Python (``python:``, ``cmd:``, ``ros2:``, ``navground:``, or
    an object)."""
    return not isinstance(name, str) or name.startswith(USER_PREFIXES)
