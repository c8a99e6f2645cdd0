"""Ray as the engine of a sweep (``--ray [ADDRESS]`` of ``flowgap-eval-flights`` and ``flowgap-eval-masks``).

flowgap grows no scheduler of its own: each flight (or each scene's mask pairs) is one Ray task with its CPUs
declared, and Ray places it on any node. This module knows nothing of flights: it connects (:func:`ray_session`),
runs one remote function over many argument tuples and yields the results as they finish (:class:`RayTasks`),
and stops what is still running when the sweep is interrupted.

Where Ray runs:

- ``--ray local``: a Ray started for this sweep on this machine and stopped after it. Its token authentication
  stays on with a token of this run only, kept in the environment of its processes (nothing is written to
  ``~/.ray``), unless ``RAY_AUTH_MODE``/``RAY_AUTH_TOKEN``/``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``
  say otherwise. On Linux a local Ray listens on the machine's interface address, not on loopback; the tests
  run it in a loopback-only network namespace (:mod:`tools.loopback`).
- ``--ray auto`` (or a bare ``--ray``): the cluster in ``RAY_ADDRESS``, else the one started on this machine
  with ``ray start --head``; never a new one. ``--ray HOST:PORT``: that cluster. Its authentication is the
  cluster's (``RAY_AUTH_MODE=token`` and the head's token on every node and driver; docs/evaluation.md).

Workers need flowgap installed (``pip install -e '.[ray]'``, the same version everywhere); what a task needs
beyond the package (scene specs, weights) travels as task arguments or through the object store (:func:`put`),
never over a shared disk. A worker that Ray stops (cancel, shutdown) takes its child processes with it (Ray
kills a worker's children when it exits), so no flight process outlives its task.
"""

from __future__ import annotations

import logging
import math
import os
import secrets
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

log = logging.getLogger("flowgap.ray")

INSTALL_HINT = "pip install -e '.[ray]'"
CANCEL_WAIT_S = 30.0    # how long cancelled tasks get to stop their flights' processes before Ray is shut down


class RaySetupError(RuntimeError):
    """Ray cannot be used as asked: one line naming the problem and the fix."""


def add_ray_argument(parser, what: str = "flight") -> None:
    parser.add_argument(
        "--ray", nargs="?", const="auto", default=None, metavar="ADDRESS",
        help=f"run each {what} as a Ray task (extra: {INSTALL_HINT}): 'local' starts a Ray on this machine for this "
             "sweep; 'auto' (or no value) joins the cluster in RAY_ADDRESS or the one started here with "
             "'ray start --head'; HOST:PORT joins that cluster (default: no Ray, this machine's own pool)")


def require_ray() -> None:
    """Raise :class:`RaySetupError` unless Ray is installed; without importing it (:func:`ray_session` must set
    the authentication environment before Ray is first imported)."""
    import importlib.util

    if importlib.util.find_spec("ray") is None:
        raise RaySetupError(f"--ray needs Ray, which is not installed: {INSTALL_HINT}")


def import_ray():
    require_ray()
    import ray

    return ray


def _local_ray_environment() -> None:
    """The environment a local Ray of this run only inherits.

    Token authentication: on, with a fresh token in the environment, unless the user chose a mode or a token; so
    that nothing lands in ``~/.ray/auth_token``, where a head started later would demand it. Worker niceness 0
    (Ray's default is 15): a flight's vehicle and companion inherit it, and at 15 they ran 5x slower than the local
    pool's beside a training job on this 2-core machine (26-36 s against 5 s a flight)."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    os.environ.setdefault("RAY_worker_niceness", "0")
    if "RAY_AUTH_MODE" in os.environ:
        return
    os.environ["RAY_AUTH_MODE"] = "token"
    has_token = ("RAY_AUTH_TOKEN" in os.environ or "RAY_AUTH_TOKEN_PATH" in os.environ
                 or (Path.home() / ".ray" / "auth_token").exists())
    if not has_token:
        os.environ["RAY_AUTH_TOKEN"] = secrets.token_hex(32)


@contextmanager
def ray_session(address: str, local_cpus: float | None = None) -> Iterator[dict]:
    """Connect to Ray (``address``: 'local', 'auto' or HOST:PORT) for the ``with`` block; yields a description
    (``address``, ``nodes``, ``cpus``). A local Ray gets ``local_cpus`` logical CPUs (None: this machine's)."""
    check_address(address)
    if address == "local":
        if "ray" in sys.modules and "RAY_AUTH_MODE" not in os.environ:
            raise RaySetupError("Ray was imported before its local cluster's authentication was set: start the "
                                "sweep in a fresh process")
        _local_ray_environment()
    ray = import_ray()
    if ray.is_initialized():
        raise RaySetupError("Ray is already initialised in this process: one sweep per process")
    kwargs: dict = {"logging_level": logging.WARNING}
    if address == "local":
        kwargs.update(address="local", include_dashboard=False,
                      num_cpus=None if local_cpus is None else max(1, math.ceil(local_cpus)))
    else:
        kwargs.update(address=address)
    where = os.environ.get("RAY_ADDRESS", "") if address == "auto" else address
    start_a_head = ("start one with 'ray start --head --port 6379' and set RAY_ADDRESS=HOST:6379, or use "
                    "--ray local")
    if where not in ("", "local") and not _listening(where):
        raise RaySetupError(f"nothing listens at {where}{' (RAY_ADDRESS)' if address == 'auto' else ''}: "
                            f"{start_a_head}")
    t0 = time.monotonic()
    try:
        ray.init(**kwargs)
    except Exception as exc:  # noqa: BLE001 — connection, auth and version errors from Ray: one line
        if _mentions_auth(exc):
            raise RaySetupError(f"the Ray cluster at {where or address} refused this machine's token (or its lack "
                                f"of one): set RAY_AUTH_MODE=token and put the head's token in ~/.ray/auth_token or "
                                f"RAY_AUTH_TOKEN_PATH") from None
        if isinstance(exc, ConnectionError):
            raise RaySetupError(f"no Ray cluster at {where or address} ({_first_line(exc)}): {start_a_head}") from None
        raise RaySetupError(f"cannot start or join Ray at {address!r}: {_first_line(exc)}") from None
    try:
        alive = [n for n in ray.nodes() if n.get("Alive")]
        info = {"address": address, "nodes": len(alive), "start_s": round(time.monotonic() - t0, 1),
                "cpus": float(sum(n.get("Resources", {}).get("CPU", 0) for n in alive))}
        log.info("Ray: %s, %d nodes, %g CPUs", address, info["nodes"], info["cpus"])
        yield info
    finally:
        ray.shutdown()


def check_address(address: str) -> None:
    """Raise :class:`RaySetupError` unless ``address`` is 'local', 'auto', HOST:PORT or a ray:// address (a scene
    name right after a bare ``--ray`` lands here)."""
    host, _, port = address.rpartition(":")
    if address in ("local", "auto") or address.startswith("ray://") or (host and port.isdigit()):
        return
    raise RaySetupError(f"--ray {address}: not a Ray address (local, auto or HOST:PORT); a scene name goes before "
                        f"--ray, or after --ray auto")


def _listening(address: str) -> bool:
    """Whether something accepts TCP connections at HOST:PORT (Ray itself retries a silent address for minutes);
    other forms (ray://, a bare host) are left to Ray."""
    import socket

    host, _, port = address.rpartition(":")
    if "://" in address or not host or not port.isdigit():
        return True
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
        return True
    except OSError:
        return False


def _mentions_auth(exc: BaseException) -> bool:
    seen = 0
    while exc is not None and seen < 5:
        if "authtoken" in str(exc).lower().replace("_", "") or "authenticat" in str(exc).lower():
            return True
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return False


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def put(data: bytes):
    """Put ``data`` (a scene spec, a weights file) into the object store once; pass the reference to tasks."""
    return import_ray().put(data)


def scene_payload(scene: str) -> dict[str, bytes]:
    """The files a worker needs to load ``scene``, by name: none for a suite name (the package has it), the spec
    for a ``.json``, the splats and their spec for a ``.ply``."""
    from scenes import library

    if scene in library.NAMED:
        return {}
    path = Path(scene)
    paths = [path, path.with_suffix(".json")] if path.suffix == ".ply" else [path]
    return {p.name: p.read_bytes() for p in paths if p.exists()}


def materialise_scene(scene: str, payload: dict[str, bytes] | None, folder: Path) -> str:
    """On a worker: write ``scene``'s ``payload`` into ``folder``; what to load it by (its name when no files)."""
    if not payload:
        return scene
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in payload.items():
        (folder / name).write_bytes(data)
    return str(folder / Path(scene).name)


def node_id() -> str:
    """The Ray node this task runs on."""
    return import_ray().get_runtime_context().get_node_id()


class TaskFailed(RuntimeError):
    """A task raised; its key says which."""

    def __init__(self, key, exc: BaseException) -> None:
        cause = getattr(exc, "cause", None) or exc      # RayTaskError wraps the task's own exception
        super().__init__(f"{key}: {type(cause).__name__}: {_first_line(cause)}")
        self.key = key


class RayTasks:
    """Tasks of one function on the connected Ray, each declaring ``num_cpus``, yielded as they finish."""

    def __init__(self, fn: Callable, num_cpus: float) -> None:
        ray = import_ray()
        self._ray = ray
        self._remote = ray.remote(num_cpus=num_cpus)(fn)
        self._pending: dict = {}                     # ObjectRef -> key

    def submit(self, key, *args) -> None:
        self._pending[self._remote.remote(*args)] = key

    def as_completed(self) -> Iterator[tuple[object, object]]:
        """(key, result) as each task ends; whatever is still pending when this stops (a task raised, Ctrl-C, the
        consumer closed it) is cancelled."""
        try:
            while self._pending:
                done, _ = self._ray.wait(list(self._pending), num_returns=1)
                ref = done[0]
                key = self._pending.pop(ref)
                try:
                    result = self._ray.get(ref)
                except Exception as exc:  # noqa: BLE001 — re-raised with the task's key
                    raise TaskFailed(key, exc) from None
                yield key, result
        finally:
            self.cancel()

    def cancel(self, wait_s: float = CANCEL_WAIT_S) -> None:
        """Cancel what is pending: a running task gets a KeyboardInterrupt (``tools.launch`` then stops its
        flight's processes) and ``wait_s`` to end; one that does not end by then is killed with its worker."""
        refs = list(self._pending)
        self._pending.clear()
        if not refs:
            return
        log.warning("stopping: cancelling %d tasks", len(refs))
        for ref in refs:
            self._ray.cancel(ref, force=False)
        _, stuck = self._ray.wait(refs, num_returns=len(refs), timeout=wait_s)
        for ref in stuck:
            self._ray.cancel(ref, force=True)
        if stuck:
            log.warning("%d cancelled tasks did not stop within %.0f s; killed with their workers", len(stuck), wait_s)
