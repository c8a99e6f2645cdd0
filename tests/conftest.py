"""Shared pytest set-up: keep CPU-heavy libraries to a deliberate thread count on 2-core machines."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "2")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import logging  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _logging_as_it_was():
    """A CLI's main() run in a test configures logging (basicConfig, its own handlers) on the stderr that the
    test's capture provides; left in place, that handler writes to a closed stream in every later test (in
    random order, into another test's captured stderr).  Every logger is put back as it was after each test."""
    def state():
        loggers = {name: lg for name, lg in logging.Logger.manager.loggerDict.items() if isinstance(lg, logging.Logger)}
        loggers[""] = logging.getLogger()
        return loggers, {name: (lg.handlers[:], lg.level, lg.propagate) for name, lg in loggers.items()}

    _, before = state()
    yield
    loggers, _ = state()
    for name, lg in loggers.items():
        handlers, level, propagate = before.get(name, ([], logging.NOTSET, True))
        lg.handlers[:] = handlers
        lg.setLevel(level)
        lg.propagate = propagate
