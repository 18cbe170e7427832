"""The step protocol, version 1: one JSON object a line, one answer per message.

The harness sends ``hello``, then per task ``reset`` and per step ``observe``;
the agent answers ``hello``, ``ready`` and ``act`` (or ``error``). The schemas
are in the repository's ``schemas/agent-protocol/`` folder.
"""

import base64
import json
import sys
import threading
import traceback

PROTOCOL_VERSION = 1
ACTION_SPACES = ("computer", "pyautogui", "computer_13", "typed")
COORDS = ("pixels", "fraction", "grid1000")
DECISIONS = ("DONE", "FAIL", "WAIT")


class ProtocolError(Exception):
    """A message this side cannot handle."""


class Agent:
    """Base class of an agent.

    ``action_space`` names what ``predict`` answers in; ``coords`` (optional:
    ``pixels``, ``fraction`` or ``grid1000``) what the coordinates of its
    pyautogui code and ``computer_13`` actions are measured in, where ``None``
    leaves it to the run's ``--coords``; ``observation`` says
    what each observation should carry (see ``docs/agents.md``): keys
    ``screenshot`` (``path``, ``inline`` or ``none``), ``a11y`` (``xml``,
    ``tree`` or ``none``), ``windows``, ``clipboard`` and ``som`` (booleans).
    """

    name = None
    action_space = "pyautogui"
    coords = None
    observation = {}

    def reset(self, task):
        """Called once per task with the ``reset`` message (``instruction``,
        ``task_id``, ``domain``, ``screen_width``, ``screen_height``...)."""

    def predict(self, obs):
        """Answers the ``observe`` message ``obs``.

        Return a dict with any of ``actions``, ``decision``, ``response``,
        ``record``, ``action_space``, ``computer_update``, ``usage`` (the
        step's model tokens, ``{"input_tokens": N, "output_tokens": N}``); or a list of
        actions; or OSWorld's ``(response, actions)`` pair.
        """
        raise NotImplementedError


def screenshot_bytes(obs):
    """The observation's screenshot as PNG bytes, from its file or inline; None without one."""
    shot = obs.get("screenshot") or {}
    if "path" in shot:
        with open(shot["path"], "rb") as f:
            return f.read()
    if "png_base64" in shot:
        return base64.b64decode(shot["png_base64"])
    return None


def to_act(answer):
    """An ``act`` message from what ``predict`` returned."""
    if isinstance(answer, dict):
        act = {k: v for k, v in answer.items() if v is not None}
    elif isinstance(answer, tuple) and len(answer) == 2:
        act = {"response": answer[0] or "", "actions": list(answer[1] or [])}
    elif isinstance(answer, list):
        act = {"actions": answer}
    elif isinstance(answer, str) and answer in DECISIONS:
        act = {"decision": answer}
    else:
        raise ProtocolError(f"predict returned {type(answer).__name__}; expected a dict, a list or a pair")
    act["type"] = "act"
    if not isinstance(act.get("response", ""), str):
        act["response"] = str(act["response"])
    record = act.get("record")
    if record is not None:
        act["record"] = json.loads(json.dumps(record, default=str))
    return act


class Session:
    """One conversation with the harness: one agent, one task at a time."""

    def __init__(self, agent):
        self.agent = agent

    def hello(self, message):
        if message.get("protocol") != PROTOCOL_VERSION:
            raise ProtocolError(
                f"the harness speaks protocol version {message.get('protocol')}, this agent {PROTOCOL_VERSION}"
            )
        space = getattr(self.agent, "action_space", "pyautogui")
        if space not in ACTION_SPACES:
            raise ProtocolError(f"unknown action space {space!r}; expected one of {', '.join(ACTION_SPACES)}")
        answer = {
            "type": "hello",
            "protocol": PROTOCOL_VERSION,
            "agent": getattr(self.agent, "name", None) or type(self.agent).__name__,
            "action_space": space,
        }
        coords = getattr(self.agent, "coords", None)
        if coords is not None:
            if coords not in COORDS:
                raise ProtocolError(f"unknown coordinate convention {coords!r}; expected one of {', '.join(COORDS)}")
            answer["coords"] = coords
        wants = dict(getattr(self.agent, "observation", None) or {})
        if wants:
            answer["observation"] = wants
        return answer

    def handle(self, message):
        """The answer to one message; an exception in the agent becomes an ``error`` answer."""
        kind = message.get("type") if isinstance(message, dict) else None
        try:
            if kind == "hello":
                return self.hello(message)
            if kind == "reset":
                self.agent.reset(message)
                return {"type": "ready"}
            if kind == "observe":
                return to_act(self.agent.predict(message))
            raise ProtocolError(f"unknown message type {kind!r}")
        except Exception as err:  # the harness records it and ends the episode
            traceback.print_exc(file=sys.stderr)
            return {"type": "error", "message": f"{type(err).__name__}: {err}"}


def serve_stdio(agent, stdin=None, stdout=None):
    """Answers messages from ``stdin`` on ``stdout`` until end of input.

    While the agent runs, ``sys.stdout`` is the standard error stream, so an
    agent that prints cannot corrupt the protocol.
    """
    stdin = stdin or sys.stdin
    out = stdout or sys.stdout
    sys.stdout = sys.stderr
    session = Session(agent)
    for line in stdin:
        line = line.strip()
        if not line:
            continue
        try:
            message = json.loads(line)
        except ValueError as err:
            answer = {"type": "error", "message": f"not JSON: {err}"}
        else:
            answer = session.handle(message)
        out.write(json.dumps(answer) + "\n")
        out.flush()


def serve_http(make_agent, host="127.0.0.1", port=8080, ready=None):
    """Serves the protocol as HTTP POSTs (``--agent http``): each message is a
    POST body and the answer is the response body. Each harness session (the
    ``session`` field) gets its own agent from ``make_agent()``.
    ``ready``, when given, is called with the bound ``(host, port)``."""
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    sessions = {}
    lock = threading.Lock()

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):
            length = int(self.headers.get("Content-Length") or 0)
            try:
                message = json.loads(self.rfile.read(length))
            except ValueError as err:
                answer = {"type": "error", "message": f"not JSON: {err}"}
            else:
                key = message.get("session", "") if isinstance(message, dict) else ""
                with lock:
                    session = sessions.get(key)
                    if session is None:
                        session = sessions[key] = Session(make_agent())
                answer = session.handle(message)
            body = json.dumps(answer).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, fmt, *args):
            sys.stderr.write("arena_agent http: " + fmt % args + "\n")

    server = ThreadingHTTPServer((host, port), Handler)
    if ready:
        ready(server.server_address[:2])
    try:
        server.serve_forever()
    finally:
        server.server_close()
