"""The stub tasks' oracle, reporting a fixed `usage` with every answer (the
cost ledger's test): 1000 input tokens of which 400 cached, 100 output tokens,
7 ms of model time per step."""

from oracle_agent import Oracle

USAGE = {"input_tokens": 1000, "output_tokens": 100, "cached_tokens": 400, "model_ms": 7}


class Metered(Oracle):
    name = "metered"

    def predict(self, obs):
        answer = super().predict(obs)
        answer["usage"] = dict(USAGE)
        return answer
