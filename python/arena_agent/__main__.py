"""``python -m arena_agent MODULE:CLASS``: serve one agent over the step protocol.

On stdin/stdout by default (``arena run --agent exec --agent-cmd ...``), or
as an HTTP server with ``--http HOST:PORT`` (``arena run --agent http``).
``--adapter waa`` or ``osworld`` wraps an upstream agent class unchanged;
``--path`` adds folders to ``sys.path`` (a WAA checkout's client folder);
``--kwargs`` gives the class's constructor arguments as JSON.
"""

import argparse
import importlib
import json
import sys

from . import adapters, protocol


def load(spec, kwargs, adapter, action_space):
    module_name, _, attr = spec.partition(":")
    if not attr:
        raise SystemExit(f"arena_agent: expected MODULE:CLASS, got {spec!r}")
    cls = getattr(importlib.import_module(module_name), attr)
    inner = cls(**kwargs)
    if adapter == "auto":
        if isinstance(inner, protocol.Agent):
            adapter = "native"
        elif module_name.startswith("mm_agents."):
            adapter = "waa"
        else:
            adapter = "osworld"
    if adapter == "native":
        if action_space:
            inner.action_space = action_space
        return inner
    wrapper = adapters.WaaAdapter if adapter == "waa" else adapters.OsworldAdapter
    return wrapper(inner, action_space) if action_space else wrapper(inner)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m arena_agent", description=__doc__.splitlines()[0])
    parser.add_argument("agent", help="MODULE:CLASS")
    parser.add_argument("--adapter", choices=["auto", "native", "waa", "osworld"], default="auto")
    parser.add_argument("--action-space", choices=list(protocol.ACTION_SPACES))
    parser.add_argument("--kwargs", default="{}", help="the class's constructor arguments as a JSON object")
    parser.add_argument("--path", action="append", default=[], help="a folder to add to sys.path (repeatable)")
    parser.add_argument("--http", metavar="HOST:PORT", help="serve HTTP instead of stdin/stdout")
    args = parser.parse_args(argv)
    sys.path[:0] = args.path
    kwargs = json.loads(args.kwargs)
    if args.http:
        host, _, port = args.http.rpartition(":")

        def announce(address):
            print(f"arena_agent: listening on http://{address[0]}:{address[1]}/", file=sys.stderr, flush=True)

        protocol.serve_http(
            lambda: load(args.agent, kwargs, args.adapter, args.action_space),
            host or "127.0.0.1",
            int(port),
            ready=announce,
        )
    else:
        protocol.serve_stdio(load(args.agent, kwargs, args.adapter, args.action_space))


if __name__ == "__main__":
    main()
