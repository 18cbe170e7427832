"""A tiny agent over MCP, with the official MCP Python SDK (`pip install mcp`):
for each task `arena run --agent mcp` hands it, it types the quoted text of a
"Type "..." and save it" instruction, saves and calls `done`; anything else it `fail`s.

    arena run --tasks tasks/stub --stub-guests 1 --agent mcp --mcp-listen 127.0.0.1:8765 &
    python3 examples/mcp_agent.py http://127.0.0.1:8765/mcp TOKEN
"""

import asyncio
import json
import re
import sys

import httpx2 as httpx
from mcp import ClientSession
from mcp.client.streamable_http import streamable_http_client


def text_of(result):
    return "".join(getattr(c, "text", "") for c in result.content)


async def play(url, token):
    scores = []
    async with httpx.AsyncClient(headers={"Authorization": f"Bearer {token}"}, timeout=600) as http:
        async with streamable_http_client(url, http_client=http) as (read, write):
            async with ClientSession(read, write) as session:
                await session.initialize()
                while True:
                    task = json.loads(text_of(await session.call_tool("get_task", {})))
                    if task["task_id"] is None:
                        break
                    quoted = re.search(r'[Tt]ype "([^"]*)"', task["instruction"])
                    if quoted is None:
                        ended = await session.call_tool("fail", {})
                    else:
                        await session.call_tool("type_text", {"text": quoted.group(1)})
                        await session.call_tool("press_keys", {"keys": ["ctrl", "s"]})
                        ended = await session.call_tool("done", {})
                    result = json.loads(text_of(ended))["result"] or {}
                    print(f"{task['task_id']}: {result.get('score')}", flush=True)
                    scores.append(result.get("score"))
    return scores


if __name__ == "__main__":
    asyncio.run(play(sys.argv[1], sys.argv[2]))
