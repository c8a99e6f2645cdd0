"""Sweep throughput: ``eval.flights_per_hour`` of ``flowgap-eval-flights`` as it runs by default (lockstep,
two flights at once on this machine's local pool), and ``eval.flights_per_hour_realtime`` of the same sweep
paced by the wall clock at ``--speed 2`` (the default before lockstep), from the same run, with ``dis:fine``."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from tools.eval_flights import main as eval_flights

SCENES = ["window1_brick", "window2_stone", "window3_granite", "window4_newspaper"]


def _sweep(extra: list[str]) -> tuple[float, int, int]:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        eval_flights([*SCENES, "--starts", "1", "--jobs", "2", "--seed", "0", "--flow", "dis:fine",
                      "--out", str(out), *extra])
        summary = json.loads((out / "flights.json").read_text())["summary"]
    return summary["total_wall_s"], summary["flights"], summary["success"]


def run() -> dict:
    lock_s, n, lock_ok = _sweep([])
    real_s, _, real_ok = _sweep(["--realtime", "--speed", "2"])
    what = f"flights per wall hour, {n} suite flights 2 at a time, dis:fine"
    return {
        "eval.flights_per_hour": {"value": round(3600 * n / lock_s),
                                  "unit": f"{what}, lockstep (the default; {lock_ok}/{n} through)"},
        "eval.flights_per_hour_realtime": {"value": round(3600 * n / real_s),
                                           "unit": f"{what}, --realtime --speed 2 ({real_ok}/{n} through)"},
    }
