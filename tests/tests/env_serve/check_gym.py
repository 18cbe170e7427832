"""gymnasium's own env checker on ArenaGymEnv, then one episode through it.
Run by tests/tests/env_serve.rs with a Python that has gymnasium, numpy and Pillow."""

import sys

from gymnasium.utils.env_checker import check_env

from arena_agent.gym_env import ArenaGymEnv

env = ArenaGymEnv(sys.argv[1], "stub-notepad-draft")
check_env(env, skip_render_check=True)
obs, info = env.reset()
assert obs["screenshot"].shape == env.observation_space["screenshot"].shape, obs["screenshot"].shape
assert "draft.txt" in info["window_title"], info
obs, reward, terminated, truncated, info = env.step("pyautogui.write('This is a draft.'); pyautogui.hotkey('ctrl', 's')")
assert (reward, terminated, truncated) == (0.0, False, False)
obs, reward, terminated, truncated, info = env.step("DONE")
assert terminated and reward == 1.0, (reward, info)
env.close()
print("gym ok", reward)
