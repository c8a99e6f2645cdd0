"""Command line of ``flowgap-tlog``."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from companion.edges import EDGE_MODES
from companion.jsonsafe import json_safe
from tools.tlog.analysis import analyse_tlog
from tools.tlog.truth import TRUTH_AUTO_ORDER, parse_truth_option

PROG = "flowgap-tlog"
EPILOG = f"""\
what it reports: duration, systems/components, autopilot and vehicle type, message counts and rates,
packet loss per link from sequence gaps, mode timeline (PX4 and ArduPilot custom modes), arm/disarm,
STATUSTEXT; offboard setpoint rate and longest gap, time in offboard mode, position tracking error of
LOCAL_POSITION_NED against the latest position-controlled SET_POSITION_TARGET_LOCAL_NED, and against
ground truth when the log carries it (--truth; auto tries, in order,
{', '.join(TRUTH_AUTO_ORDER)}
from any component other than the one whose LOCAL_POSITION_NED is the estimate).

problems in the log (truncation, garbage, CRC failures, unknown ids, no position data) are reported as
one-line notes on stderr and in metrics.json, never as a traceback.

exit status: 0 analysed; 1 no MAVLink packets in the file (empty / not a tlog; outputs still written);
2 usage error, missing or unreadable file (or a run directory replay cannot read).

examples:
  {PROG} flight.tlog                          # summary on stdout
  {PROG} flight.tlog --out report/ --csv      # + report.md, metrics.json, PNGs, csv/<MSG>.csv
  {PROG} run/link.tlog --out r/ --scene window1_brick --truth att_pos_mocap
  {PROG} replay runs/<time>-window1_brick/companion --flow dis:medium --detector paper
"""


def _build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EPILOG,
        description="Analyse a MAVLink telemetry log (.tlog: 8-byte big-endian µs UNIX time before each "
                    "MAVLink 1/2 packet) from flowgap, PX4 or ArduPilot: what the vehicle did, what it "
                    f"was told, how well it followed. `{PROG} replay RUN_DIR` re-runs a companion run's "
                    "perception with other settings.")
    p.add_argument("tlog", type=Path, help="the .tlog file")
    p.add_argument("-o", "--out", type=Path, metavar="DIR",
                   help="write report.md, metrics.json and the plots here (default: summary only)")
    p.add_argument("--csv", action="store_true", help="also write DIR/csv/<MESSAGE>.csv per message type")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots (faster)")
    p.add_argument("--scene", metavar="NAME",
                   help="a scenes suite name or spec .json: draw its wall and opening(s), report where the "
                        "trajectory crosses the wall plane")
    p.add_argument("--truth", default="auto", metavar="SPEC",
                   help="ground-truth source: auto (default), none, a name (att_pos_mocap, "
                        "local_position_ned_cov, odometry, local_position_ned), optionally @SYSID:COMPID")
    p.add_argument("--dialect", default="ardupilotmega",
                   help="pymavlink v2.0 dialect to decode with (default: %(default)s, a superset of common)")
    p.add_argument("--signing-key", type=Path, metavar="FILE",
                   help="check every packet's MAVLink 2 signature with this PX4 key file and count good, "
                        "replayed, bad and unsigned packets (per source)")
    p.add_argument("--json", action="store_true", help="print metrics.json to stdout instead of the summary")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    return p


class _NoteFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        kind = "note" if record.levelno == logging.WARNING else record.levelname.lower()
        return f"{PROG}: {kind}: {record.getMessage()}"


def _setup_logging(verbose: bool) -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_NoteFormatter())
    root = logging.getLogger("tools.tlog")
    root.handlers[:] = [handler]
    root.setLevel(logging.DEBUG if verbose else logging.WARNING)
    root.propagate = False


def _replay(argv: list[str]) -> int:
    from tools.tlog.replay import ReplayError, describe, replay

    p = argparse.ArgumentParser(
        prog=f"{PROG} replay", description="Re-render a flowgap-companion run at its logged poses and re-run "
        "perception with other settings; lists the steps where the used centroid differs from the flown one.")
    p.add_argument("run_dir", type=Path, help="a companion run directory (summary.json, frames.jsonl, ...)")
    p.add_argument("--flow", help="flow backend to replay with, e.g. dis:medium (default: the flight's)")
    p.add_argument("--detector", choices=["parallax", "paper"], help="detector (default: the flight's)")
    p.add_argument("--edges", choices=EDGE_MODES, help="photo: the openings' edges read again from the frames; "
                   "flow: the detector's masks as they are (default: the flight's; flow for runs before the option)")
    p.add_argument("--differ-px", type=float, default=10.0, help="centroid distance that counts as a "
                   "different decision (default 10)")
    p.add_argument("-o", "--out", type=Path, help="write the replay JSON here (default RUN_DIR/replay.json)")
    p.add_argument("--rerun", nargs="?", const="", default=None, metavar="FILE",
                   help="also record the replay for the Rerun viewer in FILE (default RUN_DIR/replay.rrd); "
                        "needs the extra: pip install 'flowgap[viz]'")
    p.add_argument("--rerun-connect", metavar="ADDRESS", help="stream that recording to a running viewer instead")
    args = p.parse_args(argv)
    if not args.run_dir.is_dir():
        print(f"{PROG}: error: {args.run_dir} is not a directory", file=sys.stderr)
        return 2
    recording = None
    if args.rerun is not None or args.rerun_connect:
        from companion.recording import RecordingError, open_recording

        try:
            recording = open_recording(Path(args.rerun) if args.rerun else args.run_dir / "replay.rrd",
                                       args.rerun_connect)
        except RecordingError as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 2
    try:
        result = replay(args.run_dir, args.flow, args.detector, args.differ_px, recording, args.edges)
    except (ReplayError, KeyError, ValueError) as exc:
        print(f"{PROG}: error: replay: {exc}", file=sys.stderr)
        return 2
    finally:
        if recording is not None:
            recording.close()
    out = args.out or args.run_dir / "replay.json"
    out.write_text(json.dumps(json_safe(result), indent=2) + "\n")
    print(describe(result))
    print(f"wrote {out}")
    if recording is not None and not args.rerun_connect:
        print(f"wrote {Path(args.rerun) if args.rerun else args.run_dir / 'replay.rrd'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "replay":
        return _replay(argv[1:])
    if argv and argv[0] in ("analyse", "analyze"):
        argv = argv[1:]
    args = _build_parser().parse_args(argv)
    _setup_logging(args.verbose)
    try:
        parse_truth_option(args.truth)
    except ValueError as exc:
        print(f"{PROG}: error: --truth: {exc}", file=sys.stderr)
        return 2
    path: Path = args.tlog
    if not path.exists():
        print(f"{PROG}: error: no such file: {path}", file=sys.stderr)
        return 2
    if not path.is_file():
        print(f"{PROG}: error: not a file: {path}", file=sys.stderr)
        return 2
    try:  # refuse an unreadable file here, in one line, before the analysis would note it too
        path.open("rb").close()
    except OSError as exc:
        print(f"{PROG}: error: cannot read {path}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    try:
        from tools.tlog.framing import load_dialect

        load_dialect(args.dialect)
    except ImportError:
        print(f"{PROG}: error: unknown pymavlink dialect {args.dialect!r}", file=sys.stderr)
        return 2
    secret = None
    if args.signing_key is not None:
        from sitl_vehicle.signing import SigningKeyError, read_key_file

        try:
            secret = read_key_file(args.signing_key).secret
        except SigningKeyError as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 2
    t = time.perf_counter()
    rep = analyse_tlog(path, truth=args.truth, dialect=args.dialect,
                       progress=not args.quiet and sys.stderr.isatty(), signing_secret=secret)
    if rep.frames is None and rep.notes and rep.notes[0].startswith("cannot read"):
        return 2  # it became unreadable after the check above: the analysis's note has said so, in one line
    elapsed = time.perf_counter() - t
    written = None
    if args.out is not None:
        from tools.tlog.output import write_outputs

        try:
            written = write_outputs(rep, args.out, plots=not args.no_plots, csv_dir=args.csv, scene=args.scene)
            from tools.tlog.storyboard import write_run_storyboard

            board = write_run_storyboard(path, args.out)     # the tlog of a companion run: its storyboard too
            written["storyboard"] = str(board) if board is not None else None
        except OSError as exc:
            print(f"{PROG}: error: cannot write to {args.out}: {exc.strerror or exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps(json_safe(rep.to_json()), indent=2))
    else:
        from tools.tlog.output import summary_text

        print(summary_text(rep))
        n = rep.metrics.get("framing", {}).get("packets", 0)
        print(f"  analysed {n} packets in {elapsed:.2f} s")
        if written is not None:
            extra = f", {len(written.get('csv', []))} CSV files" if args.csv else ""
            extra += ", storyboard.png" if written.get("storyboard") else ""
            print(f"  wrote {args.out}/report.md, metrics.json, {len(written['plots'])} plots{extra}")
    return 0 if rep.usable else 1


if __name__ == "__main__":
    sys.exit(main())
