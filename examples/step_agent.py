"""A tiny agent over the step protocol: it types the quoted text of a
"Type "..." and save it" instruction, saves, and says DONE; anything else it FAILs.

    pip install ./python
    arena run --tasks tasks/stub --stub-guests 1 --agent exec \
        --agent-cmd "python3 examples/step_agent.py"
"""

import re

from arena_agent import Agent, serve_stdio


class TypeAndSave(Agent):
    action_space = "pyautogui"
    observation = {"screenshot": "none", "a11y": "none"}

    def reset(self, task):
        self.quoted = re.search(r'[Tt]ype "([^"]*)"', task["instruction"])
        self.typed = False

    def predict(self, obs):
        if self.quoted is None:
            return {"decision": "FAIL", "response": "not a typing task"}
        if self.typed:
            return {"decision": "DONE"}
        self.typed = True
        text = self.quoted.group(1)
        return {"actions": [f"pyautogui.write({text!r})", "pyautogui.hotkey('ctrl', 's')"], "response": f"typing {text!r}"}


if __name__ == "__main__":
    serve_stdio(TypeAndSave())
