"""Shared pytest set-up: keep CPU-heavy libraries to a deliberate thread count on 2-core machines."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "2")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")
