#!/usr/bin/env python3
"""The route follower (follower.py) as a ``cmd:`` program on sitgen's JSON-lines protocol: the
same logic as the ROS 2 node, without DDS, for ``make bench`` to time the two side by side.

Run it:  sitgen run situation.json --controller 'cmd:python3 examples/ros2/follower_cmd.py'
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from follower import Follower


def main() -> None:
    follower = Follower()
    angle_min = angle_increment = 0.0
    for line in sys.stdin:
        message = json.loads(line)
        if message["type"] == "reset":
            follower.follow(message["waypoints"])
            angles = message["laser"]["angles"]
            angle_min = angles[0]
            angle_increment = (angles[-1] - angles[0]) / max(1, len(angles) - 1)
            reply = {"ready": True}
        elif message["type"] == "observation":
            ranges = message["ranges"]
            v, omega = follower.command(message["pose"], ranges, angle_min, angle_increment)
            reply = {"v": v, "omega": omega}
        else:
            break
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
