"""``ArenaGymEnv``: an ``arena env serve`` task as a gymnasium environment.

Needs gymnasium, numpy and Pillow (``pip install gymnasium pillow``); the rest of
``arena_agent`` needs none of them.

- observation: ``{"screenshot": uint8 array (height, width, 3), "step": int}``;
  the text parts of the step protocol's observation (``instruction``,
  ``a11y_xml``, ``windows``, ``window_title``, ``clipboard``) are in ``info``;
- action: one action of the chosen action space as text (``pyautogui`` code by
  default; ``computer`` code works the same way), ``"DONE"`` and ``"FAIL"`` ending
  the episode;
- reward: the task's score when the episode ends, 0 before; ``terminated`` when
  it ends (a decision or its last step), never ``truncated``.

``reset(options={"task": ...})`` plays another served task than the one the
environment was made for.
"""

from __future__ import annotations

import base64
import io
import string
from typing import Any, Dict, Optional, Tuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from PIL import Image

from .env import ArenaEnv

__all__ = ["ArenaGymEnv"]

# What a sampled action may hold: code's usual characters.
CHARSET = string.ascii_letters + string.digits + " _.,:;()[]'\"=+-*/<>\n"

TEXT_KEYS = ("instruction", "a11y_xml", "windows", "window_title", "clipboard")


class ArenaGymEnv(gym.Env):
    """One served task (``task``: its id or name) on a session of ``url``."""

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        url: str,
        task: str,
        action_space: str = "pyautogui",
        max_action_length: int = 4096,
        render_mode: Optional[str] = None,
        token: Optional[str] = None,
    ):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r}: only 'rgb_array' is offered")
        self.arena = ArenaEnv(url, observation={"screenshot": "inline"}, token=token)
        served = self.arena.info()
        screen = served.get("screen") or {}
        if not screen:
            raise ValueError(f"{url} does not say its screen size (GET /info)")
        self.task = task
        self.arena_action_space = action_space
        self.render_mode = render_mode
        self.observation_space = spaces.Dict(
            {
                "screenshot": spaces.Box(0, 255, (screen["height"], screen["width"], 3), np.uint8),
                "step": spaces.Discrete(int(served["max_steps"]) + 2),
            }
        )
        self.action_space = spaces.Text(max_length=max_action_length, min_length=1, charset=CHARSET)
        self._frame: Optional[np.ndarray] = None

    def _split(self, observation: Dict[str, Any]) -> Tuple[Dict[str, Any], Dict[str, Any]]:
        png = base64.b64decode(observation["screenshot"]["png_base64"])
        with Image.open(io.BytesIO(png)) as image:
            frame = np.asarray(image.convert("RGB"), dtype=np.uint8)
        self._frame = frame
        info = {key: observation.get(key) for key in TEXT_KEYS}
        return {"screenshot": frame, "step": int(observation["step"])}, info

    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None):
        super().reset(seed=seed)
        task = (options or {}).get("task", self.task)
        obs, info = self._split(self.arena.reset(task))
        info.update(self.arena.last_info)
        return obs, info

    def step(self, action: str):
        observation, reward, done, served = self.arena.step(action, self.arena_action_space)
        obs, info = self._split(observation)
        info.update(served)
        return obs, reward, done, False, info

    def render(self):
        return self._frame if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self.arena.close()
        super().close()
