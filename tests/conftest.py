"""Shared pytest set-up: keep CPU-heavy libraries to a deliberate thread count on 2-core machines."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "2")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import logging  # noqa: E402
import signal  # noqa: E402

import pytest  # noqa: E402

try:  # hypothesis is in the dev extra; without it the fuzz tests skip themselves (pytest.importorskip)
    from hypothesis import HealthCheck, settings
except ImportError:  # pragma: no cover
    settings = None
if settings is not None:
    # The fuzz tests' profiles (docs/testing.md): "ci", the default, is the same examples on every run so a
    # failure in CI is a failure on every machine; HYPOTHESIS_PROFILE=deep (or FLOWGAP_FUZZ=deep) draws fresh
    # ones, many more (support.fuzzing scales each budget). No deadline: a loaded 2-core machine runs slow.
    # No example database: nothing written into the checkout; a failure prints the example to reproduce.
    settings.register_profile("ci", deadline=None, derandomize=True, database=None, print_blob=True,
                              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    settings.register_profile("deep", settings.get_profile("ci"), derandomize=False)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE")
                          or ("deep" if os.environ.get("FLOWGAP_FUZZ") == "deep" else "ci"))


# A suite started in the background by a non-interactive shell (`cmd &` in a script, nohup) inherits SIGINT
# ignored, and every process it starts would too; the Ctrl-C tests (flowgap-sitl, a stopped sweep, the Rerun
# viewer) send SIGINT and need it delivered, as from a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


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
