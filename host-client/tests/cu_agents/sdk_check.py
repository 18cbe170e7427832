"""Checks request bodies the computer-use agents sent against the vendors' own SDK types.

Reads, on stdin, a JSON list of {"api": API, "body": BODY} and prints one line per
problem (nothing when every body is what the SDK types allow); exits 1 on a problem.
API is one of:

- "anthropic":      anthropic.types.message_create_params.MessageCreateParamsNonStreaming
- "anthropic-beta": anthropic.types.beta.message_create_params.MessageCreateParamsNonStreaming
- "openai":         openai.types.responses.response_create_params.ResponseCreateParamsNonStreaming

The strict comparison (required fields, no field the type lacks, literal tags,
unions by shape) is the one the Agent S3 mock models use: it is imported from
examples/agent_s3/mock_models.py, whose path is the first argument.
"""

import importlib.util
import json
import sys

from anthropic.types import message_create_params as anthropic_params
from anthropic.types.beta import message_create_params as anthropic_beta_params
from openai.types.responses import response_create_params as openai_params

TYPES = {
    "anthropic": anthropic_params.MessageCreateParamsNonStreaming,
    "anthropic-beta": anthropic_beta_params.MessageCreateParamsNonStreaming,
    "openai": openai_params.ResponseCreateParamsNonStreaming,
}


def main():
    spec = importlib.util.spec_from_file_location("mock_models", sys.argv[1])
    checker = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(checker)
    found = []
    for n, item in enumerate(json.load(sys.stdin)):
        found += checker.problems(item["body"], TYPES[item["api"]], f"request {n} ({item['api']})")
    for line in found:
        print(line)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
