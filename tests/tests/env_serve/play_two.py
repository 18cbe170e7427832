"""Plays two stub tasks through arena_agent.env.ArenaEnv, side by side on two
guests, in two action spaces, and prints each task's score as JSON; then checks
the client's errors. Run by tests/tests/env_serve.rs against `arena env serve`."""

import json
import sys
import threading

from arena_agent.env import ArenaEnv, ArenaEnvError

URL = sys.argv[1]
scores = {}


def draft():
    # pyautogui code, as upstream's agents answer.
    with ArenaEnv(URL, observation={"screenshot": "inline", "a11y": "xml"}) as env:
        obs = env.reset("stub-notepad-draft")
        assert obs["screenshot"]["png_base64"], "an inline screenshot"
        assert obs["a11y_xml"].startswith("<desktop"), obs["a11y_xml"][:80]
        assert "draft.txt" in obs["window_title"], obs["window_title"]
        obs, reward, done, info = env.step(["pyautogui.write('This is a draft.')", "pyautogui.hotkey('ctrl', 's')"])
        assert (reward, done, obs["step"]) == (0.0, False, 2), (reward, done, obs["step"])
        obs, reward, done, info = env.step("DONE")
        assert done and info["status"] == "completed", info
        assert env.evaluate() == reward
        scores["stub-notepad-draft"] = reward


def count():
    # Typed actions, with the task given as its id.
    with ArenaEnv(URL, observation={"screenshot": "none", "a11y": "none"}) as env:
        obs = env.reset("stub-notepad-count")
        assert "screenshot" not in obs and "a11y_xml" not in obs, sorted(obs)
        _, reward, done, _ = env.step(
            [{"type": "type_text", "text": "3"}, {"type": "hotkey", "keys": ["ctrl", "s"]}], action_space="typed"
        )
        assert not done
        _, reward, done, info = env.step("DONE", action_space="typed")
        assert done, info
        scores["stub-notepad-count"] = env.evaluate()


threads = [threading.Thread(target=f) for f in (draft, count)]
errors = []
for t in threads:
    t.start()
for t in threads:
    t.join()

# The client's errors name what was wrong.
with ArenaEnv(URL) as env:
    served = env.info()
    assert served["guests"] == 2 and served["free_guests"] == 2, served
    try:
        env.reset("no-such-task")
        raise SystemExit("an unknown task was accepted")
    except ArenaEnvError as err:
        assert err.status == 404 and "no-such-task" in err.message, err
    env.reset("stub-settings-infeasible")
    try:
        env.step("x", action_space="morse")
        raise SystemExit("an unknown action space was accepted")
    except ArenaEnvError as err:
        assert err.status == 400 and "morse" in err.message, err
    try:
        env.evaluate()
        raise SystemExit("a running episode was evaluated")
    except ArenaEnvError as err:
        assert err.status == 409, err
    _, reward, done, info = env.step("FAIL")
    scores["stub-settings-infeasible"] = reward
    try:
        env.step("DONE")
        raise SystemExit("an ended episode took a step")
    except ArenaEnvError as err:
        assert err.status == 409 and "ended" in err.message, err

print(json.dumps(scores, sort_keys=True))
