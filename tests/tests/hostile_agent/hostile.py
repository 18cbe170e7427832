"""An outside agent for the hostile-agent tests, speaking the step protocol on
stdin/stdout by hand (no package): it behaves on every task but the victim,
where it misbehaves as its first argument says.

  actions N   answers one act of N typed actions
  long N      answers one act of N typed actions (each followed by the run's pause)
  lines MB    writes MB MiB of 100 KB stderr lines, then behaves
  raw MB      writes MB MiB of stderr with no newline, then behaves
  children    starts a child and a grandchild in a new session, then behaves

Each mode writes its marker file (second argument) once it has answered the
victim's first observe, so the test knows the act has started; `children`
writes the pids it started, one a line."""

import json
import os
import subprocess
import sys

VICTIM = "stub-notepad-append"
mode, arg = sys.argv[1], sys.argv[2]
marker = sys.argv[3] if len(sys.argv) > 3 else None


def send(message):
    sys.stdout.write(json.dumps(message) + "\n")
    sys.stdout.flush()


def mark(text=""):
    if marker:
        with open(marker + ".tmp", "w") as f:
            f.write(text)
        os.replace(marker + ".tmp", marker)


task = None
seen = 0
for line in sys.stdin:
    message = json.loads(line)
    kind = message["type"]
    if kind == "hello":
        send({"type": "hello", "protocol": 1, "action_space": "typed"})
    elif kind == "reset":
        task, seen = message["task_name"], 0
        send({"type": "ready"})
    elif kind == "observe":
        seen += 1
        if task != VICTIM or seen > 1:
            send({"type": "act", "decision": "DONE"})
            continue
        if mode in ("actions", "long"):
            n = int(arg)
            send({"type": "act", "actions": [{"type": "key_press", "key": "a"}] * n})
            mark()
            continue
        if mode in ("lines", "raw"):
            total = int(arg) << 20
            chunk = ("x" * 100_000 + "\n") if mode == "lines" else "y" * 100_000
            written = 0
            while written < total:
                sys.stderr.write(chunk)
                written += len(chunk)
            sys.stderr.flush()
        if mode == "children":
            plain = subprocess.Popen(["sleep", "1000"])
            session = subprocess.Popen(
                [sys.executable, "-c", "import subprocess, sys, time\n"
                 "p = subprocess.Popen(['sleep', '1000'])\n"
                 "print(p.pid, flush=True)\n"
                 "time.sleep(1000)"],
                start_new_session=True, stdout=subprocess.PIPE, text=True)
            grandchild = session.stdout.readline().strip()
            mark(f"{plain.pid}\n{session.pid}\n{grandchild}\n")
        send({"type": "act", "decision": "DONE"})
        if mode in ("lines", "raw"):
            mark()
