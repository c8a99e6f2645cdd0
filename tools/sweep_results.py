"""A sweep's result files and its resumption: one JSON file per flight under ``OUT/results``.

Each file holds the flight's judged row and the sweep settings it was flown with (``{"sweep": ..., "row": ...}``),
written as soon as the flight ends, atomically (a stopped sweep leaves whole files or none). With ``resume``,
:func:`run_sweep` reuses every file of a planned flight and flies only the rest; a file flown with other settings
is an error, never silently mixed in. Without it, the results of an earlier sweep in the same folder are cleared.
``OUT/sweep_runs.jsonl`` records each run's wall time, so that a resumed sweep reports the time of all its runs.
A flight that ends after the sweep was interrupted (Ctrl-C) is never saved: its processes may have had the
signal too.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from tqdm import tqdm

log = logging.getLogger("flowgap.sweep")

RESULTS = "results"
RUNS = "sweep_runs.jsonl"   # one line per run of the sweep (the first and each --resume): its wall time and end


class ResumeError(ValueError):
    """A result file that cannot be merged into this sweep (flown with other settings)."""


class SweepInterrupted(RuntimeError):
    """Ctrl-C during a sweep; what was saved stays for ``--resume``."""

    def __init__(self, out: Path, saved: int, missing: int) -> None:
        super().__init__(f"interrupted: {saved} flights of this run saved under {out / RESULTS}; rerun the same "
                         f"command with --resume to fly the {missing} missing")
        self.saved, self.missing = saved, missing


class Job(Protocol):
    key: str        # the flight's file name stem: "<scene>-<start index>"


class Executor(Protocol):
    def run(self, jobs: list) -> Iterator[tuple[object, dict]]:
        """Fly ``jobs``; yield (job, launch verdict) as each ends; stop what is running when closed."""


@dataclass
class SweepOutcome:
    rows: list[dict]     # the planned flights' rows, reused or flown, in the order of the jobs
    reused: int
    flown: int
    missing: list[str]   # keys of flights stopped before they ended (a task cancelled from outside): none of them


def result_path(out: Path, key: str) -> Path:
    return out / RESULTS / f"{key}.json"


def write_result(out: Path, key: str, row: dict, settings: dict) -> Path:
    """Write one flight's row with the settings it was flown with; atomic (temporary file, then rename)."""
    path = result_path(out, key)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.part")
    tmp.write_text(json.dumps({"sweep": settings, "row": row}, indent=1) + "\n")
    os.replace(tmp, path)
    return path


def record_run(out: Path, wall_s: float, flown: int | None, ended: str) -> None:
    """Add one run of the sweep in ``out`` to its record (``ended``: "complete", "stopped" (flights left to fly),
    "interrupted", "failed")."""
    out.mkdir(parents=True, exist_ok=True)
    with (out / RUNS).open("a") as f:
        f.write(json.dumps({"wall_s": round(wall_s, 1), "flown": flown, "ended": ended}) + "\n")


def recorded_runs(out: Path) -> list[dict]:
    """The runs of the sweep in ``out`` recorded so far (a line that cannot be read is left out, with a warning:
    a run killed outright leaves none, so the record is a lower bound)."""
    runs = []
    path = out / RUNS
    for n, line in enumerate(path.read_text().splitlines() if path.is_file() else [], start=1):
        try:
            run = json.loads(line)
            runs.append({"wall_s": float(run["wall_s"]), "flown": run.get("flown"), "ended": str(run["ended"])})
        except (ValueError, KeyError, TypeError):
            log.warning("%s line %d is not a run record; left out of the sweep's wall time", path, n)
    return runs


def clear_results(out: Path) -> int:
    """Remove an earlier sweep's result files (and the record of its runs) from ``out``; how many results."""
    (out / RUNS).unlink(missing_ok=True)
    folder = out / RESULTS
    gone = 0
    for path in [*folder.glob("*.json"), *folder.glob("*.json.part")] if folder.is_dir() else []:
        path.unlink()
        gone += 1
    return gone


def load_results(out: Path, keys: Iterable[str], settings: dict) -> dict[str, dict]:
    """The rows of ``keys`` already flown under ``out`` with these ``settings`` (a key without a file, or with an
    unreadable one, is missing). Raises :class:`ResumeError` for a file flown with other settings."""
    want = json.loads(json.dumps(settings))        # compared as they read back from JSON (tuples become lists)
    found = {}
    for key in keys:
        path = result_path(out, key)
        if not path.exists():
            continue
        try:
            saved = json.loads(path.read_text())
            row, theirs = saved["row"], saved["sweep"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("%s is unreadable (%s): flying it again", path, exc)
            continue
        for name in sorted(set(want) | set(theirs)):
            if want.get(name) != theirs.get(name):
                raise ResumeError(f"{path} was flown with {name} {theirs.get(name)!r}, this sweep has "
                                  f"{want.get(name)!r}: resume with the same settings, run without --resume to "
                                  f"fly everything again, or choose another --out")
        found[key] = row
    return found


def interrupted_flight(verdict: dict) -> bool:
    """Whether launch stopped this flight on a Ctrl-C (it is no result)."""
    return str(verdict.get("error", "")).startswith("interrupted")


def run_sweep(jobs: list, executor: Executor, make_row: Callable[[object, dict], dict], out: Path, settings: dict,
              resume: bool = False, progress: bool = True) -> SweepOutcome:
    """Fly ``jobs`` (each with a unique ``key``) on ``executor``, saving each row as it ends; with ``resume``, reuse
    what ``out`` already holds. ``make_row(job, verdict)`` turns a verdict into the row saved.
    Raises :class:`ResumeError`, :class:`SweepInterrupted` (Ctrl-C), or whatever a flight raised."""
    if resume:
        done = load_results(out, [job.key for job in jobs], settings)
    else:
        cleared = clear_results(out)
        if cleared:
            log.info("cleared %d result files of an earlier sweep in %s", cleared, out)
        done = {}
    reused = len(done)
    todo = [job for job in jobs if job.key not in done]
    bar = tqdm(total=len(jobs), initial=reused, desc="flights", unit="flight", disable=not progress)
    if reused:
        bar.set_postfix_str(f"{reused} reused")
    flown = 0
    try:
        with closing(executor.run(todo)) as stream:
            for job, verdict in stream:
                if interrupted_flight(verdict):
                    continue
                row = make_row(job, verdict)
                write_result(out, job.key, row, settings)
                done[job.key] = row
                flown += 1
                bar.update(1)
    except KeyboardInterrupt:
        raise SweepInterrupted(out, flown, len(todo) - flown) from None
    finally:
        bar.close()
    return SweepOutcome([done[job.key] for job in jobs if job.key in done], reused, flown,
                        [job.key for job in jobs if job.key not in done])
