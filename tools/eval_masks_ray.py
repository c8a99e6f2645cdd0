"""``flowgap-eval-masks --ray``: each scene's viewpoint pairs as one Ray task (:mod:`tools.ray_sweep`).

A task declares ``--threads`` CPUs, builds the backends on its node (RAFT weights given with ``--raft-weights``
arrive through the object store and are written to the task's temporary folder, as is a scene's spec file),
evaluates its scene with :func:`tools.eval_masks.evaluate_scene` and returns the rows and the montage tile.
Rows come back in the order of the scenes, whatever order the tasks end in.
"""

from __future__ import annotations

import tempfile
from functools import partial
from pathlib import Path


def evaluate_scene_task(scene: str, files: dict[str, bytes] | None, quick: bool, backend_specs: list[str],
                        detectors: list[str], weights: tuple[str, bytes] | None, raft_iters: int | None,
                        threads: int, montage_backend: str) -> dict:
    """On a worker: one scene's rows, montage tile, skipped backends and the node it ran on."""
    import cv2

    from tools.eval_masks import build_backends, evaluate_scene, scene_viewpoints
    from tools.ray_sweep import materialise_scene, node_id

    cv2.setNumThreads(threads)
    with tempfile.TemporaryDirectory(prefix="flowgap-masks-") as tmp:
        path = materialise_scene(scene, files, Path(tmp) / "scene")
        weights_path = None
        if weights is not None:
            weights_path = Path(tmp) / Path(weights[0]).name
            if weights[1] is not None:             # (None: missing on the driver; the backend reports it)
                weights_path.write_bytes(weights[1])
        backends, skipped = build_backends(backend_specs, weights_path, raft_iters, threads)
        if weights is not None:                    # name the driver's file, not this task's copy
            skipped = {k: v.replace(str(weights_path), weights[0]) for k, v in skipped.items()}
        rows, tile = evaluate_scene(path, partial(scene_viewpoints, quick=quick), backends, backend_specs,
                                    detectors, montage_backend=montage_backend)
    return {"rows": rows, "tile": tile, "skipped": skipped, "node": node_id()}


def evaluate_on_ray(scenes_list: list[str], quick: bool, backend_specs: list[str], detectors: list[str], *,
                    raft_weights: Path | None = None, raft_iters: int | None = None, threads: int = 2,
                    montage_backend: str = "dis:medium", progress: bool = True):
    """(rows, skipped backends, montage rows, nodes) of the scenes on the Ray this process is connected to."""
    from tqdm import tqdm

    from tools.eval_masks import make_viewpoints
    from tools.ray_sweep import RayTasks, put, scene_payload

    weights = None
    if raft_weights is not None and Path(raft_weights).is_file():
        weights = put((str(raft_weights), Path(raft_weights).read_bytes()))
    elif raft_weights is not None:
        weights = (str(raft_weights), None)          # missing: each worker's backend reports it as skipped
    tasks = RayTasks(evaluate_scene_task, threads)
    for index, scene in enumerate(scenes_list):
        files = scene_payload(scene)
        tasks.submit(index, scene, put(files) if files else None, quick, list(backend_specs), list(detectors),
                     weights, raft_iters, threads, montage_backend)
    results: dict[int, dict] = {}
    per_scene = len(make_viewpoints(quick))
    with tqdm(total=len(scenes_list) * per_scene, desc="pairs", unit="pair", disable=not progress) as bar:
        for index, result in tasks.as_completed():
            results[index] = result
            bar.update(per_scene)
    rows, skipped, montage = [], {}, []
    for index in range(len(scenes_list)):
        rows += results[index]["rows"]
        skipped.update(results[index]["skipped"])
        if results[index]["tile"] is not None:
            montage.append(results[index]["tile"])
    return rows, skipped, montage, sorted({r["node"] for r in results.values()})
