#!/usr/bin/env python3
"""The `Cautious` controller as a separate program speaking sitgen's line protocol.

Any language works the same way: read one JSON object per line on stdin, write one JSON object
per line on stdout, flush after each (docs/controller-protocol.md).

Run it:   sitgen run situation.json --controller 'cmd:python3 examples/controllers/cautious_cmd.py'
Check it: sitgen check-controller 'cmd:python3 examples/controllers/cautious_cmd.py'

It uses only the standard library, so it shows everything a program has to do.
"""

import json
import math
import sys


def main() -> None:
    waypoints: list[list[float]] = []
    angles: list[float] = []
    next_index = 0
    for line in sys.stdin:
        message = json.loads(line)
        if message["type"] == "reset":
            # The route, body, laser (with its beam angles) and limits, once per run.
            waypoints = message["waypoints"]
            angles = message["laser"]["angles"]
            next_index = 0
            reply = {"ready": True}
        elif message["type"] == "observation":
            x, y, heading = message["pose"]
            while next_index < len(waypoints) and math.dist(waypoints[next_index], (x, y)) <= 0.5:
                next_index += 1
            if next_index == len(waypoints):
                reply = {"v": 0.0, "omega": 0.0}
            else:
                gx, gy = waypoints[next_index]
                error = math.remainder(math.atan2(gy - y, gx - x) - heading, math.tau)
                ahead = [
                    r
                    for r, a in zip(message["ranges"], angles, strict=True)
                    if abs(a) < math.radians(30)
                ]
                slow = min(1.0, max(0.0, (min(ahead, default=10.0) - 0.6) / 1.5))
                v = 0.5 * slow * max(0.0, math.cos(error)) if abs(error) < 0.8 else 0.0
                reply = {"v": v, "omega": 1.5 * error}
        else:  # "end": the run is over
            break
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
