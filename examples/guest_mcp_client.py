"""Drives a guest's desktop over MCP with the official MCP Python SDK (`pip install mcp`):
lists the tools, starts Notepad, finds its text area among the numbered elements of
`state`, types into it, copies the text and reads it back from the clipboard, puts
other text on the clipboard and reads that, checks that an old number is refused
once a newer state has numbered the screen, then tries `shell` (refused unless the
guest runs with --mcp-shell). Prints one JSON object saying what each step answered.

    arena-guest --backend stub --mcp --token A-TOKEN-OF-16-CHARS --port 5000 &
    python3 examples/guest_mcp_client.py http://127.0.0.1:5000/mcp A-TOKEN-OF-16-CHARS
"""

import asyncio
import json
import sys

import httpx2 as httpx
from mcp import ClientSession
from mcp.client.streamable_http import streamable_http_client


def text_of(result):
    return "".join(getattr(c, "text", "") for c in result.content)


async def call(session, tool, arguments):
    result = await session.call_tool(tool, arguments)
    if result.is_error:
        raise RuntimeError(f"{tool}: {text_of(result)}")
    return json.loads(text_of(result))


async def drive(url, token, words):
    said = {}
    async with httpx.AsyncClient(headers={"Authorization": f"Bearer {token}"}, timeout=120) as http:
        async with streamable_http_client(url, http_client=http) as (read, write):
            async with ClientSession(read, write) as session:
                await session.initialize()
                said["tools"] = [tool.name for tool in (await session.list_tools()).tools]

                said["launched"] = await call(session, "launch_app", {"name": "notepad"})
                state = await call(session, "state", {})
                text_area = next(
                    e
                    for e in state["elements"]
                    if "Notepad" in e["window"] and e["role"] in ("Document", "Edit")
                )
                said["element"] = text_area
                said["typed"] = await call(
                    session, "type_into_element", {"element": text_area["element"], "text": words, "clear": True}
                )
                await call(session, "press_keys", {"keys": ["ctrl", "a"]})
                await call(session, "press_keys", {"keys": ["ctrl", "c"]})
                said["copied"] = await call(session, "clipboard_get", {})
                await call(session, "clipboard_set", {"text": "Set by the Python SDK"})
                said["set"] = await call(session, "clipboard_get", {})

                # A newer state numbers on from the last: the old numbers are refused as stale.
                await call(session, "state", {})
                stale = await session.call_tool("click_element", {"element": text_area["element"]})
                said["stale"] = {"is_error": bool(stale.is_error), "text": text_of(stale)}

                shell = await session.call_tool("shell", {"command": "echo hello"})
                said["shell"] = {"is_error": bool(shell.is_error), "text": text_of(shell)}
    print(json.dumps(said), flush=True)


if __name__ == "__main__":
    asyncio.run(drive(sys.argv[1], sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else "Hello from MCP"))
