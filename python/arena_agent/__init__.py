"""The arena step protocol for agents written in Python.

Subclass :class:`Agent`, then run it with ``python -m arena_agent MODULE:CLASS``
under ``arena run --agent exec`` (or ``--http HOST:PORT`` for ``--agent http``).
Existing WindowsAgentArena and OSWorld agents run unchanged through
:mod:`arena_agent.adapters`. Standard library only.
"""

from .protocol import (
    ACTION_SPACES,
    COORDS,
    PROTOCOL_VERSION,
    Agent,
    ProtocolError,
    Session,
    screenshot_bytes,
    serve_http,
    serve_stdio,
)

__all__ = [
    "ACTION_SPACES",
    "COORDS",
    "PROTOCOL_VERSION",
    "Agent",
    "ProtocolError",
    "Session",
    "screenshot_bytes",
    "serve_http",
    "serve_stdio",
]
