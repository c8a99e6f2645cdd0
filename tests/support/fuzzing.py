"""Budgets for the hypothesis fuzz tests: small and fixed in ``make test``, large in a deep run.

A deep run is HYPOTHESIS_PROFILE=deep (or FLOWGAP_FUZZ=deep, the switch the MAVLink-edge fuzz tests read);
the profiles themselves (derandomised, no deadline) are registered in tests/conftest.py. A test asks here for
its number of examples so that its default cost stays inside the suite's fuzzing budget (docs/testing.md).
"""

from __future__ import annotations

import os

DEEP = os.environ.get("HYPOTHESIS_PROFILE") == "deep" or os.environ.get("FLOWGAP_FUZZ") == "deep"
DEEP_FACTOR = 50  # a deep run: 50 times each test's default examples, freshly drawn (as the MAVLink fuzz tests)


def fuzz_examples(default: int) -> int:
    """How many examples a fuzz test runs: ``default`` in the ci profile, DEEP_FACTOR times more when deep."""
    return default * DEEP_FACTOR if DEEP else default
