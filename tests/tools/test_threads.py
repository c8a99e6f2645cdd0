"""Flights flown side by side hold their processes' numeric libraries to their share of the CPUs."""

import sys

from tools.threads import THREAD_VARIABLES, available_cpus, flight_threads, thread_env


def test_every_library_is_held_to_the_threads_given_and_a_variable_the_user_set_is_kept():
    assert thread_env(1) == {name: "1" for name in THREAD_VARIABLES}
    assert {"OMP_NUM_THREADS", "NUMBA_NUM_THREADS"} <= set(THREAD_VARIABLES)
    env = thread_env(3, {"OMP_NUM_THREADS": "8", "PATH": "/bin"})
    assert env["OMP_NUM_THREADS"] == "8" and env["NUMBA_NUM_THREADS"] == "3" and "PATH" not in env


def test_each_flight_gets_its_share_of_the_cpus_and_never_none():
    assert flight_threads(2, cpus=2) == 1
    assert flight_threads(2, cpus=8) == 4
    assert flight_threads(1, cpus=2) == 2
    assert flight_threads(3, cpus=2) == 1 and flight_threads(0, cpus=4) == 4
    assert available_cpus() >= 1 and flight_threads(1) == available_cpus()


def test_a_flight_process_starts_with_the_environment_it_is_given():
    from tools.launch import _start, _stop

    code = "import os; print(os.environ.get('OMP_NUM_THREADS'), os.environ.get('NUMBA_NUM_THREADS'))"
    proc = _start([sys.executable, "-c", code], "[test]", None, {"PATH": "/usr/bin:/bin", **thread_env(1)})
    proc.wait(timeout=30)
    _stop(proc)                                 # (ended: only forgotten)
    proc.pump.join(timeout=5)
    assert list(proc.tail) == ["1 1"]
