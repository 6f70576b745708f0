"""User controllers: a Python class, or any program speaking a JSON-lines protocol.

Both plug in as the agent's controller, named like the built-in ones:

- ``python:module:Class`` (``module`` importable from the current directory or a path to a
  ``.py`` file): an object with ``reset(info)`` and ``act(obs) -> (v, omega)``, run in a
  process of its own (:mod:`sitgen.controllers.host`);
- ``cmd:program args…``: a program started without a shell, spoken to in lockstep, one JSON
  object per line each way (docs/controller-protocol.md).

Both get a per-step deadline of processor time with a wall-clock backstop, start in a process
group of their own that is killed
with everything in it when the run ends, and die with sitgen. Anything that goes wrong inside a
controller — an exception, ``sys.exit``, a crash, a hang, a closed pipe, a reply that is not a
command — raises :exc:`ControllerError` with a one-line reason; a run turns it into an ``error``
outcome, and the next run starts a fresh controller.
"""

from __future__ import annotations

import contextlib
import json
import os
import selectors
import shlex
import shutil
import signal
import subprocess
import time
from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np

from sitgen import _core
from sitgen.controllers.deadlines import (
    COMPUTING,
    STEP_TIMEOUT_S,
    WAITING_ON_ITS_OWN,
    WAITING_ON_OUTPUT,
    ControllerError,
    backstop_s,
    computing_too_long,
    did_not_reply,
    starved,
    starved_reason,
    stopped_reason,
)
from sitgen.controllers.host import MAX_LINE_BYTES
from sitgen.controllers.marks import die_with_parent_prefix, kill_marked, marked_env, marked_pids
from sitgen.controllers.proc_tasks import (
    BUSY_SHARE,
    STOPPED,
    cpu_seconds,
    schedstat_seconds,
    task_state,
)
from sitgen.world.sim import Observation

CPU_COUNTED_AFTER_S = 0.005
"""A reply not in this long after the observation (or a tenth of the step timeout, if less)
has the program's processor time read, to count its deadline from."""
PAUSED_S = 0.25
"""A wait for a program's reply that wakes this much later than it asked was paused with sitgen
(SIGSTOP, a suspended machine): the pause is added to the backstop, which measures the
program's waiting, not the machine's."""
START_TIMEOUT_S = 10.0
"""Default wall-clock time a program has to start and answer the reset message (an
interpreter's start-up can take seconds on a loaded machine)."""
END_TIMEOUT_S = 1.0
"""How long a controller program has to exit after `end` before it is killed."""
MAX_REPLY_BYTES = MAX_LINE_BYTES
"""Longest line a controller program may send (a reply is a few dozen bytes; a program that
writes more without a newline is broken, and is stopped before it costs memory)."""
CPU_LOOK_S = 0.05
"""How often (wall seconds) the processor time of a program that has not replied within its
step timeout of wall clock is read, until it replies, uses up that timeout of processor time or
reaches its backstop."""
STDERR_TAIL_BYTES = 4096
"""What is kept of a controller program's stderr: its tail, read as it comes, so that the
last line can be quoted when it dies however much it writes."""


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
    wants_map = False
    """Whether its reset info carries the situation's map (``map``: ``occupied`` rows, top
    row first, and ``resolution_m``): a ROS 2 node gets it as /map."""

    def reset(self, info: dict[str, Any]) -> None:
        raise NotImplementedError

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        raise NotImplementedError

    def load(self) -> None:
        """Make it ready to run (start its process, load its class); ControllerError if it
        cannot be."""

    def drive(self, core: _core.Run) -> None:
        """Step ``core`` to its end, asking :meth:`act` for a command whenever the agent
        decides (between its decisions its last command stays in force); raises
        ControllerError when the controller fails."""
        while True:
            command = self.act(core.observe_agent()) if core.agent_acts else None
            if core.step(command):
                return

    def close(self) -> str | None:
        """End the run; releases any process. Returns None if it shut down cleanly, else why
        not (``check-controller`` reports it; a run's outcome is already set)."""
        return None


def signal_name(number: int) -> str:
    """``SIGSEGV`` for 11; a real-time signal, which has no name of its own, as ``SIGRTMIN+6``
    (or ``signal 40`` where even that does not fit)."""
    try:
        return signal.Signals(number).name
    except ValueError:
        low, high = int(signal.SIGRTMIN), int(signal.SIGRTMAX)
        return f"SIGRTMIN+{number - low}" if low <= number <= high else f"signal {number}"


def command_argv(command_line: str, name: str) -> list[str]:
    """A program controller's command line split as a shell would (no shell runs it);
    ControllerError, naming the controller, where it does not split (an unterminated quote),
    holds a NUL (no program can be given one), or names no program."""
    if "\0" in command_line:
        raise ControllerError(f"controller {name}: its command line holds a NUL character")
    try:
        argv = shlex.split(command_line)
    except ValueError as e:
        raise ControllerError(f"controller {name}: its command line does not parse: {e}") from None
    if not argv:
        raise ControllerError(f"controller {name}: no program given")
    return argv


def program_path(argv: list[str], name: str) -> str:
    """The program ``argv`` starts, resolved as exec would; ControllerError if there is none."""
    program = argv[0]
    found = shutil.which(program) if os.sep not in program else program
    if found is None or not os.path.isfile(found) or not os.access(found, os.X_OK):
        where = "on PATH" if os.sep not in program else "as an executable file"
        raise ControllerError(f"controller {name} could not start: no program `{program}` {where}")
    return found


def current_cpu() -> int | None:
    """The CPU this thread runs on now (Linux's /proc), None where that cannot be read."""
    try:
        with open("/proc/thread-self/stat", "rb") as stat:
            # Field 39, counted after the command name (which may hold spaces) ends at ')'.
            return int(stat.read().rpartition(b")")[2].split()[36])
    except (OSError, ValueError, IndexError):
        return None


def pin_to_one_core(cpu: int | None = None) -> set[int] | None:
    """Pin this thread to one CPU (``cpu``, else the one it runs on), so that a program it
    starts, which inherits the pinning, shares its core. In lockstep the two never compute at
    once, and a reply that crosses cores waits for the other core to wake: a pipe round trip
    took 145 µs across the two cores of a virtual machine and 11 µs on one. Threads started
    while it is pinned inherit the pinning, so a caller makes its core run (which starts the
    core's thread pool) before it starts a program. Returns the affinity to restore, None if
    nothing changed (already on one CPU, or not Linux)."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = os.sched_getaffinity(0)
    if len(allowed) <= 1:
        return None
    chosen = cpu if cpu in allowed else current_cpu()
    os.sched_setaffinity(0, {chosen if chosen in allowed else min(allowed)})
    return allowed


class ProcessController(UserController):
    """A program in lockstep over stdin/stdout, one JSON object per line each way.

    The program starts in a session (and process group) of its own, so that the terminal's
    Ctrl-C reaches sitgen only and its children can be killed with it; when the run ends the
    whole group is killed. Every read and write has a deadline: a program that stops reading,
    stops writing or closes its output while it runs on cannot hang the run."""

    def __init__(
        self,
        argv: list[str],
        name: str,
        step_timeout_s: float = STEP_TIMEOUT_S,
        start_timeout_s: float = START_TIMEOUT_S,
        host: bool = False,
    ) -> None:
        self.name = name
        if not argv:
            raise ControllerError(f"controller {name}: no program given")
        self._argv = [program_path(argv, name), *argv[1:]]
        self._host = host
        self._step_timeout_s = step_timeout_s
        self._start_timeout_s = start_timeout_s
        self._proc: subprocess.Popen[bytes] | None = None
        self._mark = ""
        self._failed = False
        self._buffer = b""
        # The program's stderr is a pipe drained whenever sitgen waits on the program (so it
        # never fills and hangs it), of which only the tail is kept, to quote when it dies.
        self._stderr_tail = bytearray()
        self._selector = selectors.DefaultSelector()
        self._unpinned: set[int] | None = None

    def reset(self, info: dict[str, Any]) -> None:
        if self._proc is None:
            self._start()
        self._exchange({"type": "reset", **info}, self._start_timeout_s, "on reset")

    def load(self) -> None:
        """Start the program; a Python host is also asked to load its class."""
        self._start()
        if self._host:
            self._exchange({"type": "probe"}, self._start_timeout_s, "on start")

    def _start(self) -> None:
        self._unpinned = pin_to_one_core()
        env, self._mark = marked_env()
        try:
            self._proc = subprocess.Popen(
                [*die_with_parent_prefix(), *self._argv],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                start_new_session=True,
                env=env,
            )
        except OSError as e:
            raise ControllerError(f"controller {self.name} could not start: {e}") from e
        proc = self._proc
        assert proc.stdout is not None and proc.stdin is not None and proc.stderr is not None
        for pipe in (proc.stdout, proc.stdin, proc.stderr):
            os.set_blocking(pipe.fileno(), False)
        self._selector.register(proc.stdout, selectors.EVENT_READ)
        self._selector.register(proc.stderr, selectors.EVENT_READ)

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
        return self._command(self._exchange(message, self._step_timeout_s, when), when)

    def drive(self, core: _core.Run) -> None:
        # The core writes each observation line (sitgen_core::run::protocol) and calls back
        # here only for the exchange: the step loop stays out of Python.
        timeout_s = self._step_timeout_s

        def act(line: bytes, time_s: float) -> tuple[float, float]:
            when = f"at {time_s:.1f} s"
            return self._command(self._exchange(line, timeout_s, when), when)

        core.drive(act, None, True)

    def _command(self, reply: dict[str, Any], when: str) -> tuple[float, float]:
        v, omega = reply.get("v"), reply.get("omega")
        if not all(isinstance(x, int | float) and not isinstance(x, bool) for x in (v, omega)):
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: expected "
                f'{{"v": number, "omega": number}}, got {short(json.dumps(reply))}'
            )
        return float(v), float(omega)  # type: ignore[arg-type]

    def _exchange(
        self, message: dict[str, Any] | bytes, timeout_s: float, when: str
    ) -> dict[str, Any]:
        """Send ``message`` (a dict, or a line already written) and read the reply."""
        # Until the reply is in, the program counts as failed: close() then kills it at once
        # instead of waiting for it to end by itself.
        self._failed = True
        reply = self._converse(message, timeout_s, when)
        self._failed = False
        return reply

    def _converse(
        self, message: dict[str, Any] | bytes, timeout_s: float, when: str
    ) -> dict[str, Any]:
        start = time.monotonic()
        line = message if isinstance(message, bytes) else json.dumps(message).encode() + b"\n"
        self._write(line, start + backstop_s(timeout_s), when)
        line = self._read_line(start, timeout_s, when)
        try:
            reply = json.loads(line)
        except ValueError:
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: not JSON: "
                f"{short(line.decode(errors='replace'))}"
            ) from None
        if not isinstance(reply, dict):
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: expected a JSON "
                f"object, got {short(line.decode(errors='replace'))}"
            )
        if self._host and isinstance(reply.get("error"), str):
            raise ControllerError(f"controller {self.name} {reply['error']}")
        return reply

    def _write(self, data: bytes, deadline: float, when: str) -> None:
        proc = self._proc
        assert proc is not None and proc.stdin is not None
        fd = proc.stdin.fileno()
        # A line fits the pipe's buffer unless the program has stopped reading: write it at
        # once, and wait for room only for what is left.
        try:
            data = data[os.write(fd, data) :]
        except BlockingIOError:
            pass
        except OSError:
            raise ControllerError(self._died(when)) from None
        if not data:
            return
        with selectors.DefaultSelector() as writable:
            writable.register(fd, selectors.EVENT_WRITE)
            assert proc.stderr is not None
            writable.register(proc.stderr, selectors.EVENT_READ)
            while data:
                left = deadline - time.monotonic()
                ready = writable.select(left) if left > 0 else []
                if not ready:
                    raise ControllerError(self._stuck("stopped reading its input", when))
                if any(key.fileobj is proc.stderr for key, _ in ready) and not self._drain_stderr():
                    writable.unregister(proc.stderr)
                if not any(key.fd == fd for key, _ in ready):
                    continue
                try:
                    data = data[os.write(fd, data) :]
                except BlockingIOError:
                    continue
                except OSError:
                    raise ControllerError(self._died(when)) from None

    def _read_line(self, start: float, timeout_s: float, when: str) -> bytes:
        """The program's next line. Its deadline counts the program's processor time from
        ``start`` (``timeout_s`` of it), read only once a step timeout of wall clock has passed
        (a program that computes for less wall time cannot have used more, unless threaded, and
        the common step costs no read); a wall-clock backstop ends one that waits."""
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        if b"\n" not in self._buffer:
            # On one core in lockstep the program has usually answered while sitgen wrote to it:
            # take the reply without waiting (a program that has not is waited for below).
            try:
                chunk = os.read(proc.stdout.fileno(), 1 << 16)
            except BlockingIOError:
                chunk = None
            if chunk == b"":
                raise ControllerError(self._died(when))
            self._buffer += chunk or b""
        backstop = start + backstop_s(timeout_s)
        look_at, cpu_start = start + timeout_s, None
        # Its processor time is read only for a reply not in after a short wait (most come
        # sooner, and the read costs more than a quick step); what it used before the read is
        # at most that wait, which the deadline then grants it over.
        counted_from = start + min(CPU_COUNTED_AFTER_S, timeout_s / 10)
        window: tuple[float, float, float] | None = None
        stopped_since: float | None = None
        while b"\n" not in self._buffer:
            if len(self._buffer) > MAX_REPLY_BYTES:
                raise ControllerError(
                    f"controller {self.name} sent a malformed reply {when}: a line longer than "
                    f"{MAX_REPLY_BYTES} bytes"
                )
            now = time.monotonic()
            if cpu_start is None and now >= counted_from:
                cpu_start = cpu_seconds([proc.pid])
            if now >= look_at and cpu_start is not None:
                if cpu_seconds([proc.pid]) - cpu_start >= timeout_s:
                    raise ControllerError(
                        self._stuck("", when) or computing_too_long(self.name, timeout_s, when)
                    )
                if window is None:
                    window = (now, *schedstat_seconds(self._pids()))
                # A program stopped (SIGSTOP, a debugger) neither computes nor waits: the time
                # it is seen stopped is added to its backstop, as sitgen's own pauses are.
                if task_state(f"/proc/{proc.pid}/stat") in STOPPED:
                    stopped_since = now if stopped_since is None else stopped_since
                elif stopped_since is not None:
                    backstop += now - stopped_since
                    stopped_since = None
                look_at = now + CPU_LOOK_S
            if now >= backstop:
                if stopped_since is not None:
                    raise stopped_reason(self.name, now - stopped_since, when)
                raise self._overdue(backstop_s(timeout_s), window, when)
            asked = min(look_at, backstop) if cpu_start is not None else counted_from
            ready = self._selector.select(max(0.0, asked - now))
            late = time.monotonic() - asked
            if late > PAUSED_S:
                backstop += late
            if any(key.fileobj is proc.stderr for key, _ in ready):
                self._drain_stderr()
            if not any(key.fileobj is proc.stdout for key, _ in ready):
                continue
            try:
                chunk = os.read(proc.stdout.fileno(), 1 << 16)
            except BlockingIOError:
                continue
            if not chunk:
                raise ControllerError(self._died(when))
            self._buffer += chunk
        line, _, self._buffer = self._buffer.partition(b"\n")
        if len(line) > MAX_REPLY_BYTES:
            raise ControllerError(
                f"controller {self.name} sent a malformed reply {when}: a line longer than "
                f"{MAX_REPLY_BYTES} bytes"
            )
        return line.strip()

    def _drain_stderr(self, most: int = 1 << 22) -> bool:
        """Read what the program has written to stderr (up to ``most`` bytes at a time, so a
        flood cannot hold sitgen here), keeping only the tail; False once it is closed."""
        proc = self._proc
        if proc is None or proc.stderr is None:
            return False
        fd = proc.stderr.fileno()
        read = 0
        while read < most:
            try:
                chunk = os.read(fd, 1 << 16)
            except BlockingIOError:
                return True
            except OSError:
                chunk = b""
            if not chunk:
                with contextlib.suppress(KeyError, ValueError):
                    self._selector.unregister(proc.stderr)
                return False
            read += len(chunk)
            self._stderr_tail += chunk
            del self._stderr_tail[:-STDERR_TAIL_BYTES]
        return True

    def _stuck(self, how: str, when: str) -> str:
        """Why a deadline passed: the program died, or it runs on and ``how``."""
        assert self._proc is not None
        if self._proc.poll() is not None:
            return self._died(when)
        return f"controller {self.name} {how} {when}" if how else ""

    def _pids(self) -> set[int]:
        assert self._proc is not None
        return {self._proc.pid, *marked_pids(self._mark)}

    def _overdue(
        self, wall_s: float, window: tuple[float, float, float] | None, when: str
    ) -> ControllerError:
        """The error of a program that has not replied by its backstop: it died; the machine
        starved it (its threads' schedstat since its step timeout of wall clock, ``window``:
        when, running and queued seconds then); it computes (threads or children of its own
        used the time); or it waits — for a program most often on a reply left in its output
        buffer, the commonest way one hangs in lockstep."""
        died = self._stuck("", when)
        if died:
            return ControllerError(died)
        if window is not None:
            running, queued = schedstat_seconds(self._pids())
            elapsed = time.monotonic() - window[0]
            used, waited = running - window[1], queued - window[2]
            if starved(elapsed, used, waited):
                return starved_reason(self.name, wall_s, when)
            if used >= BUSY_SHARE * elapsed:
                return ControllerError(did_not_reply(self.name, f"{wall_s:g} s", when, COMPUTING))
        hint = WAITING_ON_ITS_OWN if self._host else WAITING_ON_OUTPUT
        return ControllerError(did_not_reply(self.name, f"{wall_s:g} s", when, hint))

    def _died(self, when: str) -> str:
        """Why the program stopped answering: its exit code, or that it closed its output and
        runs on (it is killed when the run closes it)."""
        assert self._proc is not None
        try:
            code = self._proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            code = None
        self._drain_stderr()
        tail = self._stderr_tail.decode(errors="replace").strip().splitlines()
        said = f": {short(tail[-1])}" if tail else ""
        if code is None:
            how = "closed its output"
        elif code < 0:
            how = f"was killed by {signal_name(-code)}"
        else:
            how = f"exited with code {code}"
        return f"controller {self.name} {how} {when}{said}"

    def close(self) -> str | None:
        proc = self._proc
        unclean = None
        if proc is not None:
            try:
                if not self._failed and proc.poll() is None and proc.stdin is not None:
                    proc.stdin.write(b'{"type": "end"}\n')
                    proc.stdin.close()
                    code = proc.wait(timeout=END_TIMEOUT_S)
                    if code != 0:
                        unclean = f"exited with code {code} on `end`"
            except subprocess.TimeoutExpired:
                unclean = f"did not exit within {END_TIMEOUT_S:g} s of `end` and was killed"
            except (OSError, ValueError):
                unclean = "closed its input before `end`"
            # The whole group: the program and anything it started, and anything that left it.
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            kill_marked(self._mark)
            proc.wait()
            self._selector.close()
            for pipe in (proc.stdin, proc.stdout, proc.stderr):
                if pipe is not None:
                    with contextlib.suppress(OSError):
                        pipe.close()
        self._proc = None
        if self._unpinned is not None:
            os.sched_setaffinity(0, self._unpinned)
            self._unpinned = None
        return unclean


def short(text: str) -> str:
    return repr(text if len(text) <= 80 else text[:77] + "...")
