#!/usr/bin/env python3
"""Sends one QMP command to a QEMU monitor socket and prints the reply's "return" as JSON.

Usage: qmp.py SOCKET COMMAND [ARGUMENTS_JSON]
       qmp.py SOCKET hmp 'savevm ready'      (human-monitor-command shorthand)

Exits 1 with the error on stderr when QEMU answers with an error. Standard library only;
used by scripts/standin/check.sh.
"""

import json
import socket
import sys


def main() -> int:
    if len(sys.argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    path, command = sys.argv[1], sys.argv[2]
    if command == "hmp":
        arguments = {"command-line": sys.argv[3]}
        command = "human-monitor-command"
    else:
        arguments = json.loads(sys.argv[3]) if len(sys.argv) > 3 else {}
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(600)
    sock.connect(path)
    stream = sock.makefile("rw")

    def reply() -> dict:
        # Events (asynchronous messages) can come before the answer: skip them.
        while True:
            line = stream.readline()
            if not line:
                raise SystemExit("QEMU closed the monitor")
            message = json.loads(line)
            if "event" not in message:
                return message

    reply()  # the greeting
    for request in ({"execute": "qmp_capabilities"}, {"execute": command, "arguments": arguments}):
        stream.write(json.dumps(request) + "\n")
        stream.flush()
        answer = reply()
        if "error" in answer:
            print(f"{request['execute']}: {answer['error']}", file=sys.stderr)
            return 1
    result = answer.get("return")
    # human-monitor-command returns the monitor's text, which is empty on success.
    if isinstance(result, str):
        if result.strip():
            print(result.strip(), file=sys.stderr)
            if "rror" in result:
                return 1
    else:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
