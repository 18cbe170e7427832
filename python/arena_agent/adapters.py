"""Existing agents, unchanged, behind the step protocol.

- :class:`WaaAdapter`: an upstream WindowsAgentArena agent such as
  ``mm_agents.navi.agent:NaviAgent``. Each step it gets upstream's ``obs``
  dict (the keys ``desktop_env._get_obs`` builds) and ``predict(instruction,
  obs)`` returns ``(response, actions, logs, computer_update_args)`` as
  ``lib_run_single.py`` takes them; the ``rects``, ``window_rect`` and
  ``scale`` of the update go back to the harness, which resolves
  ``computer.mouse.move_id`` with them as upstream's ``/update_computer`` does.
- :class:`OsworldAdapter`: an OSWorld-style agent, ``predict(instruction,
  obs) -> (response, actions)`` with pyautogui code or ``computer_13`` actions.
"""

import io
import json

from .protocol import Agent, screenshot_bytes


def upstream_obs(obs):
    """Upstream's observation dict from an ``observe`` message.

    ``window_rect`` is the whole screen and ``window_image`` the whole
    screenshot (a PIL image when Pillow is installed): the step protocol does
    not carry the foreground window's rectangle (docs/agents.md).
    """
    png = screenshot_bytes(obs)
    width, height = obs.get("screen_width", 0), obs.get("screen_height", 0)
    image = None
    if png is not None:
        try:
            from PIL import Image

            image = Image.open(io.BytesIO(png))
        except ImportError:
            image = None
    return {
        "screenshot": png,
        "accessibility_tree": obs.get("a11y_xml"),
        "terminal": None,
        "instruction": obs.get("instruction", ""),
        "window_title": obs.get("window_title", ""),
        "window_rect": [0, 0, width, height],
        "window_image": image,
        "window_names_str": "\n".join(obs.get("windows") or []),
        "computer_clipboard": obs.get("computer_clipboard"),
        "human_input": None,
    }


def json_fields(logs):
    """The entries of an agent's ``logs`` that JSON can carry (images and the like are left out)."""
    kept = {}
    for key, value in (logs or {}).items():
        try:
            json.dumps(value)
        except (TypeError, ValueError):
            continue
        kept[str(key)] = value
    return kept


class _Upstream(Agent):
    def __init__(self, inner, action_space):
        self.inner = inner
        self.action_space = action_space
        self.name = type(inner).__name__
        self.instruction = ""

    def reset(self, task):
        self.instruction = task.get("instruction", "")
        self.inner.reset()


class WaaAdapter(_Upstream):
    """An upstream WAA agent; answers ``computer`` code by default."""

    observation = {"a11y": "xml", "windows": True, "clipboard": True}

    def __init__(self, inner, action_space="computer"):
        super().__init__(inner, action_space)

    def predict(self, obs):
        answer = self.inner.predict(obs.get("instruction", self.instruction), upstream_obs(obs))
        response, actions = answer[0], answer[1]
        logs = answer[2] if len(answer) > 2 else {}
        update = answer[3] if len(answer) > 3 else None
        act = {"response": response or "", "actions": list(actions or []), "record": json_fields(logs)}
        if update:
            act["computer_update"] = {
                "rects": [list(map(float, r)) for r in update.get("rects") or []],
                "window_rect": list(map(float, update.get("window_rect") or [])) or None,
                "scale": list(map(float, update.get("scale") or [])) or None,
            }
            act["computer_update"] = {k: v for k, v in act["computer_update"].items() if v is not None}
        return act


class OsworldAdapter(_Upstream):
    """An OSWorld-style agent; answers pyautogui code by default (``computer_13`` with ``--action-space``)."""

    observation = {"a11y": "xml"}

    def __init__(self, inner, action_space="pyautogui"):
        super().__init__(inner, action_space)

    def predict(self, obs):
        answer = self.inner.predict(obs.get("instruction", self.instruction), upstream_obs(obs))
        response, actions = answer[0], answer[1]
        return {"response": response if isinstance(response, str) else json.dumps(response, default=str),
                "actions": list(actions or [])}
