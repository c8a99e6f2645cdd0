"""Replay the companion's fit judgement on flown sweeps: ``python -m tools.fit_replay RUN... --thickness T...``.

A sweep of 100 hard-world flights takes half an hour; which of its flights a different fit judgement would have
refused can be read from their decision logs in seconds.  The judgement turns on the wall thickness an opening's
size is scaled for (``ServoConfig.wall_thickness_m``: the back face bounds what is seen through the opening), and
this replays it for other thicknesses:

- each judged frame's size estimate (``estimate_m``, from ``estimate_px`` pixels in the wall's plane) is scaled
  again for a wall ``T`` thick: the depth it was scaled by is recovered from the two, and the pixels are
  stretched by :func:`companion.opening.turned_wall_stretch` at ``T`` over the stretch at the thickness flown
  (exact where the opening's width bounds its clear circle, an upper bound of the change otherwise);
- the judgement is made as :class:`companion.opening.OpeningTracker` makes it: from the ``min_estimates``-th
  judged estimate of an opening on (a log's count falling back to 1 starts another), refused as soon as the upper
  quartile of the latest ``radius_window``, less the size allowance, falls short of the body radius and its
  margin.  A flight counts as refused by the replay if any opening it judged is (the switch to another opening in
  view that a refusal may make instead is not replayed).

What it tells: which flights flown through the replay refuses (a passable one lost; an impassable one refused, as
it must be).  What it cannot: how a flight refused for its size would have gone had it been judged to fit; those
are counted as ``undecided``.  Logs flown before 2026-12-05 (d3837f6) lack the refusing frame, so their refusals
for size are undecided at every thickness.

Outputs (in ``-o/--out``): ``fit_replay.json`` (per run and thickness: counts and the scenes that change) and
``fit_replay.md``.

    python -m tools.fit_replay runs/hard_88 --thickness 0.10 0.125 0.15 -o runs/fit_replay
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import sys
from pathlib import Path

log = logging.getLogger("flowgap.fit_replay")


class ReplayError(ValueError):
    """A run folder that holds no sweep's results, or a flight whose decision log is missing or unreadable."""


def flights(run: Path) -> list[dict]:
    """The sweep's rows (``RUN/results/*.json``, as ``flowgap-eval-flights`` saves them), each with its decision
    log's lines under ``decisions``.  A run folder moved since it was flown is found by its own name."""
    files = sorted((run / "results").glob("*.json"))
    if not files:
        raise ReplayError(f"{run}: no results/*.json; give a folder flowgap-eval-flights wrote (its -o/--out)")
    out = []
    for path in files:
        try:
            row = json.loads(path.read_text())["row"]
        except (OSError, ValueError, KeyError) as exc:
            raise ReplayError(f"{path}: not a sweep's result file ({exc}); fly it again with --resume") from exc
        log_path = next((p for p in (Path(row.get("run_dir", "")) / "companion" / "decisions.jsonl",
                                     run / path.stem / "companion" / "decisions.jsonl") if p.is_file()), None)
        if log_path is None:
            raise ReplayError(f"{path.stem}: no companion/decisions.jsonl in its run folder; the sweep's flight "
                              "folders must be beside results/")
        try:
            decisions = [json.loads(line) for line in log_path.read_text().splitlines() if line.strip()]
        except ValueError as exc:
            raise ReplayError(f"{log_path}: not JSON lines ({exc})") from exc
        out.append({**row, "decisions": decisions})
    return out


def rescaled(decision: dict, judging, flown, focal_px: float) -> float:
    """A logged frame's size estimate (m), scaled by the :class:`companion.opening.OpeningTracker` ``flown``, scaled
    again as ``judging`` (another wall thickness) scales it (see the module)."""
    from companion.opening import TURN_NEGLIGIBLE_RAD
    from companion.opening_geometry import turned_wall_stretch

    estimate, pixels = decision["estimate_m"], decision["estimate_px"]
    flown_t, judging_t = flown.servo.wall_thickness_m, judging.servo.wall_thickness_m
    depth = estimate * focal_px / (pixels + flown.config.mask_inset_px) - flown_t    # clear_radius_m's inverse
    turn = decision.get("wall_turn_rad")
    if turn is not None and abs(turn) > TURN_NEGLIGIBLE_RAD:
        need = judging.servo.body_radius_m + judging.servo.clearance_margin_m      # as observe stretches
        pixels *= turned_wall_stretch(need, depth, turn, judging_t) / turned_wall_stretch(need, depth, turn, flown_t)
    return judging.clear_radius_m(pixels, depth, focal_px)


def refused_for_size(decisions: list[dict], judging, flown, focal_px: float) -> bool:
    """Whether the tracker ``judging`` (another wall thickness than ``flown``'s), replayed on a flight's decision
    lines, refuses an opening of it."""
    from companion.opening import upper_quartile
    from companion.servo import judged_tolerance

    config = judging.config
    estimates: list[float] = []
    for d in decisions:
        if not d.get("judged") or d.get("estimate_m") is None or d.get("estimate_px") is None:
            continue
        if d.get("judged_estimates", 0) <= 1:
            estimates = []               # another opening, or the tracked one's history forgotten
        estimates.append(rescaled(d, judging, flown, focal_px))
        if (len(estimates) >= config.min_estimates
                and judged_tolerance(upper_quartile(estimates, config.radius_window), judging.servo) < 0):
            return True
    return False


def tracker_for(thickness_m: float):
    """The companion's opening tracker, its defaults but for the wall thickness it scales sizes for."""
    from companion.opening import OpeningTracker
    from companion.servo import ServoConfig

    return OpeningTracker(dataclasses.replace(ServoConfig(), wall_thickness_m=thickness_m))


def replay_run(rows: list[dict], thicknesses: list[float], focal_px: float) -> dict:
    """Per thickness: passable flights through, impassable ones flown, the flights whose outcome the replay
    changes (``lost``: passable, flown through, refused by the replay; ``now_refused``: impassable, flown, refused
    by it) and those it cannot tell (``undecided``: refused for size as flown, judged to fit by the replay)."""
    from companion.opening import OpeningTracker, is_size_refusal

    flown = OpeningTracker()
    as_flown = {r["scene"]: refused_for_size(r["decisions"], flown, flown, focal_px) for r in rows}
    out = {}
    for t in thicknesses:
        lost, now_refused, undecided, through, imp_flown = [], [], [], 0, 0
        judging = tracker_for(t)
        for r in rows:
            refuses = refused_for_size(r["decisions"], judging, flown, focal_px)
            if r["passable"] and r["success"]:
                if refuses and not as_flown[r["scene"]]:
                    lost.append(r["scene"])
                else:
                    through += 1
            elif not r["passable"] and not r["refused"]:
                if refuses and not as_flown[r["scene"]]:
                    now_refused.append(r["scene"])
                else:
                    imp_flown += 1
            if r["refused"] and is_size_refusal(r.get("companion_reason")) and not refuses:
                undecided.append(r["scene"])
        out[f"{t:g}"] = {"passable": sum(r["passable"] for r in rows), "passable_through": through,
                         "impassable": sum(not r["passable"] for r in rows), "impassable_flown": imp_flown,
                         "lost": lost, "now_refused": now_refused, "undecided": undecided}
    return out


def markdown(report: dict) -> str:
    lines = ["# The fit judgement replayed", "",
             "| run | wall judged (m) | passable through | impassable flown | lost | now refused | undecided |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for run, by_t in report["runs"].items():
        for t, r in by_t.items():
            lines.append(f"| {run} | {t} | {r['passable_through']}/{r['passable']} | {r['impassable_flown']}/"
                         f"{r['impassable']} | {', '.join(r['lost']) or '-'} | {', '.join(r['now_refused']) or '-'} | "
                         f"{len(r['undecided'])} |")
    lines += ["", f"Flown with {report['flown_thickness_m']:g} m; replayed as `companion.opening.OpeningTracker` "
              "judges. Undecided: refused for size as flown, judged to fit by the replay (named in fit_replay.json; "
              "see `python -m tools.fit_replay --help`)."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from scenes import PinholeCamera

    parser = argparse.ArgumentParser(prog="python -m tools.fit_replay", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, metavar="RUN", help="folders flowgap-eval-flights wrote")
    parser.add_argument("--thickness", type=float, nargs="+", default=[0.10, 0.125, 0.15], metavar="M",
                        help="wall thicknesses to judge the fit with (metres)")
    parser.add_argument("-o", "--out", type=Path, default=Path("runs/fit_replay"), help="output folder")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if not all(0.0 <= t < 2.0 and math.isfinite(t) for t in args.thickness):
        print("fit_replay: --thickness must be between 0 and 2 m", file=sys.stderr)
        return 2
    from companion.servo import ServoConfig

    focal = float(PinholeCamera().K[0, 0])      # the companion's camera (companion.camera)
    report = {"flown_thickness_m": ServoConfig().wall_thickness_m, "focal_px": focal, "runs": {}}
    try:
        for run in args.runs:
            report["runs"][str(run)] = replay_run(flights(run), args.thickness, focal)
    except ReplayError as exc:
        print(f"fit_replay: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "fit_replay.json").write_text(json.dumps(report, indent=2) + "\n")
    table = markdown(report)
    (args.out / "fit_replay.md").write_text(table)
    print(table)
    print(f"-> {args.out / 'fit_replay.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
