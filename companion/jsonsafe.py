"""JSON-safe copies of nested results (shared by the companion's run logs and the tools' reports)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def json_safe(value: Any, digits: int | None = None) -> Any:
    """Copy of ``value`` that ``json.dumps`` writes as standard JSON: non-finite floats -> None (JSON has no
    NaN), numpy scalars -> Python numbers, tuples -> lists; floats rounded to ``digits`` (None: full
    precision)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        return value if digits is None else round(value, digits)
    if isinstance(value, dict):
        return {k: json_safe(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v, digits) for v in value]
    return value
