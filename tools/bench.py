"""Benchmark runner: ``python -m tools.bench [GROUP ...]`` (console ``flowgap-bench``).

Each module in ``tools/benchmarks/`` is one group (``vehicle``, ``scenes``, ``tlog``, ...) and exposes
``run() -> dict[str, dict]`` mapping a key such as ``vehicle.steps_per_s`` to ``{"value": x, "unit": u}``.
Results are merged into ``bench/results.json`` so that one group can be re-run alone without losing the
others; a key that a re-run no longer writes is dropped once every group writing under its prefix has run
(a renamed benchmark leaves no stale number behind). Each benchmark measures the median of several runs
itself.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import pkgutil
import platform
import sys
import time
from pathlib import Path

import tools.benchmarks as benchmarks_pkg

log = logging.getLogger(__name__)
RESULTS = Path(__file__).resolve().parent.parent / "bench" / "results.json"


def available_groups() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(benchmarks_pkg.__path__) if not m.name.startswith("_"))


def key_prefix(group: str) -> str:
    """The first word of a group's keys: group "vehicle_link" writes "vehicle.*" keys."""
    return group.split("_")[0]


def rerun_prefixes(groups: list[str]) -> set[str]:
    """The key prefixes that running ``groups`` rewrites wholly: those of which every group ran."""
    return {key_prefix(g) for g in groups} - {key_prefix(g) for g in available_groups() if g not in groups}


def run_groups(groups: list[str]) -> dict[str, dict]:
    results: dict[str, dict] = {}
    for group in groups:
        module = importlib.import_module(f"tools.benchmarks.{group}")
        t0 = time.perf_counter()
        out = module.run()
        for key, entry in out.items():
            # A group's keys live under its first word: group "vehicle_link" may write "vehicle.*".
            if key.split(".")[0] != key_prefix(group) or not {"value", "unit"} <= set(entry):
                raise ValueError(f"benchmark group {group!r} returned malformed entry {key!r}: {entry!r}")
        results.update(out)
        log.info("%s done in %.1f s", group, time.perf_counter() - t0)
    return results


def merge_results(new: dict[str, dict], path: Path = RESULTS,
                  rerun_prefixes: set[str] = frozenset()) -> dict[str, dict]:
    """Merge ``new`` into the results file; old keys under ``rerun_prefixes`` that ``new`` lacks are dropped."""
    merged: dict[str, dict] = {}
    if path.exists():
        try:
            merged = json.loads(path.read_text())
        except json.JSONDecodeError:
            log.warning("%s is not valid JSON; starting it afresh", path)
    for key in [k for k in merged if k.split(".")[0] in rerun_prefixes and k not in new]:
        log.info("dropping %s: no benchmark writes it any more", key)
        del merged[key]
    merged.update(new)
    merged["_machine"] = {"value": f"{platform.machine()} {platform.processor() or ''}".strip(), "unit": "",
                          "python": platform.python_version()}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(dict(sorted(merged.items())), indent=2) + "\n")
    return merged


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="flowgap-bench",
        description="Run flowgap's benchmarks and merge the medians into bench/results.json.",
    )
    parser.add_argument("groups", nargs="*", help=f"groups to run (default: all of {available_groups()})")
    parser.add_argument("-o", "--out", "--output", dest="output", metavar="FILE", type=Path, default=RESULTS,
                        help="results file (default: %(default)s)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    groups = args.groups or available_groups()
    unknown = sorted(set(groups) - set(available_groups()))
    if unknown:
        print(f"flowgap-bench: unknown group(s) {unknown}; choose from {available_groups()}", file=sys.stderr)
        return 2
    from tools.launch import flights_stopped_by_signals

    try:
        with flights_stopped_by_signals():     # the flight benchmark's processes stop with it, as in flowgap-sitl
            new = run_groups(groups)
    except KeyboardInterrupt:
        print(f"flowgap-bench: interrupted; {args.output} left as it was", file=sys.stderr)
        return 130
    merge_results(new, args.output, rerun_prefixes(groups))
    width = max((len(k) for k in new), default=0)
    for key, entry in sorted(new.items()):
        print(f"{key:<{width}}  {entry['value']:>12.4g} {entry['unit']}")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
