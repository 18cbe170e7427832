"""Agents the agent-protocol tests run through `python -m arena_agent`: the stub
tasks' oracle solutions written in the four action spaces (one space per task,
coordinates on the 0..1000 grid the hello names),
and three that misbehave on one task (garbage, a hang, an exit)."""

import os
import sys
import time

from arena_agent import Agent, screenshot_bytes

PLANS = {
    # pyautogui answers are input only, so starting Notepad on the file is WAA
    # `computer` code (upstream's /execute_windows runs any Python).
    "stub-explorer-fill-file": ("computer", [
        ["import subprocess\nsubprocess.Popen(['notepad.exe', r'C:\\Users\\Docker\\Documents\\Projects\\notes.txt'])"],
        ["computer.keyboard.write('kickoff on monday')\ncomputer.keyboard.press('ctrl+s')"],
        "DONE",
    ]),
    # As a person would: the Run dialog, the folder, and a click on its OK button,
    # on the 0..1000 grid the agent names in its hello (near (191, 821) of 1440x900).
    "stub-explorer-open-folder": ("pyautogui", [
        ["pyautogui.hotkey('win', 'r')",
         "pyautogui.write(r'C:\\Users\\Docker\\Documents\\Reports')",
         "pyautogui.click(133, 912)"],
        "DONE",
    ]),
    "stub-notepad-append": ("computer", [
        ["computer.keyboard.press('ctrl+end')\ncomputer.keyboard.write('buy eggs\\n')"],
        ["computer.keyboard.press('ctrl+s')"],
        "DONE",
    ]),
    "stub-notepad-count": ("typed", [
        [{"type": "type_text", "text": "3"}, {"type": "hotkey", "keys": ["ctrl", "s"]}],
        "DONE",
    ]),
    "stub-notepad-draft": ("computer_13", [
        [{"action_type": "TYPING", "parameters": {"text": "This is a draft."}},
         {"action_type": "HOTKEY", "parameters": {"keys": ["ctrl", "s"]}}],
        "DONE",
    ]),
    "stub-settings-infeasible": ("pyautogui", ["FAIL"]),
}

# The task the misbehaving agents break on.
VICTIM = "stub-notepad-append"


class Oracle(Agent):
    name = "oracle"
    action_space = "pyautogui"
    coords = "grid1000"

    def reset(self, task):
        self.task = task["task_name"]
        self.space, self.plan = PLANS[self.task]
        self.i = 0

    def predict(self, obs):
        png = screenshot_bytes(obs)
        if png is None or not png.startswith(b"\x89PNG"):
            raise ValueError("the observation has no PNG screenshot")
        if "<desktop" not in (obs.get("a11y_xml") or ""):
            raise ValueError("the observation has no accessibility XML")
        step = self.plan[min(self.i, len(self.plan) - 1)]
        self.i += 1
        print(f"oracle: {self.task} step {self.i}", file=sys.stderr)
        record = {"oracle_step": self.i, "screen": [obs["screen_width"], obs["screen_height"]]}
        if isinstance(step, str):
            return {"decision": step, "response": f"{self.task}: {step}", "record": record}
        return {"action_space": self.space, "actions": step, "response": f"{self.task}: step {self.i}", "record": record}


class Garbage(Oracle):
    def predict(self, obs):
        if self.task == VICTIM:
            sys.__stdout__.write("this is not JSON\n")
            sys.__stdout__.flush()
        return super().predict(obs)


class Hang(Oracle):
    def predict(self, obs):
        if self.task == VICTIM:
            time.sleep(3600)
        return super().predict(obs)


class Exit(Oracle):
    def predict(self, obs):
        if self.task == VICTIM and self.i == 1:
            os._exit(3)
        return super().predict(obs)
