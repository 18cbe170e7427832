"""A client of ``arena env serve``: the harness as an environment your program drives.

``ArenaEnv(url)`` opens a session on one of the server's guests at the first
``reset``; each ``step`` plays one step of the episode, as ``arena run`` plays it
for a built-in agent (the task's setup, the pause after each action, the
evaluation with the task's own checks). The observation is the step protocol's
``observe`` message (docs/agents.md): ``instruction``, ``screenshot``
(``png_base64``), ``a11y_xml``, ``windows``, ``window_title``, ``clipboard``.

    env = ArenaEnv("http://127.0.0.1:8766")
    obs = env.reset("stub-notepad-draft")
    obs, reward, done, info = env.step("pyautogui.write('This is a draft.')")
    obs, reward, done, info = env.step("DONE")      # reward: the task's score
    env.close()

Only the standard library is used. ``arena_agent.gym_env`` wraps it for
gymnasium when gymnasium is installed.
"""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from typing import Any, Dict, List, Optional, Tuple, Union

__all__ = ["ArenaEnv", "ArenaEnvError"]


class ArenaEnvError(RuntimeError):
    """The server refused a request; ``status`` is its HTTP status, the message its reason."""

    def __init__(self, status: int, message: str):
        super().__init__(f"HTTP {status}: {message}")
        self.status = status
        self.message = message


Actions = Union[str, Dict[str, Any], List[Union[str, Dict[str, Any]]]]


class ArenaEnv:
    """One session of an ``arena env serve`` server: one guest, one episode at a time."""

    def __init__(
        self,
        url: str,
        observation: Optional[Dict[str, Any]] = None,
        timeout: float = 900.0,
        token: Optional[str] = None,
    ):
        """``url``: the server's address; ``observation``: what each observation
        carries, as the step protocol's ``hello`` asks it (``{"a11y": "none"}``, ...);
        ``timeout``: the longest wait for one answer, in seconds (a step includes the
        task's setup, pauses and evaluation); ``token``: the server's ``--env-token``,
        by default ``ARENA_ENV_TOKEN`` from the environment (none for a server
        without one)."""
        self.url = url.rstrip("/")
        self.token = token if token is not None else os.environ.get("ARENA_ENV_TOKEN") or None
        self.observation = observation
        self.timeout = timeout
        self.session: Optional[str] = None
        self.done = False
        self.last_info: Dict[str, Any] = {}

    def _call(self, method: str, path: str, body: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.url + path, data=data, method=method)
        request.add_header("Content-Type", "application/json")
        if self.token:
            request.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(request, timeout=self.timeout) as answer:
                return json.loads(answer.read())
        except urllib.error.HTTPError as err:
            text = err.read().decode(errors="replace")
            try:
                message = json.loads(text).get("error") or text
            except ValueError:
                message = text
            raise ArenaEnvError(err.code, message) from None

    def info(self) -> Dict[str, Any]:
        """The served tasks (``id``, ``name``, ``domain``, ``instruction``), the
        guests, the step cap, the action spaces and the screen size."""
        return self._call("GET", "/info")

    def reset(self, task: Union[str, Dict[str, Any]]) -> Dict[str, Any]:
        """Starts an episode of ``task`` (a served task's id or name, or a task's
        JSON as a dict) and answers its first observation. ``last_info`` gets the
        task's facts and the screen size."""
        body: Dict[str, Any] = {"task": task}
        if self.session is not None:
            body["session"] = self.session
        if self.observation is not None:
            body["observation"] = self.observation
        answer = self._call("POST", "/reset", body)
        self.session = answer["session"]
        self.done = False
        self.last_info = answer.get("info", {})
        return answer["observation"]

    def step(
        self, actions: Actions, action_space: str = "pyautogui", coords: Optional[str] = None
    ) -> Tuple[Dict[str, Any], float, bool, Dict[str, Any]]:
        """One step: ``actions`` is one action or a list, in ``action_space``
        (``pyautogui`` or ``computer`` code strings, ``computer_13`` or ``typed``
        action objects); ``"DONE"``, ``"FAIL"`` and ``"WAIT"`` are the decisions in
        any space. Answers ``(observation, reward, done, info)``: the reward is the
        task's score when the episode ends (a decision, or its last step), 0 before."""
        if self.session is None:
            raise ArenaEnvError(409, "no episode: call reset first")
        body: Dict[str, Any] = {"session": self.session, "actions": actions, "action_space": action_space}
        if coords is not None:
            body["coords"] = coords
        answer = self._call("POST", "/step", body)
        self.done = bool(answer["done"])
        self.last_info = answer.get("info", {})
        return answer["observation"], float(answer["reward"]), self.done, self.last_info

    def evaluate(self) -> float:
        """The ended episode's score (the server refuses while it still runs)."""
        if self.session is None:
            raise ArenaEnvError(409, "no episode: call reset first")
        return float(self._call("POST", "/evaluate", {"session": self.session})["score"])

    def close(self) -> None:
        """Ends the episode, if any, and gives the guest back to the server."""
        if self.session is not None:
            session, self.session = self.session, None
            try:
                self._call("POST", "/close", {"session": session})
            except ArenaEnvError as err:
                if err.status != 404:
                    raise

    def __enter__(self) -> "ArenaEnv":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
