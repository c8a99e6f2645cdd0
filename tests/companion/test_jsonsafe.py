"""json_safe: what run logs and tlog reports write is standard JSON (no NaN), with numpy scalars as numbers."""

import json
import math

import numpy as np

from companion.jsonsafe import json_safe


def test_json_safe_replaces_non_finite_floats_converts_numpy_and_rounds_on_request():
    record = {"a": math.nan, "b": (np.float32(1.25), np.int64(3), -math.inf), "c": [{"d": np.float64(0.123456789)}],
              "e": "text", "f": None, "g": True}
    safe = json_safe(record)
    assert safe == {"a": None, "b": [1.25, 3, None], "c": [{"d": 0.123456789}], "e": "text", "f": None, "g": True}
    assert isinstance(safe["b"][1], int) and isinstance(safe["c"][0]["d"], float)
    json.loads(json.dumps(safe, allow_nan=False))  # standard JSON
    assert json_safe(record, digits=3)["c"][0]["d"] == 0.123
    assert json_safe(np.float32(math.nan)) is None
