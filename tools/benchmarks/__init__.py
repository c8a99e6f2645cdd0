"""Benchmark groups: one module per group, each with ``run() -> {key: {"value", "unit"}}``."""
