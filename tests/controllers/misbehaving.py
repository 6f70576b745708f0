"""A controller program that misbehaves on purpose, as its argument says: `crash` exits after a
few steps, `hang` stops replying, `garbage` replies with text that is not JSON, `noreply` sends
an object without a command, `nan` sends NaN; `sometimes` crashes in runs whose start x is in
an even metre; `closeout` closes its output and runs on; `deaf` stops reading its input and
floods its output; `spawn` starts a child that sleeps, writes its pid to the file named by the
second argument and then hangs; `stderrflood` writes 600 MiB to stderr on reset, then a last
line, and exits; `longline` sends a 2 MiB line with no end and hangs; `ignoreend` drives
well but ignores `end`; `noflush` stops flushing its replies (they wait in its output buffer);
`spin` computes for ever; `stopped` is stopped (SIGSTOP) for 3 s at its fifth step unless the
file named by the second argument exists (which it then makes), as a debugger or a shell's job
control would stop it; `good` drives straight at 0.3 m/s."""

import json
import os
import signal
import subprocess
import sys
import time

mode = sys.argv[1]
buffered = None
for step, line in enumerate(sys.stdin):
    message = json.loads(line)
    if message["type"] == "end":
        if mode == "ignoreend":
            time.sleep(600)
        break
    if message["type"] == "reset":
        if mode == "sometimes" and int(message["start"][0]) % 2 == 0:
            sys.exit(4)
        if mode == "stderrflood":
            block = b"noise " * (1 << 20)
            for _ in range(100):
                sys.stderr.buffer.write(block)
            sys.stderr.buffer.write(b"\nlast words before the crash\n")
            sys.stderr.flush()
            sys.exit(3)
        reply = '{"ready": true}'
    elif step >= 5 and mode == "crash":
        print("simulated failure in the planner", file=sys.stderr)
        sys.exit(3)
    elif step >= 5 and mode == "hang":
        time.sleep(30)
        reply = '{"v": 0, "omega": 0}'
    elif step >= 5 and mode == "spin":
        while True:
            pass
    elif step >= 5 and mode == "noflush":
        # A buffer of its own: sys.stdout is block-buffered on a pipe, but not where the
        # environment sets PYTHONUNBUFFERED.
        buffered = buffered or open(1, "w", buffering=1 << 16, closefd=False)  # noqa: SIM115
        buffered.write('{"v": 0.3, "omega": 0.0}\n')
        continue
    elif step == 5 and mode == "stopped" and not os.path.exists(sys.argv[2]):
        open(sys.argv[2], "w").close()
        subprocess.Popen(["sh", "-c", f"sleep 3; kill -CONT {os.getpid()}"])
        os.kill(os.getpid(), signal.SIGSTOP)
        reply = '{"v": 0.3, "omega": 0.0}'
    elif step >= 5 and mode == "garbage":
        reply = "hello"
    elif step >= 5 and mode == "noreply":
        reply = '{"speed": 1}'
    elif step >= 5 and mode == "nan":
        reply = '{"v": NaN, "omega": 0}'
    elif step >= 5 and mode == "closeout":
        sys.stdout.close()
        os.close(1)
        time.sleep(600)
    elif step >= 5 and mode == "deaf":
        while True:
            sys.stdout.write('{"v": 0.3, "omega": 0.0}\n' * 1000)
            sys.stdout.flush()
    elif step >= 5 and mode == "longline":
        sys.stdout.write("x" * (2 << 20))
        sys.stdout.flush()
        time.sleep(600)
    elif step >= 5 and mode == "spawn":
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
        with open(sys.argv[2], "w") as f:
            f.write(f"{child.pid} {os.getpid()}")
        time.sleep(600)
    else:
        reply = '{"v": 0.3, "omega": 0.0}'
    sys.stdout.write(reply + "\n")
    sys.stdout.flush()
