"""Mutation testing of the pure-core modules with mutmut 3, one target (module or package) at a time.

Each target runs in its own staging directory (build/mutation/<target>/) holding links to the packages and
tests and a pyproject.toml whose [tool.mutmut] names that target's files and test files; mutmut copies it all
into mutants/ and runs pytest there.  The staging pytest config puts the staging root before tests/ on
sys.path (pythonpath = [".", "tests"]) and a conftest.py that imports the packages before collection: pytest
names tests/companion/test_*.py ``companion.test_*`` (tests/ has no __init__.py) and, if ``companion`` is not
imported yet, makes tests/companion/__init__.py the ``companion`` package, whose submodules the editable
install then takes from the *unmutated* tree.

Results go to a JSON file (one entry per target, kept across runs); the markdown report is written from it
and from the list of equivalent mutants (mutant name -> reason).  Usage::

    python -m tools.mutation --run companion.servo        # run one target, then write the report
    python -m tools.mutation --run all                    # every target (hours on 2 cores)
    python -m tools.mutation                              # report only
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import shutil
import subprocess
import sys
import time
from datetime import datetime, timezone
from importlib.metadata import version
from pathlib import Path

from tools.threads import thread_env

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("companion", "scenes", "sitl_vehicle", "tools", "tests")
RESULTS = ROOT / "docs" / "mutation-results.json"
EQUIVALENT = ROOT / "docs" / "mutation-equivalent.json"

# target -> (files to mutate, test files); smallest and fastest first
TARGETS: dict[str, tuple[list[str], list[str]]] = {
    "companion.servo": (["companion/servo.py"],
                        ["tests/closed_loop/test_servo.py", "tests/companion/test_servo_edges.py",
                         "tests/companion/test_opening.py"]),
    "sitl_vehicle.control": ([f"sitl_vehicle/control/{m}.py" for m in ("position", "attitude", "rate", "mixer")],
                             ["tests/sitl_vehicle/test_control.py", "tests/sitl_vehicle/test_control_laws.py"]),
    "companion.motion": (["companion/motion.py"], ["tests/closed_loop/test_tracking_and_motion.py"]),
    "companion.tracking": (["companion/tracking.py"],
                           ["tests/companion/test_tracking.py", "tests/closed_loop/test_tracking_and_motion.py"]),
    "scenes.camera": (["scenes/camera.py"], ["tests/scenes/test_camera.py", "tests/scenes/test_groundtruth.py"]),
    "companion.gap": (["companion/gap.py", "companion/gap_paper.py", "companion/holes.py",
                       "companion/inverse_depth.py"],
                      ["tests/companion/test_gap.py", "tests/companion/test_gap_detail.py",
                       "tests/companion/test_gap_edges.py", "tests/companion/test_gap_plain.py",
                       "tests/companion/test_gap_against_wall.py", "tests/companion/test_gap_focus.py",
                       "tests/companion/test_holes.py", "tests/companion/test_opening.py"]),
    "scenes.collision": (["scenes/collision.py"], ["tests/scenes/test_collision.py"]),
    "scenes.groundtruth": (["scenes/groundtruth.py"], ["tests/scenes/test_groundtruth.py"]),
    "sitl_vehicle.trajectory": (["sitl_vehicle/trajectory.py"], ["tests/sitl_vehicle/test_trajectory.py"]),
    "sitl_vehicle.estimator": (["sitl_vehicle/estimator.py"], ["tests/sitl_vehicle/test_estimator.py"]),
    "sitl_vehicle.dynamics": (["sitl_vehicle/dynamics.py"],
                              ["tests/sitl_vehicle/test_dynamics.py", "tests/sitl_vehicle/test_wind.py"]),
    "sitl_vehicle.commander": ([f"sitl_vehicle/{m}.py" for m in ("commander", "failsafes", "navigator", "stick_modes",
                                                                  "geofence", "return_plan", "orbit",
                                                                  "commander_types")],
                               [f"tests/sitl_vehicle/test_{t}.py" for t in ("commander", "takeoff", "mission",
                                                                            "manual", "acro", "geofence",
                                                                            "rally", "return_types",
                                                                            "mission_items", "reposition",
                                                                            "orbit")]),
}

STAGING_PYPROJECT = """\
[tool.pytest.ini_options]
testpaths = ["tests"]
pythonpath = [".", "tests"]
addopts = "-ra --import-mode=importlib"
timeout = 300
markers = ["slow: longer end-to-end tests", "fuzz: hypothesis fuzzing"]

[tool.mutmut]
source_paths = {sources}
only_mutate = {mutate}
pytest_add_cli_args_test_selection = {tests}
also_copy = ["conftest.py"]
"""

STAGING_CONFTEST = """\
# the real packages first, before pytest makes tests/companion the 'companion' package (tools/mutation.py)
import companion  # noqa: F401
import scenes  # noqa: F401
import sitl_vehicle  # noqa: F401
"""

LINE = re.compile(r"^\s*(\S+): (.+)$")


def stage(target: str, build: Path) -> Path:
    """A fresh staging directory for ``target``: links to the code and tests, and its own pyproject.toml."""
    mutate, tests = TARGETS[target]
    where = build / target
    shutil.rmtree(where, ignore_errors=True)
    where.mkdir(parents=True)
    for name in PACKAGES:
        (where / name).symlink_to(ROOT / name, target_is_directory=True)
    sources = [p for p in PACKAGES if p != "tests"]
    (where / "pyproject.toml").write_text(STAGING_PYPROJECT.format(
        sources=json.dumps(sources), mutate=json.dumps(mutate), tests=json.dumps(tests)))
    (where / "conftest.py").write_text(STAGING_CONFTEST)
    return where


def run_target(target: str, build: Path, max_children: int) -> dict:
    """Run mutmut for one target and return its entry for the results file."""
    where = stage(target, build)
    cmd = [sys.executable, "-m", "mutmut", "run", "--max-children", str(max_children)]
    log.info("%s: %s (in %s)", target, " ".join(cmd[1:]), where)
    start = time.monotonic()
    # mutmut forks a child per mutant: numba's GNU OpenMP layer kills a forked child with SIGTERM (mutmut's
    # 'suspicious'), so use its fork-safe workqueue layer, and one thread per library
    env = dict(os.environ, NUMBA_THREADING_LAYER="workqueue", **thread_env(1))
    run = subprocess.run(cmd, cwd=where, capture_output=True, text=True, env=env)
    wall = time.monotonic() - start
    (where / "mutmut-run.log").write_text(run.stdout + run.stderr)
    if run.returncode != 0:
        raise RuntimeError(f"mutmut run failed for {target} (rc {run.returncode}); see {where}/mutmut-run.log")
    listing = subprocess.run([sys.executable, "-m", "mutmut", "results", "--all", "true"], cwd=where,
                             capture_output=True, text=True, check=True).stdout
    statuses = {m.group(1): m.group(2).strip() for m in map(LINE.match, listing.splitlines()) if m}
    if not statuses:
        raise RuntimeError(f"no mutants listed for {target}; see {where}/mutmut-run.log")
    return {"mutate": TARGETS[target][0], "tests": TARGETS[target][1], "statuses": statuses,
            "mutmut": version("mutmut"), "wall_s": round(wall, 1),
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "command": f"python -m tools.mutation --run {target}"}


def module_of(mutant: str) -> str:
    return mutant.rsplit(".", 1)[0]  # companion.servo.x_servo_step__mutmut_3 -> companion.servo


def report(results: dict, equivalent: dict[str, str]) -> str:
    rows, notes, eq_lines = [], [], []
    head = ("| module | mutants | killed | survived | no tests | timeout | other | equivalent | "
            "killed % of non-equivalent |\n|---|---|---|---|---|---|---|---|---|")
    for target in TARGETS:
        entry = results.get(target)
        for path in TARGETS[target][0]:
            module = path[:-3].replace("/", ".")
            if entry is None:
                rows.append(f"| {module} | not run yet | | | | | | | |")
                continue
            st = {k: v for k, v in entry["statuses"].items() if module_of(k) == module}
            eq = {k for k, v in st.items() if v != "killed" and k in equivalent}
            count = {s: sum(1 for k, v in st.items() if v == s and k not in eq)
                     for s in ("killed", "survived", "no tests", "timeout")}
            count["other"] = len(st) - len(eq) - sum(count.values())   # suspicious, segfault, not checked
            judged = len(st) - len(eq)
            pct = f"{100 * (count['killed'] + count['timeout']) / judged:.1f}" if judged else "n/a"
            rows.append(f"| {module} | {len(st)} | {count['killed']} | {count['survived']} | {count['no tests']} | "
                        f"{count['timeout']} | {count['other']} | {len(eq)} | {pct} |")
            eq_lines += [f"- `{k}`: {equivalent[k]}" for k in sorted(eq)]
            left = sorted(k for k, v in st.items() if v not in ("killed", "timeout") and k not in eq)
            if left:
                notes.append(f"- {module}: " + ", ".join(f"`{k}` ({st[k]})" for k in left))
    runs = [f"- {t}: mutmut {e['mutmut']}, `{e['command']}`, {e['wall_s']:.0f} s wall, {e['date']}; tests: "
            + ", ".join(e["tests"]) for t, e in results.items() if t in TARGETS]
    out = ["# Mutation testing", "",
           "mutmut 3 over the pure-core modules, each with its own test files (`make mutation`, or "
           "`python -m tools.mutation --run TARGET`; not part of `make test`). Timeouts count as killed. "
           "'other' is mutmut's 'suspicious' (the forked test run ended by a signal, not by a test result) and the "
           "like; they count as not killed. An equivalent mutant changes no observable behaviour; each is listed "
           "below with the reason.", "",
           "Each target runs in build/mutation/<target>/ (links to the code, a pytest config with the copied "
           "code before tests/ on sys.path, and a conftest importing the packages first), because pytest names "
           "tests/companion/test_*.py `companion.test_*` and would otherwise make tests/companion the `companion` "
           "package, with the unmutated submodules from the editable install (checked by hand: a sign flipped in "
           "the copy's heading_to_ned fails test_servo.py there, and passes with the project's own pytest path). "
           "numba runs its workqueue threading layer there: its GNU OpenMP layer kills mutmut's forked children.",
           "",
           head, *rows, "", "## Runs", "", *(runs or ["- none yet"]), "",
           "## Equivalent mutants", "", *(eq_lines or ["- none"]), "",
           "## Not killed (neither killed nor equivalent)", "", *(notes or ["- none"]), ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", nargs="*", default=[], metavar="TARGET",
                    help=f"targets to run ('all' for every one): {', '.join(TARGETS)}")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "docs" / "mutation.md", help="markdown report path")
    ap.add_argument("--results", type=Path, default=RESULTS, help="JSON results, kept across runs")
    ap.add_argument("--equivalent", type=Path, default=EQUIVALENT, help="JSON: mutant name -> why equivalent")
    ap.add_argument("--build", type=Path, default=ROOT / "build" / "mutation", help="staging directories")
    ap.add_argument("--max-children", type=int, default=os.cpu_count() or 2)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    targets = list(TARGETS) if args.run == ["all"] else args.run
    unknown = [t for t in targets if t not in TARGETS]
    if unknown:
        ap.error(f"unknown targets {unknown}; choose from {list(TARGETS)}")
    results = json.loads(args.results.read_text()) if args.results.exists() else {}
    for target in targets:
        results[target] = run_target(target, args.build, args.max_children)
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
        log.info("%s: %d mutants in %.0f s", target, len(results[target]["statuses"]), results[target]["wall_s"])
    equivalent = json.loads(args.equivalent.read_text()) if args.equivalent.exists() else {}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(report(results, equivalent))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
