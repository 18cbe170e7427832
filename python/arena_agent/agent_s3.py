"""Agent S3 (Simular's ``gui-agents`` package) over the step protocol, unchanged.

``gui_agents.s3`` builds its agent from two models: the main (generation) model,
which writes one ``agent.click(...)``-style call a step, and the grounding model,
which answers the screen point of an element description; its ``OSWorldACI``
turns the call into pyautogui code in screen pixels. This module builds
``AgentS3`` and ``OSWorldACI`` exactly as Agent S's own command line and OSWorld
runner do (the same engine parameters, ``env=None``: no code agent), calls
``predict(instruction, obs)`` each step, and answers its pyautogui code in the
``pyautogui`` action space with ``coords`` ``pixels``. Its ``DONE``, ``FAIL`` and
``WAIT`` answers are decisions, as in OSWorld's runner.

Per task: a fresh ``OSWorldACI`` and ``AgentS3`` sized to the task's screen
(``reset``'s ``screen_width`` and ``screen_height``); the screenshot is sent at
the screen's own size, as OSWorld's ``DesktopEnv`` sends it. The step's
``response`` is the main model's plan and ``record`` carries the agent's info
dict (``plan``, ``plan_code``, ``exec_code``, ``reflection``, ...), the fields
OSWorld's runner writes in ``traj.jsonl``.

The command line takes Agent S's own options (``agent_s --help``)::

    arena run ... --agent exec --agent-cmd "python -m arena_agent.agent_s3 \\
        --provider openai --model gpt-5-2025-08-07 \\
        --ground_provider huggingface --ground_url http://localhost:8080 \\
        --ground_model ui-tars-1.5-7b --grounding_width 1920 --grounding_height 1080"

``gui_agents`` is imported when the first task starts, so ``--help`` works
without it; this module itself needs only the standard library.
"""

import argparse
import sys

from .adapters import json_fields, upstream_obs
from .protocol import DECISIONS, Agent, serve_http, serve_stdio


class AgentS3Adapter(Agent):
    """``gui_agents.s3.agents.agent_s.AgentS3`` behind the step protocol."""

    name = "AgentS3"
    action_space = "pyautogui"
    # OSWorldACI writes screen pixels (it scales the grounding model's answer itself).
    coords = "pixels"
    # Agent S3 looks at the screenshot only (a file for exec, inline over HTTP: the defaults).
    observation = {"a11y": "none", "windows": False, "clipboard": False}

    def __init__(
        self,
        engine_params,
        engine_params_for_grounding,
        platform="windows",
        max_trajectory_length=8,
        enable_reflection=True,
    ):
        self.engine_params = dict(engine_params)
        self.engine_params_for_grounding = dict(engine_params_for_grounding)
        self.platform = platform
        self.max_trajectory_length = max_trajectory_length
        self.enable_reflection = enable_reflection
        self.inner = None
        self.instruction = ""

    def reset(self, task):
        from gui_agents.s3.agents.agent_s import AgentS3
        from gui_agents.s3.agents.grounding import OSWorldACI

        self.instruction = task.get("instruction", "")
        grounding = OSWorldACI(
            env=None,
            platform=self.platform,
            engine_params_for_generation=self.engine_params,
            engine_params_for_grounding=self.engine_params_for_grounding,
            width=task["screen_width"],
            height=task["screen_height"],
        )
        self.inner = AgentS3(
            self.engine_params,
            grounding,
            platform=self.platform,
            max_trajectory_length=self.max_trajectory_length,
            enable_reflection=self.enable_reflection,
        )

    def predict(self, obs):
        if self.inner is None:
            raise RuntimeError("observe before reset")
        info, actions = self.inner.predict(obs.get("instruction", self.instruction), upstream_obs(obs))
        info = info or {}
        answer = {"response": str(info.get("plan") or ""), "record": json_fields(info)}
        codes = [a for a in actions or [] if isinstance(a, str) and a.strip()]
        decisions = [a.strip() for a in codes if a.strip() in DECISIONS]
        if decisions:
            answer["decision"] = decisions[-1]
        answer["actions"] = [a for a in codes if a.strip() not in DECISIONS]
        return answer


def build_parser():
    parser = argparse.ArgumentParser(
        prog="python -m arena_agent.agent_s3",
        description="Serve Agent S3 (gui-agents) over the arena step protocol; the options are Agent S's own.",
    )
    main = parser.add_argument_group("main (generation) model")
    main.add_argument("--provider", default="openai", help="engine_type of the main model (openai, anthropic, ...)")
    main.add_argument("--model", default="gpt-5-2025-08-07")
    main.add_argument("--model_url", default="", help="base URL of the main model's API")
    main.add_argument("--model_api_key", default="", help="else the provider's variable (OPENAI_API_KEY, ...)")
    main.add_argument("--model_temperature", type=float, default=None)
    ground = parser.add_argument_group("grounding model")
    ground.add_argument("--ground_provider", required=True, help="engine_type of the grounding model (huggingface, vllm, ...)")
    ground.add_argument("--ground_url", required=True)
    ground.add_argument("--ground_api_key", default="")
    ground.add_argument("--ground_model", required=True)
    ground.add_argument("--grounding_width", type=int, required=True, help="width of the grounding model's coordinates")
    ground.add_argument("--grounding_height", type=int, required=True, help="height of the grounding model's coordinates")
    agent = parser.add_argument_group("agent")
    agent.add_argument("--max_trajectory_length", type=int, default=8)
    agent.add_argument(
        "--no_reflection", action="store_true", help="turn the reflection agent off (Agent S's default is on)"
    )
    agent.add_argument("--platform", default="windows", choices=["windows", "linux", "darwin"])
    parser.add_argument("--http", metavar="HOST:PORT", help="serve HTTP (--agent http) instead of stdin/stdout")
    return parser


def from_args(args):
    engine_params = {
        "engine_type": args.provider,
        "model": args.model,
        "base_url": args.model_url,
        "api_key": args.model_api_key,
        "temperature": args.model_temperature,
    }
    engine_params_for_grounding = {
        "engine_type": args.ground_provider,
        "model": args.ground_model,
        "base_url": args.ground_url,
        "api_key": args.ground_api_key,
        "grounding_width": args.grounding_width,
        "grounding_height": args.grounding_height,
    }
    return AgentS3Adapter(
        engine_params,
        engine_params_for_grounding,
        platform=args.platform,
        max_trajectory_length=args.max_trajectory_length,
        enable_reflection=not args.no_reflection,
    )


def main(argv=None):
    args = build_parser().parse_args(argv)
    if args.http:
        host, _, port = args.http.rpartition(":")

        def announce(address):
            print(f"arena_agent.agent_s3: listening on http://{address[0]}:{address[1]}/", file=sys.stderr, flush=True)

        serve_http(lambda: from_args(args), host or "127.0.0.1", int(port), ready=announce)
    else:
        serve_stdio(from_args(args))


if __name__ == "__main__":
    main()
