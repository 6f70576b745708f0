"""A controller's deadlines, and the errors a run ends with when one passes: the same words
on every path a controller takes (in process, a host process, a program).

What it does: names a step's deadline (:data:`STEP_TIMEOUT_S` of processor time) and its
wall-clock backstop (:func:`backstop_s`), words a controller that computed too long
(:func:`computing_too_long`) or waited too long (:func:`waiting_too_long`), and tells a call
the machine starved of a core (:func:`starved`) from one that waited on its own: that is the
machine's error (:class:`MachineError`), which ``sitgen.run`` makes again and never stores as
the controller's failure.

Why: wall clock measures the machine, not the controller. A loaded machine slows a controller
down without changing what it computes; counting its processor time keeps a verdict the same
under load, and a generous backstop still ends a controller that waits for ever.

Parameters: :data:`STEP_TIMEOUT_S` (s of CPU, default 1), :data:`BACKSTOP_FACTOR` (10),
:data:`MOST_BACKSTOP_OVER_S` (20 s), :data:`LEAST_BACKSTOP_S` (2 s), :data:`MACHINE_RETRIES`
(3); a run spec's ``[run.controller] step_timeout_s`` overrides the first.

Source: docs/controller-protocol.md, "Deadlines"; Linux's schedstat (running and run-queue
time of a thread, proc(5)).
"""

from __future__ import annotations

from sitgen.controllers.proc_tasks import BUSY_SHARE

STEP_TIMEOUT_S = 1.0
"""Default processor time (seconds of CPU) a controller may spend answering one observation:
its step deadline counts its own work, so that a loaded machine, which slows a controller down
without changing what it computes, cannot change a verdict (docs/controller-protocol.md,
"Deadlines")."""
BACKSTOP_FACTOR = 10.0
"""A controller that waits (a sleep, a lock, input of its own) spends no processor time: the
wall-clock backstop that ends it is this many step deadlines, at most :data:`MOST_BACKSTOP_OVER_S`
past the deadline and at least :data:`LEAST_BACKSTOP_S`."""
MOST_BACKSTOP_OVER_S = 20.0
LEAST_BACKSTOP_S = 2.0


class ControllerError(Exception):
    """A controller failed: the message is one line saying how and when."""


class MachineError(ControllerError):
    """The machine, not the controller, failed the run: a controller starved of a core past
    its backstop, a worker lost. The run is made again; it is never stored as the controller's
    failure (``sitgen.run`` gives up after :data:`MACHINE_RETRIES` and says so)."""


MACHINE_RETRIES = 3
"""How often a run the machine failed is made again before its error is stored (with a reason
that says the machine failed it, which triage does not count as the controller's)."""

MACHINE_PREFIX = "the machine "
"""How the stored reason of a run the machine failed begins (triage leaves such runs out)."""


def backstop_s(step_timeout_s: float) -> float:
    """The wall-clock backstop of a call whose processor-time deadline is ``step_timeout_s``
    (10 s for the default 1 s, 30 s for a reset's 10 s)."""
    generous = min(BACKSTOP_FACTOR * step_timeout_s, step_timeout_s + MOST_BACKSTOP_OVER_S)
    return max(generous, LEAST_BACKSTOP_S)


def did_not_reply(name: str, within: str, when: str, hint: str) -> str:
    """Why a controller that did not reply in time failed, the same words on every path:
    ``within`` (``1 s of processor time``, ``10 s``) and what it was doing (``hint``)."""
    return f"controller {name} did not reply within {within} {when}; it is {hint}"


def computing_too_long(name: str, cpu_s: float, when: str) -> str:
    """Why a controller that used up its processor time failed."""
    return did_not_reply(name, f"{cpu_s:g} s of processor time", when, COMPUTING)


COMPUTING = "computing, not waiting for input: a loop that does not end?"
"""What a controller past its deadline that used the time was doing."""
WAITING_ON_ITS_OWN = "waiting, not computing: on a sleep, a lock or input of its own?"
"""What a class that waits past its backstop waits on (a program's is :data:`WAITING_ON_OUTPUT`)."""
WAITING_ON_OUTPUT = (
    "waiting, not computing: a reply left in its output buffer? (flush after every reply: "
    "docs/controller-protocol.md)"
)


def starved(wall_s: float, running_s: float, queued_s: float) -> bool:
    """Whether a call that has not returned after ``wall_s`` was kept from a core by the
    machine: runnable for a good share of the time (:data:`BUSY_SHARE`), and more of it waiting
    on a run queue than running."""
    return (running_s + queued_s) >= BUSY_SHARE * wall_s and queued_s >= running_s


def starved_reason(name: str, wall_s: float, when: str) -> MachineError:
    """The machine's error for a controller starved of a core past its backstop."""
    return MachineError(
        f"{MACHINE_PREFIX}starved controller {name} of processor time {when}: runnable but not "
        f"run for most of {wall_s:g} s (a loaded or paused machine); not the controller's failure"
    )


def stopped_reason(name: str, stopped_s: float, when: str) -> MachineError:
    """The machine's error for a controller stopped (SIGSTOP, a debugger) at its backstop,
    ``stopped_s`` seconds so far."""
    return MachineError(
        f"{MACHINE_PREFIX}found controller {name} stopped {when}, for {stopped_s:.1f} s so far "
        "(SIGSTOP or a debugger: neither computing nor waiting); not the controller's failure"
    )
