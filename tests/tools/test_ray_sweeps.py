"""Flight sweeps on Ray beside the local pool on the same node: the same rows, a stopped sweep resumed, no
shared port, nothing left running; and mask pairs on a local Ray.

Ray listens on the machine's interface address on Linux, so the Ray part re-runs this file as a script in a
loopback-only network namespace (:mod:`tools.loopback`): no traffic goes anywhere but 127.0.0.1. In there, at
once: ``ray start --head`` (2 CPUs, token authentication on, as a real cluster's head), on which the sweep (2
scenes x 2 starts, lockstep, ~10 s a flight) runs with ``RAY_ADDRESS`` and ``--ray auto``, interrupted (SIGINT)
after its first flight and rerun with ``--resume``; the local pool flying the same sweep; and
``flowgap-eval-masks --ray local`` scoring two scenes' mask pairs, without any ``RAY_AUTH_*`` setting (the local
Ray's token then lives in its environment only). Last, ``--ray auto`` looks for a cluster where there is none.
The namespace's environment: no ``RAY_*`` variables of the caller's, a ``RAY_TMPDIR`` of its own (not
``TMPDIR``: the instance locks must stay in the shared ``/tmp``) and a ``HOME`` of its own, to show that nothing
is written to ``~/.ray``.
"""
from __future__ import annotations

import importlib.util
import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

SCENES = ["window1_brick", "window2_stone"]
# dis:fine, not the default RAFT: the rows' sameness is the executors', whatever the flow, and eight flights share
# two cores here
SWEEP = [sys.executable, "-m", "tools.eval_flights", *SCENES, "--starts", "2", "--seed", "0", "--flow", "dis:fine"]
MASKS = [sys.executable, "-m", "tools.eval_masks", "--quick", "--scenes", "window1_brick", "--random", "1",
         "--backends", "dis:medium", "--detectors", "parallax", "--no-progress"]
VERDICT_FIELDS = {"success", "collision", "crossed_wall", "min_clearance_m", "servo_steps", "sim_time_s",
                  "companion_state", "passable", "through", "refused", "node", "host", "instance"}


def _draws(row: dict) -> tuple:
    return row["scene"], row["start_index"], tuple(row["start_ned"]), row["altitude_m"], row["seed"]


def _flights(folder: Path) -> dict:
    return json.loads((folder / "flights.json").read_text())


# --------------------------------------------------------------------------------------------------------------
# the part that runs inside the namespace
# --------------------------------------------------------------------------------------------------------------

HEAD = "127.0.0.1:6379"         # in a namespace of its own, nothing else listens there


def _wait_for_head(head: subprocess.Popen, timeout_s: float = 120) -> None:
    """Until the head's GCS answers (and a moment for its raylet)."""
    import socket

    host, port = HEAD.split(":")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and head.poll() is None:
        try:
            socket.create_connection((host, int(port)), timeout=1).close()
            time.sleep(3)
            return
        except OSError:
            time.sleep(0.5)
    raise RuntimeError("the Ray head did not start")


def _run_in_namespace(folder: Path) -> None:
    def start(args: list[str], name: str, command=SWEEP, env=None) -> subprocess.Popen:
        log = open(folder / f"{name}.log", "w")  # noqa: SIM115 — closed with the process
        return subprocess.Popen([*command, *args], stdout=log, stderr=subprocess.STDOUT, cwd=folder, env=env)

    report: dict = {}
    ray_cli = str(Path(sys.executable).parent / "ray")
    head = start(["start", "--head", "--port", HEAD.split(":")[1], "--num-cpus", "2", "--include-dashboard",
                  "false", "--disable-usage-stats", "--block"], "head", command=[ray_cli])
    no_auth = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    masks = start(["--ray", "local", "-o", str(folder / "masks")], "masks", command=MASKS, env=no_auth)
    local = start(["--jobs", "2", "-o", str(folder / "local")], "local")
    try:
        _wait_for_head(head)
        on_head = {**os.environ, "RAY_ADDRESS": HEAD}
        ray_args = ["--ray", "auto", "-o", str(folder / "ray")]
        first = start(ray_args, "ray-first", env=on_head)
        results = folder / "ray" / "results"
        deadline = time.monotonic() + 200
        while first.poll() is None and not list(results.glob("*.json")) and time.monotonic() < deadline:
            time.sleep(0.2)
        first.send_signal(signal.SIGINT)                     # as Ctrl-C would, once one flight is saved
        report["first_rc"] = first.wait(timeout=90)
        report["saved"] = {p.name: [p.stat().st_mtime_ns, p.read_text()] for p in sorted(results.glob("*.json"))}
        report["resumed_rc"] = start([*ray_args, "--resume"], "ray-resumed", env=on_head).wait(timeout=200)
    finally:
        head.terminate()                                     # (ray start --block stops its cluster on SIGTERM)
        report["head_rc"] = head.wait(timeout=60)
    report["local_rc"] = local.wait(timeout=200)
    report["masks_rc"] = masks.wait(timeout=200)
    nowhere = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    nowhere["RAY_TMPDIR"] = str(folder / "no-ray")                  # no cluster of any earlier Ray to find
    auto = subprocess.run([*SWEEP[:4], "--ray", "auto", "-o", str(folder / "auto")], capture_output=True, text=True,
                          timeout=60, env=nowhere)
    report["auto"] = {"rc": auto.returncode, "stderr": auto.stderr}
    (folder / "report.json").write_text(json.dumps(report, indent=1))


# --------------------------------------------------------------------------------------------------------------
# the fixture that runs it, and the tests
# --------------------------------------------------------------------------------------------------------------

def _session_processes(sid: int) -> dict[int, str]:
    from support.processes import pids, proc_stat

    found = {}
    for pid in pids():
        fields = proc_stat(pid)
        try:
            if fields is not None and int(fields[3]) == sid:          # (state, ppid, pgrp, session, ...)
                found[pid] = Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")[:120]
        except OSError:
            continue
    return found


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    from tools.loopback import loopback_command, unavailable

    if importlib.util.find_spec("ray") is None:
        pytest.skip("Ray is not installed: pip install -e '.[ray]'")
    why = unavailable()
    if why:
        pytest.skip(f"no loopback-only network namespace for Ray: {why}")
    folder = tmp_path_factory.mktemp("ray_sweeps")
    (folder / "home").mkdir()
    ray_tmp = tempfile.mkdtemp(prefix="fgray-", dir="/tmp")       # short: Ray's socket paths have a length limit
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(RAY_TMPDIR=ray_tmp, RAY_USAGE_STATS_ENABLED="0", HOME=str(folder / "home"),
               PYTHONPATH=str(Path(__file__).resolve().parents[2]),
               RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))     # a cluster's token, as on a real one
    proc = subprocess.Popen(loopback_command([sys.executable, __file__, str(folder)]), env=env,
                            start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        output, _ = proc.communicate(timeout=280)
    finally:
        deadline = time.monotonic() + 10                    # Ray's processes end a moment after their driver
        while _session_processes(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        leftovers = _session_processes(proc.pid)
        for pid in leftovers:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        shutil.rmtree(ray_tmp, ignore_errors=True)
    logs = "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted(folder.glob("*.log")))
    assert proc.returncode == 0, f"{output[-3000:]}\n{logs}"
    return {"folder": folder, "report": json.loads((folder / "report.json").read_text()), "leftovers": leftovers,
            "logs": logs}


@pytest.mark.slow
def test_a_sweep_on_a_local_ray_gives_the_local_pools_rows(sweeps):
    local, ray = _flights(sweeps["folder"] / "local"), _flights(sweeps["folder"] / "ray")
    assert sweeps["report"]["local_rc"] == 0 and sweeps["report"]["resumed_rc"] == 0, sweeps["logs"]
    assert [_draws(r) for r in ray["rows"]] == [_draws(r) for r in local["rows"]]
    assert len(ray["rows"]) == 4 and {r["scene"] for r in ray["rows"]} == set(SCENES)
    for row in local["rows"] + ray["rows"]:
        assert VERDICT_FIELDS <= set(row), VERDICT_FIELDS - set(row)
        assert (Path(row["run_dir"]) / "verdict.json").exists()        # run directories where the local pool puts them
    assert (local["summary"]["executor"], ray["summary"]["executor"]) == ("local", "ray")
    assert all(len(r["node"]) == 56 for r in ray["rows"])               # a Ray node id per row
    assert ray["summary"]["ray"]["address"] == "auto" and ray["summary"]["ray"]["cpus"] == 2
    lo, hi = ray["summary"]["success_interval"]
    assert lo <= ray["summary"]["success_rate"] <= hi
    assert "95 % CI" in (sweeps["folder"] / "ray" / "flights.md").read_text()


@pytest.mark.slow
def test_a_stopped_sweep_resumed_flies_only_the_missing_flights(sweeps):
    report, folder = sweeps["report"], sweeps["folder"] / "ray"
    assert report["first_rc"] == 130, sweeps["logs"]                  # stopped by the SIGINT
    saved = report["saved"]
    assert 1 <= len(saved) < 4
    summary = _flights(folder)["summary"]
    assert (summary["reused"], summary["flown"], summary["flights"]) == (len(saved), 4 - len(saved), 4)
    for name, (mtime_ns, text) in saved.items():                        # reused as they were, not flown again
        path = folder / "results" / name
        assert path.stat().st_mtime_ns == mtime_ns and path.read_text() == text
    assert len(list((folder / "results").glob("*.json"))) == 4
    runs = [json.loads(line) for line in (folder / "sweep_runs.jsonl").read_text().splitlines()]
    assert [(r["flown"], r["ended"]) for r in runs] == [(len(saved), "interrupted"), (4 - len(saved), "complete")]
    assert summary["runs"] == 2 and summary["this_run_wall_s"] == runs[1]["wall_s"]       # both runs' time
    assert summary["total_wall_s"] == pytest.approx(runs[0]["wall_s"] + runs[1]["wall_s"], abs=0.11)


@pytest.mark.slow
def test_two_sweeps_on_one_node_never_share_a_port(sweeps):
    local = _flights(sweeps["folder"] / "local")["rows"]
    ray = _flights(sweeps["folder"] / "ray")["rows"]
    overlapping = [(a, b) for a in local for b in ray
                   if a["flight_started"] < b["flight_ended"] and b["flight_started"] < a["flight_ended"]]
    assert overlapping, "the two sweeps never flew at the same time: the test proves nothing"
    assert all(a["instance"] != b["instance"] for a, b in overlapping)
    for rows in (local, ray):                                         # nor two flights of one sweep
        for i, a in enumerate(rows):
            for b in rows[i + 1:]:
                if a["flight_started"] < b["flight_ended"] and b["flight_started"] < a["flight_ended"]:
                    assert a["instance"] != b["instance"]


@pytest.mark.slow
def test_mask_pairs_on_a_local_ray_score_as_on_this_machine(sweeps, tmp_path):
    from tools.eval_masks import main

    assert sweeps["report"]["masks_rc"] == 0, sweeps["logs"]
    assert main([*MASKS[3:], "-o", str(tmp_path)]) == 0
    here = json.loads((tmp_path / "eval_masks.json").read_text())
    there = json.loads((sweeps["folder"] / "masks" / "eval_masks.json").read_text())
    key = ("scene", "viewpoint", "backend", "detector", "iou", "detected")
    assert [[r[k] for k in key] for r in there["rows"]] == [[r[k] for k in key] for r in here["rows"]]
    assert there["meta"]["executor"] == "ray" and len(there["meta"]["nodes"]) == 1


@pytest.mark.slow
def test_ray_auto_without_a_cluster_is_a_one_line_error(sweeps):
    auto = sweeps["report"]["auto"]
    lines = [line for line in auto["stderr"].splitlines() if line.startswith("flowgap-eval-flights")]
    assert auto["rc"] == 2 and len(lines) == 1 and "no Ray cluster" in lines[0], auto["stderr"]
    assert "Traceback" not in auto["stderr"]


@pytest.mark.slow
def test_the_sweeps_leave_no_process_and_no_token_behind(sweeps):
    assert not sweeps["leftovers"], sweeps["leftovers"]
    assert not (sweeps["folder"] / "home" / ".ray").exists()          # the local Ray's token lived in its env only


if __name__ == "__main__":
    _run_in_namespace(Path(sys.argv[1]))
