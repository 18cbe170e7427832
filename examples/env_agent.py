"""Drives `arena env serve` from Python: every served notepad task is played with a
fixed policy (type an answer found in the instruction, save, DONE), and the scores
are printed. Run: PYTHONPATH=python python3 examples/env_agent.py URL"""

import re
import sys

from arena_agent.env import ArenaEnv


def answer_of(instruction: str) -> str:
    quoted = re.findall(r'"([^"]+)"', instruction)
    return quoted[0] if quoted else ""


def main(url: str) -> None:
    with ArenaEnv(url, observation={"screenshot": "none", "a11y": "none"}) as env:
        tasks = [t for t in env.info()["tasks"] if t["domain"] == "notepad"]
        for task in tasks:
            obs = env.reset(task["id"])
            text = answer_of(obs["instruction"])
            env.step([{"type": "type_text", "text": text}, {"type": "hotkey", "keys": ["ctrl", "s"]}], action_space="typed")
            _, reward, done, info = env.step("DONE")
            print(f"{task['id']}: {reward} ({info.get('status')})")


if __name__ == "__main__":
    main(sys.argv[1])
