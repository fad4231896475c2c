"""json_text.strict_json: JSON that strict parsers accept, whatever NaN the data holds."""

from __future__ import annotations

import json

import numpy as np

from physpose.json_text import strict_json


def _strict_load(text: str):
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")
    return json.loads(text, parse_constant=refuse)


def test_non_finite_numbers_become_null_at_any_depth():
    doc = {"a": float("nan"), "b": [1.0, float("inf"), {"c": -float("inf")}],
           "d": np.float32("nan"), "e": np.array([[0.5, np.nan]]), "f": np.int64(3),
           "g": (2, None, "x")}
    assert _strict_load(strict_json(doc)) == {
        "a": None, "b": [1.0, None, {"c": None}], "d": None, "e": [[0.5, None]], "f": 3,
        "g": [2, None, "x"]}


def test_dumps_options_pass_through():
    assert strict_json({"a": [1, 2]}, separators=(",", ":")) == '{"a":[1,2]}'
