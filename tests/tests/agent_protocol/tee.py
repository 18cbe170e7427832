"""Runs an agent program and relays the step protocol to it line by line,
logging each message (`to_agent`, `to_harness`) as JSON lines to
LOG_DIR/<pid>.jsonl, so the test can check both sides against the schemas."""

import json
import os
import subprocess
import sys

log_dir, argv = sys.argv[1], sys.argv[2:]
log = open(os.path.join(log_dir, f"{os.getpid()}.jsonl"), "a")
child = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE)


def note(direction, line):
    log.write(json.dumps({"dir": direction, "line": line.rstrip("\n")}) + "\n")
    log.flush()


for line in sys.stdin:
    note("to_agent", line)
    child.stdin.write(line.encode())
    child.stdin.flush()
    answer = child.stdout.readline()
    if not answer:
        break
    note("to_harness", answer.decode())
    sys.stdout.write(answer.decode())
    sys.stdout.flush()
sys.exit(child.wait())
