"""Where a sweep's flights fly: this machine's pool, or Ray tasks on any node of a cluster.

Both executors yield ``(job, verdict)`` as flights end, so the progress bar, the result files and ``--resume``
(:mod:`tools.sweep_results`) are the same for both; and both fly a flight the same way (:func:`fly`): on a PX4
instance of its own, taken from an :class:`~tools.eval_flights.InstancePool`, whose file locks keep any two
flights on one node, of one sweep or of two, off each other's ports.

- :class:`LocalFlights`: ``--jobs`` threads on this machine, run directories under ``--out`` (as ever).
- :class:`RayFlights`: one Ray task per flight, declaring ``--cpus-per-flight`` CPUs (vehicle and companion).
  A task gets its scene's files (a spec ``.json``; a ``.ply`` with its ``.json``) from the object store, writes
  them and flies in a temporary folder of its node, and sends the flight's run directory back as a tar, which
  the driver unpacks under ``--out`` where the local pool would have written it.

A flight's draws come with its job (:func:`tools.eval_flights.draw_flight`), made before any flight starts, so
they never depend on the node or the order flights run in.
"""

from __future__ import annotations

import io
import json
import logging
import shutil
import socket
import tarfile
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from companion.flow.registry import DEFAULT_FLOW
from tools.eval_flights import InstancePool
from tools.launch import launch
from tools.link_faults import LinkFaults

log = logging.getLogger("flowgap.sweep")


class FlightFailed(RuntimeError):
    """A flight raised (a bug, not a failed flight: those are verdicts)."""


@dataclass(frozen=True)
class FlightSettings:
    """What every flight of a sweep shares."""

    flow: str = DEFAULT_FLOW
    detector: str = "parallax"
    edges: str = "photo"        # flowgap-companion --edges
    thickness_look: bool = True  # False: flowgap-companion --no-thickness-look
    lockstep: bool = True
    speed: float = 2.0          # with lockstep False only
    latency_s: float = 0.0
    threads: int | None = None  # each flight's processes' threads per library (tools.threads); None: as many as cores


@dataclass(frozen=True)
class FlightJob:
    """One planned flight: its scene, its start index and the draws made for it."""

    scene: str                  # a suite name, or a spec path on the driver's machine
    label: str                  # the scene's name, as rows report it
    start_index: int
    flight: dict                # tools.eval_flights.draw_flight: start, altitude, seed, wind, camera_delay_s
    link_faults: LinkFaults | None = None

    @property
    def key(self) -> str:
        """Its run directory's and result file's name."""
        return f"{self.label}-{self.start_index}"


def fly(job: FlightJob, settings: FlightSettings, scene: str, run_dir: Path, instances: InstancePool) -> dict:
    """Fly one flight on this node on an instance of ``instances``; launch's verdict plus ``instance``, ``host``
    and the wall-clock span the instance was held (``flight_started``, ``flight_ended``, Unix seconds)."""
    if run_dir.exists():
        # an earlier flight's files (a sweep flown again into the same --out, or a row deleted and --resumed)
        # would otherwise stay beside this flight's, its step images and logs mistaken for this one's
        shutil.rmtree(run_dir)
    instance = instances.acquire()
    started = time.time()
    try:
        verdict = launch(scene, run_dir, job.flight["start"], settings.speed, instance, settings.flow,
                         settings.detector, seed=job.flight["seed"], images=False, log_sink=None,
                         altitude=job.flight["altitude"], lockstep=settings.lockstep, latency_s=settings.latency_s,
                         wind=job.flight["wind"], camera_delay_s=job.flight["camera_delay_s"],
                         link_faults=job.link_faults, edges=settings.edges, threads=settings.threads,
                         thickness_look=settings.thickness_look)
    finally:
        ended = time.time()
        instances.release(instance)
    return {**verdict, "instance": instance, "host": socket.gethostname(), "flight_started": round(started, 3),
            "flight_ended": round(ended, 3)}


class LocalFlights:
    """``jobs_at_once`` flights at a time in threads on this machine; run directories ``OUT/<scene>-<start>``."""

    name = "local"

    def __init__(self, settings: FlightSettings, out: Path, jobs_at_once: int) -> None:
        self.settings, self.out, self.jobs_at_once = settings, out, jobs_at_once

    def run(self, jobs: list[FlightJob]) -> Iterator[tuple[FlightJob, dict]]:
        instances = InstancePool()
        host = socket.gethostname()
        pool = ThreadPoolExecutor(max_workers=self.jobs_at_once)
        futures: dict = {}
        try:
            futures = {pool.submit(fly, job, self.settings, job.scene, self.out / job.key, instances): job
                       for job in jobs}
            for future in as_completed(futures):
                job = futures[future]
                try:
                    verdict = future.result()
                except Exception as exc:  # noqa: BLE001 — re-raised with the flight's name
                    raise FlightFailed(f"{job.key}: {type(exc).__name__}: {exc}") from exc
                yield job, {**verdict, "node": host}
        except BaseException:
            running = sum(f.running() for f in futures)
            if running:
                log.warning("stopping: %d flights in progress end first (their results are not kept)", running)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)     # flights in progress end; queued ones never start


def fly_as_ray_task(job: FlightJob, settings: FlightSettings, files: dict[str, bytes] | None) -> dict:
    """A Ray task: write the scene's ``files`` and fly in a temporary folder of this node; the verdict (with
    ``node``, the Ray node id) and the run directory as a tar."""
    from tools.ray_sweep import materialise_scene, node_id

    with tempfile.TemporaryDirectory(prefix="flowgap-flight-") as tmp:
        scene = materialise_scene(job.scene, files, Path(tmp) / "scene")
        run_dir = Path(tmp) / job.key
        verdict = fly(job, settings, scene, run_dir, InstancePool())
        return {"verdict": {**verdict, "node": node_id()}, "run_dir": pack_dir(run_dir)}


class RayFlights:
    """One Ray task per flight, ``cpus_per_flight`` CPUs each, on the Ray this process is connected to."""

    name = "ray"

    def __init__(self, settings: FlightSettings, out: Path, cpus_per_flight: float) -> None:
        self.settings, self.out, self.cpus_per_flight = settings, out, cpus_per_flight

    def run(self, jobs: list[FlightJob]) -> Iterator[tuple[FlightJob, dict]]:
        from tools.ray_sweep import RayTasks, TaskFailed, put, scene_payload

        tasks = RayTasks(fly_as_ray_task, self.cpus_per_flight)
        shipped: dict[str, object] = {}            # scene -> object-store reference of its files, put once
        for job in jobs:
            if job.scene not in shipped:
                files = scene_payload(job.scene)
                shipped[job.scene] = put(files) if files else None
            tasks.submit(job, job, self.settings, shipped[job.scene])
        try:
            for job, result in tasks.as_completed():
                yield job, self._unpack(job, result)
        except TaskFailed as exc:
            raise FlightFailed(str(exc)) from None

    def _unpack(self, job: FlightJob, result: dict) -> dict:
        """The task's run directory under ``OUT/<key>``, and the verdict's paths pointing there."""
        run_dir = self.out / job.key
        if run_dir.exists():
            shutil.rmtree(run_dir)
        unpack_dir(result["run_dir"], run_dir)
        verdict = relocate(result["verdict"], run_dir)
        saved = run_dir / "verdict.json"
        if saved.exists():
            saved.write_text(json.dumps(relocate(json.loads(saved.read_text()), run_dir), indent=2) + "\n")
        return verdict


def relocate(verdict: dict, run_dir: Path) -> dict:
    """``verdict`` with the paths under its worker's run directory moved to ``run_dir``."""
    old = str(verdict.get("run_dir", ""))
    out = dict(verdict)
    for key in ("run_dir", "storyboard", "rerun"):
        value = out.get(key)
        if old and isinstance(value, str) and value.startswith(old):
            out[key] = str(run_dir) + value[len(old):]
    return out


def pack_dir(folder: Path) -> bytes:
    """A folder as an uncompressed tar (its images are compressed already)."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        if folder.exists():
            tar.add(folder, arcname=".")
    return buffer.getvalue()


def unpack_dir(data: bytes, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        if hasattr(tarfile, "data_filter"):
            tar.extractall(folder, filter="data")
        else:  # pragma: no cover — Pythons before the extraction filters
            tar.extractall(folder)  # noqa: S202 — our own workers' run directories
