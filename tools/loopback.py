"""Run a command whose network is loopback only: a new network namespace with just ``lo`` up.

On Linux a local Ray listens on the machine's interface address, not on loopback (``--node-ip-address=127.0.0.1``
does not change that); inside a namespace whose only interface is ``lo`` it uses 127.0.0.1. The tests and the
benchmark that start Ray run it this way (``unshare -n``, or ``unshare -rn`` where a user without root may create
user namespaces), so that none of its traffic goes anywhere but 127.0.0.1. Only the network is private: files,
``/tmp`` (and the instance locks of ``tools.eval_flights.InstancePool`` in it) and processes are shared.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess

_UP_AND_EXEC = 'ip link set lo up && exec "$@"'


@functools.cache
def _prefix() -> tuple[tuple[str, ...] | None, str]:
    """(the ``unshare`` prefix that works here, or None; why not)."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return None, "needs the unshare and ip commands (util-linux, iproute2)"
    candidates = [("unshare", "-n")] if os.geteuid() == 0 else []
    candidates.append(("unshare", "-r", "-n"))
    why = ""
    for prefix in candidates:
        probe = subprocess.run([*prefix, "sh", "-c", _UP_AND_EXEC, "sh", "true"], capture_output=True, text=True,
                               timeout=30)
        if probe.returncode == 0:
            return prefix, ""
        why = (probe.stderr.strip().splitlines() or [f"exit {probe.returncode}"])[-1]
    return None, f"cannot create a network namespace here ({why})"


def unavailable() -> str | None:
    """Why a loopback-only namespace cannot be made here, or None when it can."""
    return _prefix()[1] or None


def loopback_command(argv: list[str]) -> list[str]:
    """``argv`` run in a fresh loopback-only network namespace (check :func:`unavailable` first)."""
    prefix, why = _prefix()
    if prefix is None:
        raise RuntimeError(f"no loopback-only namespace: {why}")
    return [*prefix, "sh", "-c", _UP_AND_EXEC, "sh", *argv]
