"""A DDS domain for each sitgen process that runs ROS 2 nodes, so that two sitgen processes on
one machine (two campaigns, a campaign's pool workers) never hear each other's nodes.

What it does: :func:`process_domain` claims, on first use, a domain id of :data:`DOMAIN_IDS`
that no other sitgen process holds — an exclusive ``flock`` on a lock file per domain in the
shared temporary folder — and holds it until the process exits (a forked pool worker claims
its own). The lock files are opened without following a link or waiting on a special file: the
folder is shared, so a symlink or FIFO planted there must neither have its target truncated nor
block sitgen; a domain whose lock path holds anything but a regular file is passed over.

:func:`confine` holds every participant sitgen creates, its own and the nodes', to this
machine: for Fast DDS, the profile ``fastdds_loopback.xml`` beside this file — UDP on
127.0.0.1 only, every socket a participant reads bound there, discovery's multicast group
joined on the loopback interface only, and no shared-memory transport, whose segments a
killed node would leave in /dev/shm; for another rmw, or where the user names a Fast DDS
profile of their own (``FASTDDS_DEFAULT_PROFILES_FILE``), rmw's localhost-only discovery
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``). Static peers are dropped either way.
:func:`rmw_problem` refuses an ``RMW_IMPLEMENTATION`` that is not installed, which rcl would
report only by ending the process with code 102. :func:`require_free` proves, as a run starts,
that no process it did not start talks on its topics (a node some other program left on the
domain would answer the run as well); where one does, the run errs and the domain is passed
over.

Parameters: :data:`DOMAIN_IDS`, 1–101.

Source: the ROS 2 domain id and its UDP port mapping (design.ros2.org, "ROS_DOMAIN_ID");
Fast DDS's XML profiles (transport descriptors, ``interfaceWhiteList``).
"""

from __future__ import annotations

import fcntl
import os
import stat
import tempfile
from collections.abc import Iterable, Mapping, MutableMapping
from pathlib import Path
from typing import IO

from sitgen.controllers.deadlines import ControllerError

DOMAIN_IDS = range(1, 102)
"""DDS domains sitgen may claim: 0 is left to the user's own ROS system; above 101 the
ports of a domain start to collide with Linux's ephemeral range."""


def _open_lock(path: str) -> IO[bytes] | None:
    """The lock file at ``path``, opened for locking without following a link or waiting on a
    special file (the folder is shared: anyone may have put something there); None where what
    is there is not a regular file, so the domain it stands for is passed over."""
    try:
        fd = os.open(
            path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o600
        )
    except OSError:
        return None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        return None
    return os.fdopen(fd, "r+b")


def _claim_domain() -> tuple[int, IO[bytes]]:
    """A DDS domain id no other sitgen process on this machine holds, and the open lock file
    that holds it for this process's life."""
    folder = tempfile.gettempdir()
    start = os.getpid() % len(DOMAIN_IDS)
    for k in range(len(DOMAIN_IDS)):
        domain = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
        lock = _open_lock(os.path.join(folder, f"sitgen-ros2-domain-{domain}.lock"))
        if lock is None:
            continue
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return domain, lock
    raise ControllerError(
        f"ros2: every DDS domain {DOMAIN_IDS.start}-{DOMAIN_IDS.stop - 1} is held by another "
        f"sitgen process (or its lock file in {folder} is not a regular file)"
    )


_claimed: dict[int, tuple[int, IO[bytes]]] = {}
"""The domain this process holds, by pid (a forked pool worker claims its own)."""

_passed_over: list[IO[bytes]] = []
"""Locks of domains found not free (:func:`pass_over_domain`), held so that no sitgen process
claims them while this one lives."""


def process_domain() -> int:
    """This process's DDS domain id, claimed on first use and held until it exits."""
    if os.getpid() not in _claimed:
        _claimed[os.getpid()] = _claim_domain()
    return _claimed[os.getpid()][0]


def pass_over_domain() -> None:
    """Give up this process's domain for the next run (another is claimed then), keeping its
    lock: a domain some other program talks on is no sitgen process's to use."""
    claim = _claimed.pop(os.getpid(), None)
    if claim is not None:
        _passed_over.append(claim[1])


EPROSIMA_VENDOR = b"\x01\x0f"
"""The vendor id that opens a Fast DDS GUID: its next two bytes are the host's, the two after
them the low 16 bits of the participant's process id (little-endian)."""


def foreign_processes(gids: Iterable[bytes], ours: set[int]) -> set[int]:
    """The live processes, other than ``ours``, whose Fast DDS participants own endpoints of
    ``gids`` (a run's topics): proof that the domain is not free. Another rmw's GUIDs say
    nothing of their process, nor does an endpoint whose process has gone (the graph lists
    it a while longer: it answers nothing), and a process's id is known to 16 bits, so
    this finds participants of this machine's processes, not every one."""
    low = {pid & 0xFFFF for pid in ours}
    owners = {int.from_bytes(g[4:6], "little") for g in gids if g[:2] == EPROSIMA_VENDOR} - low
    if not owners:
        return set()
    live = {int(e) for e in os.listdir("/proc") if e.isdigit()}
    return {pid for pid in live - ours if pid & 0xFFFF in owners}


LOOPBACK_PROFILE = Path(__file__).with_name("fastdds_loopback.xml")
"""Fast DDS's profile for sitgen's participants: UDP on 127.0.0.1, no shared memory."""

DEFAULT_RMW = "rmw_fastrtps_cpp"


FAST_DDS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")


def confine(env: MutableMapping[str, str]) -> None:
    """Hold a participant that starts with ``env`` to this machine (``os.environ`` for
    sitgen's own, which rcl reads at init; a node's environment for the node).

    With Fast DDS and no profile of the user's, the loopback profile does it (discovery's
    multicast group is then joined on the loopback interface only); rmw's own
    ``LOCALHOST`` range is not asked for there, as it opens sockets on every interface
    besides. Otherwise (another rmw, or the user's profile) the ``LOCALHOST`` range does."""
    env.pop("ROS_STATIC_PEERS", None)
    env.setdefault("RMW_IMPLEMENTATION", DEFAULT_RMW)
    users_profile = env.get("FASTDDS_DEFAULT_PROFILES_FILE")
    if env["RMW_IMPLEMENTATION"] in FAST_DDS_RMWS and (
        not users_profile or users_profile == str(LOOPBACK_PROFILE)
    ):
        env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(LOOPBACK_PROFILE)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    else:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


def unconfined(env: Mapping[str, str]) -> str | None:
    """Why a run with ``env`` may be heard from the network, or None where sitgen confines it
    (:func:`confine`): a user's own Fast DDS profile is kept as it is, and Fast DDS then listens
    on the interfaces that profile says (every one, by default), whatever the discovery range."""
    rmw = env.get("RMW_IMPLEMENTATION", DEFAULT_RMW)
    profile = env.get("FASTDDS_DEFAULT_PROFILES_FILE")
    if rmw in FAST_DDS_RMWS and profile and profile != str(LOOPBACK_PROFILE):
        return (
            f"with your Fast DDS profile ({profile}) sitgen's participant and the node listen "
            "where it says (every interface, unless it names one): the run is not confined to "
            "this machine; unset FASTDDS_DEFAULT_PROFILES_FILE to confine it"
        )
    return None


def rmw_problem(env: MutableMapping[str, str], lib_dirs: list[str]) -> str | None:
    """Why ``env``'s ``RMW_IMPLEMENTATION`` cannot be loaded (rcl loads
    ``lib<name>.so`` from the library path), or None."""
    name = env.get("RMW_IMPLEMENTATION", DEFAULT_RMW)
    if not name or "/" in name or not name.isprintable():
        return f"RMW_IMPLEMENTATION={name!r} is not the name of an rmw implementation"
    search = [*lib_dirs, *env.get("LD_LIBRARY_PATH", "").split(os.pathsep)]
    if any(d and os.path.isfile(os.path.join(d, f"lib{name}.so")) for d in search):
        return None
    return (
        f"RMW_IMPLEMENTATION={name} is not installed (no lib{name}.so on the library path; "
        f"pip install ros-kilted-{name.replace('_', '-')}, or unset it for {DEFAULT_RMW})"
    )


def require_free(domain: int, gids: Iterable[bytes], ours: set[int]) -> None:
    """Raise ControllerError where another process's participant owns one of ``gids`` (a run's
    endpoints on ``domain``): a node left running by anything else would answer the run as
    well, and score it. This process then moves to another domain for its next run."""
    strangers = foreign_processes(gids, ours)
    if strangers:
        pass_over_domain()
        raise ControllerError(
            f"ros2: DDS domain {domain} is not free: process "
            f"{', '.join(map(str, sorted(strangers)))}, which this run did not start, talks on "
            "its topics; the next run moves to another domain"
        )
