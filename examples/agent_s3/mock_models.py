"""Two stand-in models for Agent S3 on the stub desktop, over real HTTP.

Agent S3 (``python -m arena_agent.agent_s3``) needs a main (generation) model and
a grounding model behind OpenAI-compatible chat-completions endpoints. This
script serves both on loopback ports so that Agent S3's own code (its prompts,
its reply parsing, its format checks, its grounding and coordinate scaling) runs
unchanged on a stub task without any API key::

    python examples/agent_s3/mock_models.py --log models.jsonl
    planner http://127.0.0.1:PORT/v1
    grounding http://127.0.0.1:PORT/v1

- Every request is checked against the ``openai`` SDK's own request types
  (``openai.types.chat.CompletionCreateParamsNonStreaming``): required keys,
  value types, literals, and no key the type does not declare (vendor extras
  given with ``--allow-extra``, e.g. vLLM's ``repetition_penalty``), along with
  the path, the bearer key and the model name. A request that does not match is
  answered 400 with an OpenAI-style error body naming what was wrong.
- The planner plays a "type the quoted text and save" task as a model would:
  it reads the task from the system prompt, decides from its own earlier
  answers in the conversation, and answers in Agent S3's reply format (its
  four sections and one ``agent.*`` call in a python code block). Requests
  whose system prompt lists no agent API are the reflection agent's, answered
  with a reflection.
- The grounding model answers ``(x,y)`` in its own coordinate space
  (``--grounding-size``, Agent S's ``grounding_width`` x ``grounding_height``):
  it finds the focused window of the stub desktop in the screenshot (its title
  bar colour and border, ``guest-server/src/desktop/stub/render.rs``) and points
  at the middle of its body.
- ``--log FILE`` gets one JSON line per request: which model and role, the
  screenshot sizes, the problems found and the answer.

Needs the packages Agent S3 itself needs (``openai``, ``pydantic``, ``numpy``,
``Pillow``): run it with the same Python as the agent.
"""

import argparse
import base64
import collections.abc
import io
import json
import re
import sys
import threading
import time
import types
import typing
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import typing_extensions
from openai.types.chat.completion_create_params import CompletionCreateParamsNonStreaming
from PIL import Image
from pydantic import TypeAdapter, ValidationError

# The stub desktop's colours (guest-server/src/desktop/stub/render.rs).
TITLE_FOCUSED = (0, 84, 153)
BORDER_FOCUSED = (0, 60, 120)

# --- request checking against the SDK's types -------------------------------------

_WRAPPERS = {typing_extensions.Required, typing_extensions.NotRequired, typing.Required, typing.NotRequired}
_READ_ONLY = getattr(typing_extensions, "ReadOnly", None)
_LEAF = {}


def _unwrap(tp):
    """The type under Required/NotRequired/ReadOnly/Annotated, and whether Required/NotRequired said so."""
    marker = None
    while True:
        origin = typing.get_origin(tp)
        if origin in _WRAPPERS:
            marker = marker or origin
            tp = typing.get_args(tp)[0]
        elif origin is typing.Annotated or (_READ_ONLY is not None and origin is _READ_ONLY):
            tp = typing.get_args(tp)[0]
        else:
            return tp, marker


def _leaf_ok(value, tp):
    adapter = _LEAF.get(tp)
    if adapter is None:
        adapter = _LEAF[tp] = TypeAdapter(tp)
    try:
        adapter.validate_python(value, strict=True)
        return True
    except ValidationError:
        return False


def _same_shape(value, tp):
    """Whether ``value`` has the JSON shape of ``tp`` (for an object type, its literal tags agree)."""
    tp, _ = _unwrap(tp)
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if typing_extensions.is_typeddict(tp):
        if not isinstance(value, dict):
            return False
        for key, hint in typing.get_type_hints(tp, include_extras=True).items():
            inner, _ = _unwrap(hint)
            if typing.get_origin(inner) is typing.Literal and key in value and value[key] not in typing.get_args(inner):
                return False
        return True
    if origin is typing.Union or origin is types.UnionType:
        return any(_same_shape(value, member) for member in args)
    if origin is typing.Literal:
        return value in args
    if origin in (list, collections.abc.Iterable, collections.abc.Sequence):
        return isinstance(value, list)
    if origin in (dict, collections.abc.Mapping):
        return isinstance(value, dict)
    return not isinstance(value, (dict, list))


def _brief(value):
    text = json.dumps(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _names(types_):
    return ", ".join(getattr(t, "__name__", str(t)) for t in types_)


def problems(value, tp, path, allow_extra=()):
    """Where ``value`` (parsed JSON) does not match the SDK type ``tp``; empty when it does."""
    tp, _ = _unwrap(tp)
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if typing_extensions.is_typeddict(tp):
        if not isinstance(value, dict):
            return [f"{path}: expected an object ({tp.__name__}), got {type(value).__name__}"]
        hints = typing.get_type_hints(tp, include_extras=True)
        found = []
        for key, hint in hints.items():
            _, marker = _unwrap(hint)
            required = marker is typing_extensions.Required or marker is typing.Required or (
                marker is None and getattr(tp, "__total__", True)
            )
            if required and key not in value:
                found.append(f"{path}: missing {key!r} ({tp.__name__})")
        for key, item in value.items():
            if key in hints:
                found += problems(item, hints[key], f"{path}.{key}")
            elif key not in allow_extra:
                found.append(f"{path}: {key!r} is not a field of {tp.__name__}")
        return found
    if origin is typing.Union or origin is types.UnionType:
        if value is None and type(None) in args:
            return []
        # The members of the value's own shape (an object whose tag literals match, an
        # array, a scalar); the problems of the closest one name what is wrong.
        best = None
        for member in args:
            if not _same_shape(value, member):
                continue
            found = problems(value, member, path)
            if not found:
                return []
            if best is None or len(found) < len(best):
                best = found
        return best or [f"{path}: {_brief(value)} matches no member of {_names(args)}"]
    if origin is typing.Literal:
        return [] if value in args else [f"{path}: {value!r} is not one of {list(args)}"]
    if origin in (list, collections.abc.Iterable, collections.abc.Sequence):
        if not isinstance(value, list):
            return [f"{path}: expected an array, got {type(value).__name__}"]
        return [p for i, item in enumerate(value) for p in problems(item, args[0], f"{path}[{i}]")]
    if origin in (dict, collections.abc.Mapping):
        if not isinstance(value, dict):
            return [f"{path}: expected an object, got {type(value).__name__}"]
        return [p for k, item in value.items() for p in problems(item, args[1], f"{path}.{k}")]
    if tp in (object, typing.Any):
        return []
    if tp is float and isinstance(value, int) and not isinstance(value, bool):
        return []
    return [] if _leaf_ok(value, tp) else [f"{path}: {value!r} is not a {getattr(tp, '__name__', tp)}"]


# --- reading a request ------------------------------------------------------------


def text_of(message):
    content = message.get("content")
    if isinstance(content, str):
        return content
    return "\n".join(p.get("text", "") for p in content or [] if isinstance(p, dict) and p.get("type") == "text")


def images_of(message, found):
    """The PNG images of a message, decoded; a malformed one is a problem."""
    out = []
    content = message.get("content")
    for part in content if isinstance(content, list) else []:
        if not isinstance(part, dict) or part.get("type") != "image_url":
            continue
        url = part["image_url"]["url"]
        head, _, data = url.partition(",")
        if not head.startswith("data:image") or not head.endswith(";base64"):
            found.append(f"an image is not a base64 data URL: {head[:40]!r}")
            continue
        try:
            image = Image.open(io.BytesIO(base64.b64decode(data, validate=True)))
            image.load()
        except Exception as err:  # noqa: BLE001 - any decoding failure is the request's fault
            found.append(f"an image does not decode: {err}")
            continue
        if image.format != "PNG":
            found.append(f"an image is {image.format}, not PNG")
        out.append(image)
    return out


# --- the planner ------------------------------------------------------------------


def agent_calls(text):
    """The ``agent.*`` calls in the python code blocks of an answer."""
    return re.findall(r"agent\.(\w+)\(", " ".join(re.findall(r"```(?:python)?\s*(.*?)```", text, re.DOTALL)))


def planner_answer(body, system):
    """The main model's next answer, in Agent S3's reply format."""
    if "def click(" not in system or "def done(" not in system:
        # Not the worker: the reflection agent, which answers in prose.
        return (
            "The trajectory is going according to plan: the last action did what it was meant to do. "
            "Continue as planned."
        )
    quoted = re.search(r'[Tt]ype "([^"]*)"', system)
    done_before = [c for m in body["messages"] if m.get("role") == "assistant" for c in agent_calls(text_of(m))]
    if quoted is None:
        step, analysis, code = (
            "I cannot tell what to type from this task, so it cannot be done.",
            "The task names no quoted text.",
            "agent.fail()",
        )
    elif "type" not in done_before:
        step, analysis, code = (
            f"Click into the editing area of the open Notepad window and type {quoted.group(1)!r}.",
            "A Notepad window is open in front; its editing area is empty.",
            f'agent.type(element_description="The large empty text editing area of the open Notepad window", '
            f"text={quoted.group(1)!r})",
        )
    elif "hotkey" not in done_before:
        step, analysis, code = (
            "Save the file with the keyboard shortcut.",
            "The text has been typed into the Notepad window; the file is not saved yet.",
            "agent.hotkey(['ctrl', 's'])",
        )
    else:
        step, analysis, code = (
            "The text is typed and saved: the task is complete.",
            "The Notepad window shows the typed text and the file was saved.",
            "agent.done()",
        )
    verification = (
        "No action has been taken yet."
        if not done_before
        else f"The previous action, agent.{done_before[-1]}(...), appears to have succeeded."
    )
    return (
        f"(Previous action verification)\n{verification}\n\n"
        f"(Screenshot Analysis)\n{analysis}\n\n"
        f"(Next Action)\n{step}\n\n"
        f"(Grounded Action)\n```python\n{code}\n```\n"
    )


# --- the grounding model ----------------------------------------------------------


def focused_body_centre(image):
    """The middle of the focused window's body on the stub desktop, in image pixels; None when there is none."""
    pixels = np.asarray(image.convert("RGB"))
    bar = np.all(pixels == TITLE_FOCUSED, axis=2)
    rows = np.nonzero(bar.sum(axis=1) > 40)[0]
    if rows.size == 0:
        return None
    top, bottom = int(rows[0]), int(rows[-1])
    cols = np.nonzero(bar[top : bottom + 1].any(axis=0))[0]
    centre_x = (int(cols[0]) + int(cols[-1])) // 2
    border = np.nonzero(np.all(pixels[bottom + 1 :, centre_x] == BORDER_FOCUSED, axis=1))[0]
    window_bottom = bottom + 1 + int(border[0]) if border.size else pixels.shape[0] - 1
    return centre_x, (bottom + 1 + window_bottom) // 2


def grounding_answer(image, size):
    point = focused_body_centre(image)
    if point is None:
        point = (image.width // 2, image.height // 2)
    x = round(point[0] * size[0] / image.width)
    y = round(point[1] * size[1] / image.height)
    return f"({x},{y})"


# --- the server -------------------------------------------------------------------


class Models:
    def __init__(self, args):
        self.args = args
        self.log_lock = threading.Lock()
        self.log = open(args.log, "a", encoding="utf-8") if args.log else None  # noqa: SIM115 - lives with the server

    def record(self, entry):
        if self.log is not None:
            with self.log_lock:
                self.log.write(json.dumps(entry) + "\n")
                self.log.flush()

    def answer(self, which, path, headers, raw):
        """The status and body for one request to model ``which`` (``planner`` or ``grounding``)."""
        args = self.args
        found = []
        if path.rstrip("/") != "/v1/chat/completions":
            found.append(f"POST to {path}, expected /v1/chat/completions")
        if headers.get("Authorization") != f"Bearer {args.api_key}":
            found.append("the Authorization header is not the bearer key")
        if not (headers.get("Content-Type") or "").startswith("application/json"):
            found.append(f"Content-Type is {headers.get('Content-Type')!r}")
        try:
            body = json.loads(raw)
        except ValueError as err:
            body, found = None, found + [f"the body is not JSON: {err}"]
        entry = {"model": which, "problems": found}
        if isinstance(body, dict):
            found += problems(body, CompletionCreateParamsNonStreaming, "body", tuple(args.allow_extra))
            expected = args.planner_model if which == "planner" else args.grounding_model
            if body.get("model") != expected:
                found.append(f"model is {body.get('model')!r}, expected {expected!r}")
            messages = body.get("messages") if isinstance(body.get("messages"), list) else []
            if not messages or not isinstance(messages[0], dict) or messages[0].get("role") != "system":
                found.append("the first message is not the system prompt")
            if messages and isinstance(messages[-1], dict) and messages[-1].get("role") != "user":
                found.append("the last message is not the user's")
        if found:
            self.record(entry)
            error = {"message": "; ".join(found), "type": "invalid_request_error", "param": None, "code": None}
            return 400, {"error": error}
        system = text_of(messages[0])
        images = [im for m in messages if isinstance(m, dict) for im in images_of(m, found)]
        entry["images"] = [list(im.size) for im in images]
        if which == "planner":
            entry["role"] = "worker" if "def click(" in system else "reflection"
            content = planner_answer(body, system)
        else:
            entry["role"] = "grounding"
            last = messages[-1]
            shots = images_of(last, found)
            if len(shots) != 1 or "Query:" not in text_of(last):
                found.append("a grounding request is one screenshot and one query")
            content = grounding_answer(shots[0], args.grounding_size) if shots else "no image"
            entry["query"] = text_of(last)
        entry["answer"] = content
        entry["problems"] = found
        self.record(entry)
        if found:
            error = {"message": "; ".join(found), "type": "invalid_request_error", "param": None, "code": None}
            return 400, {"error": error}
        return 200, {
            "id": f"chatcmpl-mock-{time.monotonic_ns()}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": body["model"],
            "choices": [
                {
                    "index": 0,
                    "finish_reason": "stop",
                    "logprobs": None,
                    "message": {"role": "assistant", "content": content, "refusal": None},
                }
            ],
            "usage": {"prompt_tokens": 1000, "completion_tokens": len(content) // 4, "total_tokens": 1000 + len(content) // 4},
        }


def handler(models, which):
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def do_POST(self):
            length = int(self.headers.get("Content-Length") or 0)
            status, body = models.answer(which, self.path, self.headers, self.rfile.read(length))
            data = json.dumps(body).encode()
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, fmt, *args):
            sys.stderr.write(f"mock {which}: " + fmt % args + "\n")

    return Handler


def size(text):
    width, _, height = text.partition("x")
    return int(width), int(height)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--api-key", default="mock-key", help="the bearer key both models expect")
    parser.add_argument("--planner-model", default="mock-planner", help="the main model's name")
    parser.add_argument(
        "--grounding-model", default="tgi", help="the grounding model's name (Agent S's huggingface engine sends tgi)"
    )
    parser.add_argument("--grounding-size", type=size, default=(1920, 1080), help="WIDTHxHEIGHT of its coordinates")
    parser.add_argument("--allow-extra", action="append", default=[], help="a body key outside the SDK's types")
    parser.add_argument("--log", help="a JSON line per request to this file")
    args = parser.parse_args(argv)
    models = Models(args)
    servers = []
    for which in ("planner", "grounding"):
        server = ThreadingHTTPServer(("127.0.0.1", 0), handler(models, which))
        servers.append(server)
        print(f"{which} http://127.0.0.1:{server.server_address[1]}/v1", flush=True)
        threading.Thread(target=server.serve_forever, daemon=True).start()
    # Serves until stdin closes (or the process is ended).
    sys.stdin.read()
    for server in servers:
        server.shutdown()


if __name__ == "__main__":
    main()
