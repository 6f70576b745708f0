"""A Python controller called in this process, from the core's step loop: the fast path.

What it does: runs a controller object's ``reset(info)`` and ``act(obs) -> (v, omega)``
without leaving the process — for an object handed to :func:`sitgen.run`, and for a
``python:MODULE:CLASS`` controller in a campaign's pool worker, made there by a runner (a
process the worker forks and keeps while runs leave it clean: :mod:`sitgen.controllers.sandbox`),
where the class is imported once per runner and each run gets a fresh instance. The core steps
the run and calls ``act`` whenever the agent decides (``_core.Run.drive``), with the scan as
one numpy array (a copy of the core's buffer, never a Python float per beam) and the same
:class:`Observation` the host process builds, so a run gives the same bytes on either path.

Why: a host process (:mod:`sitgen.controllers.host`) costs a JSON round trip through two pipes
per step, hundreds of times what a cheap controller itself costs. Its isolation is kept another
way: an exception, ``sys.exit`` or a bad reply — raised from the class's call, from converting
what it returned, from formatting its exception or from its ``close`` — ends the run with the
host's one-line reason. A call that uses up its step timeout of processor time is interrupted
(SIGPROF), one that waits past the wall-clock backstop too (SIGALRM, which the core's watchdog
thread sends; a call the machine starved of a core then is the machine's error, made again,
never the controller's) — main thread only; a signal that lands once the call has returned is
dropped, and a class that swallows the interruption was late all the same — and one that cannot
be interrupted (a C loop holding the GIL) has its runner killed ``KILL_GRACE_S`` later by that
thread. A runner
that dies — that kill, ``os._exit``, a crash, the out-of-memory killer — is replaced, and an
agent's run is made again in a host process, which reports what the controller did exactly as
it always has; what the class started and left behind dies with its run.

Parameters: ``step_timeout_s`` (seconds of processor time, default :data:`STEP_TIMEOUT_S`,
1 s) per ``act``, with a wall-clock backstop of ten times that (at most 20 s more, at least
2 s: :func:`~sitgen.controllers.deadlines.backstop_s`); reset and class loading get
:data:`START_TIMEOUT_S` (10 s) of processor time and its backstop; in a runner the watchdog
kills :data:`KILL_GRACE_S` past either limit.

Source: sitgen's controller protocol (docs/controller-protocol.md), whose messages this path
skips but whose meaning and error reasons it keeps.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.controllers import sandbox
from sitgen.controllers.deadlines import (
    STEP_TIMEOUT_S,
    WAITING_ON_ITS_OWN,
    ControllerError,
    backstop_s,
    computing_too_long,
    did_not_reply,
    starved,
    starved_reason,
)
from sitgen.controllers.external import END_TIMEOUT_S, START_TIMEOUT_S, UserController
from sitgen.controllers.host import BadReply, command, exception_line, find_class, instantiate
from sitgen.world.sim import Observation

KILL_GRACE_S = 1.0
"""How long past its timeout a call that ignores SIGALRM may run before the watchdog kills its
worker (a pool worker only; the run is then made again in a host process)."""


class StepTimeout(BaseException):
    """A call ran past its timeout (a BaseException, so that a controller's own
    ``except Exception`` cannot swallow it): its processor time (``cpu``) or its wall-clock
    backstop (``wall``)."""


class InProcessController(UserController):
    """An object with ``reset(info)`` and ``act(obs)``, or a ``python:`` target loaded in this
    process, called without leaving it. ``isolated``: this process is a disposable pool worker
    (the watchdog may kill it; any exception is the controller's, as in a host process)."""

    def __init__(
        self,
        target: Any,
        name: str,
        step_timeout_s: float = STEP_TIMEOUT_S,
        isolated: bool = False,
        params: Mapping[str, float] | None = None,
    ) -> None:
        self.name = name
        self._target: Any = None
        self._path = target if isinstance(target, str) else None
        if self._path is None:
            self._target = _checked(target, name)
        self._step_timeout_s = step_timeout_s
        self._isolated = isolated
        self._params = dict(params or {})
        # A host process reports any exception; in the caller's own process Ctrl-C stays its,
        # but a controller's sys.exit still ends only its run.
        self._caught: tuple[type[BaseException], ...] = (
            (BaseException,) if isolated else (Exception, SystemExit)
        )
        self._angles: np.ndarray[Any, np.dtype[np.float64]] = np.zeros(0)
        self._max_range = 0.0

    def load(self) -> None:
        if self._target is not None:
            return
        assert self._path is not None
        sandbox.note(self.name, sandbox.IN_RESET, 0.0, START_TIMEOUT_S)
        with self._watched(START_TIMEOUT_S):
            try:
                self._target = instantiate(find_class(self._path), self._params)
            except ValueError as e:
                raise ControllerError(f"controller {self.name} {e}") from None
            finally:
                sandbox.returned_in_fork()

    def reset(self, info: dict[str, Any]) -> None:
        self.load()
        # As the host process gets it: through JSON, lists where the info has tuples.
        told = json.loads(json.dumps(info))
        self._angles = np.asarray(told["laser"]["angles"], dtype=np.float64)
        self._max_range = float(told["laser"]["range_m"])
        sandbox.note(self.name, sandbox.IN_RESET, 0.0, START_TIMEOUT_S)
        with self._watched(START_TIMEOUT_S):
            self._call(lambda: self._target.reset(told), "in reset", START_TIMEOUT_S)

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        when = f"at {obs['time']:.1f} s"
        observation = self._observation(
            np.asarray(obs["ranges"], dtype=np.float64),
            tuple(obs["pose"]),
            tuple(obs["velocity"]),
            obs["stalled"],
            obs["time"],
            tuple(
                {"id": t["id"], "position": tuple(t["position"]), "velocity": tuple(t["velocity"])}
                for t in obs["tracks"]
            ),
            obs.get("waypoints_reached", 0),
        )
        sandbox.note(self.name, sandbox.AT_STEP, float(obs["time"]), self._step_timeout_s)
        with self._watched(self._step_timeout_s):
            return self._call(  # type: ignore[no-any-return]
                lambda: command(self._target.act(observation), when), when, self._step_timeout_s
            )

    def drive(self, core: _core.Run) -> None:
        """Step ``core`` to its end, the core calling ``act`` whenever the agent decides;
        raises ControllerError when the controller fails (the run stops at that step)."""
        target_act, observation = self._target.act, self._observation
        timeout_s = self._step_timeout_s
        caught, reason_of, overdue = self._caught, self._reason_of, self._overdue
        timed = _can_time()
        at = [0.0]
        armed, fired = _ARMED, _FIRED
        sandbox.note(self.name, sandbox.AT_STEP, 0.0, timeout_s)
        # Looked up once: each is read every step.
        shared, forked = sandbox.page(), sandbox.FORKED

        def act(
            ranges: Any, pose: Any, velocity: Any, stalled: bool, time_s: float, tracks: Any, k: int
        ) -> tuple[float, float]:
            at[0] = time_s
            if shared is not None:
                shared[2] = time_s  # for the reason, should this runner die in the call
            obs = observation(ranges, pose, velocity, stalled, time_s, tracks, k)
            if timed:
                fired[0] = ""
                armed[0] = True
                _core.cpu_deadline(timeout_s)
            try:
                value = target_act(obs)
                # The common reply, checked inline: a pair of floats is the command as it is.
                if type(value) is tuple and len(value) == 2:
                    v, omega = value
                    if type(v) is float and type(omega) is float:
                        command_ = value
                    else:
                        command_ = command(value, f"at {time_s:.1f} s")
                else:
                    command_ = command(value, f"at {time_s:.1f} s")
            except StepTimeout as late:
                raise overdue(str(late), f"at {time_s:.1f} s", timeout_s) from None
            except BadReply as e:
                raise ControllerError(f"controller {self.name} {e}") from None
            except caught as e:  # a user's bug must end this run only
                raise reason_of(e, f"at {time_s:.1f} s") from None
            finally:
                if timed:
                    armed[0] = False
                    _core.cpu_deadline(0)
                if forked[0]:
                    sandbox.returned_in_fork()
            if fired[0]:  # the class caught the timeout and went on: it was late all the same
                raise overdue(fired[0], f"at {time_s:.1f} s", timeout_s)
            return command_

        limits = self._limits(timeout_s) if timed else None
        try:
            with _alarm(timed):
                core.drive(act, limits)
        except StepTimeout as late:
            raise overdue(str(late), f"at {at[0]:.1f} s", timeout_s) from None

    def peer_act(self) -> Callable[..., tuple[float, float]]:
        """The call the core makes whenever the peer this controller drives decides (the
        arguments of ``_core.Run.drive``'s ``act``; ``_core.Run.set_peers``): each call under
        the step timeout, a failure a ControllerError naming the controller."""
        target_act, observation, timeout_s = (
            self._target.act,
            self._observation,
            self._step_timeout_s,
        )

        def act(
            ranges: Any, pose: Any, velocity: Any, stalled: bool, time_s: float, tracks: Any, k: int
        ) -> tuple[float, float]:
            obs = observation(ranges, pose, velocity, stalled, time_s, tracks, k)
            when = f"at {time_s:.1f} s"
            sandbox.note(self.name, sandbox.AT_STEP, time_s, timeout_s)
            with self._watched(timeout_s):
                reply: tuple[float, float] = self._call(
                    lambda: command(target_act(obs), when), when, timeout_s
                )
            return reply

        return act

    def _observation(
        self,
        ranges: Any,
        pose: Any,
        velocity: Any,
        stalled: bool,
        time_s: float,
        tracks: Any,
        waypoints_reached: int,
    ) -> Observation:
        return Observation(
            ranges=ranges,
            angles=self._angles,
            max_range=self._max_range,
            pose=pose,
            velocity=velocity,
            stalled=stalled,
            time=time_s,
            tracks=tracks,
            waypoints_reached=waypoints_reached,
        )

    def _limits(
        self, timeout_s: float, wall_s: float | None = None
    ) -> tuple[float, float, float | None]:
        """The watchdog's limits for a call of processor-time deadline ``timeout_s``: SIGALRM
        at ``wall_s`` (default its backstop) and, in a runner, the kill :data:`KILL_GRACE_S`
        past either."""
        wall_s = wall_s or backstop_s(timeout_s)
        return timeout_s, wall_s, KILL_GRACE_S if self._isolated else None

    def _overdue(
        self, how: str, when: str, timeout_s: float, wall_s: float | None = None
    ) -> ControllerError:
        """The error of a call past its deadline (``how``: ``cpu`` or ``wall``, at ``wall_s``,
        default its backstop); at the backstop, the machine's error if it kept the call from a
        core (read while the call is still watched)."""
        if how == "cpu":
            return ControllerError(computing_too_long(self.name, timeout_s, when))
        wall_s = wall_s or backstop_s(timeout_s)
        seen = _core.watched_call()
        if seen is not None and starved(*seen):
            return starved_reason(self.name, wall_s, when)
        return ControllerError(did_not_reply(self.name, f"{wall_s:g} s", when, WAITING_ON_ITS_OWN))

    def _call(
        self, call: Callable[[], Any], when: str, timeout_s: float, wall_s: float | None = None
    ) -> Any:
        """``call()`` (the class's code, and converting what it returned) under ``timeout_s``
        of processor time (and ``wall_s`` of wall clock, default its backstop: the watchdog's,
        :meth:`_watched`): whatever it raises, however late it is, ends this run only, with the
        host's reason."""
        try:
            try:
                with _alarm(_can_time()), _deadline(timeout_s):
                    value = call()
            finally:
                sandbox.returned_in_fork()
            if _FIRED[0]:  # the class caught the timeout and went on: it was late all the same
                raise StepTimeout(_FIRED[0])
            return value
        except StepTimeout as late:
            raise self._overdue(str(late), when, timeout_s, wall_s) from None
        except BadReply as e:
            raise ControllerError(f"controller {self.name} {e}") from None
        except self._caught as e:  # a user's bug must end this run only
            raise self._reason_of(e, when) from None

    def _reason_of(self, e: BaseException, when: str) -> ControllerError:
        """What the controller did, as the host process says it: ``sys.exit`` or a raise."""
        if isinstance(e, SystemExit):
            return ControllerError(f"controller {self.name} called sys.exit({e.code!r}) {when}")
        return ControllerError(f"controller {self.name} raised {when}: {exception_line(e)}")

    @contextlib.contextmanager
    def _watched(self, timeout_s: float, wall_s: float | None = None) -> Iterator[None]:
        """The watchdog armed around a call made from Python: its backstop (``wall_s``,
        default :func:`backstop_s`), and in a runner its kill."""
        if not _can_time():
            yield
            return
        _core.watch_call(self._limits(timeout_s, wall_s))
        try:
            yield
        finally:
            _core.watch_call(None)

    def close(self) -> str | None:
        """Best effort, under :data:`END_TIMEOUT_S` as a program's exit after ``end`` is: the
        run's outcome is already set, and whatever ``close`` does ends here."""
        close = getattr(self._target, "close", None)
        if not callable(close):
            return None
        sandbox.note(self.name, sandbox.IN_CLOSE, 0.0, END_TIMEOUT_S)
        try:
            # Wall clock, as a program's exit after `end` is: the run is over.
            with self._watched(END_TIMEOUT_S, END_TIMEOUT_S):
                self._call(close, "in close()", END_TIMEOUT_S, END_TIMEOUT_S)
        except ControllerError as e:
            return str(e).removeprefix(f"controller {self.name} ")
        return None


def _checked(target: Any, name: str) -> Any:
    for method in ("reset", "act"):
        if not callable(getattr(target, method, None)):
            raise ControllerError(f"controller {name} has no method `{method}`")
    return target


def _can_time() -> bool:
    """Whether SIGALRM can interrupt a call here (only Python's main thread receives it)."""
    return threading.current_thread() is threading.main_thread()


_ARMED = [False]
"""Whether a call is under its deadline now: a signal that lands once the call has returned
(late, or pending while the machine paused this process) is dropped, never raised in sitgen's
own code."""
_FIRED = [""]
"""Which deadline of the call under way fired (``cpu``, ``wall``; "" none): a class that
catches the StepTimeout and goes on was late all the same."""
_DEADLINES = {signal.SIGPROF: "cpu", signal.SIGALRM: "wall"}


def _expire(signum: int, frame: object) -> None:
    if _ARMED[0]:
        _FIRED[0] = _DEADLINES[signal.Signals(signum)]
        raise StepTimeout(_FIRED[0])


@contextlib.contextmanager
def _alarm(timed: bool) -> Iterator[None]:
    """SIGPROF (the call's processor time) and SIGALRM (its backstop, from the watchdog) raise
    StepTimeout within the block (when ``timed``)."""
    if not timed:
        yield
        return
    previous = {number: signal.signal(number, _expire) for number in _DEADLINES}
    try:
        yield
    finally:
        _ARMED[0] = False
        _core.cpu_deadline(0)
        for number, handler in previous.items():
            signal.signal(number, handler)


@contextlib.contextmanager
def _deadline(timeout_s: float) -> Iterator[None]:
    """Interrupt the block with StepTimeout after ``timeout_s`` of this process's processor
    time (SIGPROF, so only in the main thread; elsewhere the block runs unbounded); its
    backstop is the watchdog's (:meth:`InProcessController._watched`)."""
    if not _can_time():
        yield
        return
    _FIRED[0] = ""
    _ARMED[0] = True
    _core.cpu_deadline(timeout_s)
    try:
        yield
    finally:
        _ARMED[0] = False
        _core.cpu_deadline(0)
