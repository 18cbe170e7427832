"""Runs ByteDance's published UI-TARS parser (the ``ui-tars`` package) over a corpus.

    python package.py corpus.json

For each entry (``id``, ``version`` ``1.0`` or ``1.5``, ``screen`` ``[width,
height]``, ``reply``) it calls ``ui_tars.action_parser.parse_action_to_structure_output``
and ``parsing_response_to_pyautogui_code`` the way the package's README shows
(``factor=1000``; ``model_type`` ``qwen25vl`` for UI-TARS-1.5, ``qwen2vl`` for
1.0; the screenshot's size as the original size; ``input_swap=True``) and prints
one JSON line: ``{"id", "code", "thought", "reflection"}`` or ``{"id", "error"}``.
The first line is ``{"version": ...}``, the package's version.

Since 0.4 ``parsing_response_to_pyautogui_code`` takes ``scale_factor`` (default
1000), by which it divides the structured output's coordinates, which
``parse_action_to_structure_output`` gives as fractions of the image; it is
passed as 1 so that the code is in screen pixels, as before 0.4 and as the
README's example expects.
"""

import contextlib
import importlib.metadata
import inspect
import json
import sys

from ui_tars import action_parser


def run(entry):
    width, height = entry["screen"]
    model_type = "qwen25vl" if entry["version"] == "1.5" else "qwen2vl"
    # The package prints its own diagnostics; they must not mix with the answers.
    with contextlib.redirect_stdout(sys.stderr):
        structure = action_parser.parse_action_to_structure_output(
            entry["reply"],
            factor=1000,
            origin_resized_height=height,
            origin_resized_width=width,
            model_type=model_type,
        )
        extra = {}
        if "scale_factor" in inspect.signature(action_parser.parsing_response_to_pyautogui_code).parameters:
            extra["scale_factor"] = 1
        code = action_parser.parsing_response_to_pyautogui_code(
            structure, image_height=height, image_width=width, input_swap=True, **extra
        )
    first = structure[0] if structure else {}
    return {"code": code, "thought": first.get("thought"), "reflection": first.get("reflection")}


def main():
    with open(sys.argv[1], encoding="utf-8") as f:
        corpus = json.load(f)
    print(json.dumps({"version": importlib.metadata.version("ui-tars")}))
    for entry in corpus["entries"]:
        try:
            answer = run(entry)
        except Exception as err:  # noqa: BLE001 - any failure of the package is an answer
            answer = {"error": f"{type(err).__name__}: {err}"}
        answer["id"] = entry["id"]
        print(json.dumps(answer))


if __name__ == "__main__":
    main()
