"""A DDS domain for each sitgen process that runs ROS 2 nodes, so that two sitgen processes on
one machine (two campaigns, a campaign's pool workers) never hear each other's nodes.

What it does: :func:`process_domain` claims, on first use, a domain id of :data:`DOMAIN_IDS`
that no other sitgen process holds — an exclusive ``flock`` on a lock file per domain in the
shared temporary folder — and holds it until the process exits (a forked pool worker claims
its own). The lock files are opened without following a link or waiting on a special file: the
folder is shared, so a symlink or FIFO planted there must neither have its target truncated nor
block sitgen; a domain whose lock path holds anything but a regular file is passed over.

Parameters: :data:`DOMAIN_IDS`, 1–101.

Source: the ROS 2 domain id and its UDP port mapping (design.ros2.org, "ROS_DOMAIN_ID").
"""

from __future__ import annotations

import fcntl
import os
import stat
import tempfile
from typing import IO

from sitgen.controllers.external import ControllerError

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


def process_domain() -> int:
    """This process's DDS domain id, claimed on first use and held until it exits."""
    if os.getpid() not in _claimed:
        _claimed[os.getpid()] = _claim_domain()
    return _claimed[os.getpid()][0]
