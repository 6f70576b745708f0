#!/usr/bin/env python3
"""A ``cmd:`` program with a trivial reply: ready on reset, one constant command a line
otherwise, no parsing. Its own cost is reading and writing a line, which ``make bench`` times
by feeding it lines without waiting for the replies."""

from __future__ import annotations

import sys


def main() -> None:
    out = sys.stdout
    for line in sys.stdin:
        kind = line[10:21]  # after '{"type": "'
        if kind.startswith("end"):
            break
        out.write('{"v": 0.3, "omega": 0.1}\n' if kind == "observation" else '{"ready": true}\n')
        out.flush()


if __name__ == "__main__":
    main()
