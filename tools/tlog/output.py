"""Outputs of a report: ``metrics.json``, ``report.md`` (with plots), per-message CSVs, a stdout summary."""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from companion.jsonsafe import json_safe
from tools.tlog.analysis import Report
from tools.tlog.framing import decode_columns

log = logging.getLogger(__name__)


def _f(x: Any, fmt: str = ".3f", none: str = "–") -> str:
    return none if x is None else format(x, fmt)


def _err_line(st: dict[str, Any] | None) -> str:
    if not st or not st.get("n_samples"):
        return "no samples"
    return (f"mean {st['mean_m']:.3f} m, RMS {st['rms_m']:.3f} m, p95 {st['p95_m']:.3f} m, "
            f"max {st['max_m']:.3f} m ({st['n_samples']} samples)")


def summary_text(rep: Report) -> str:
    """A short human summary (a dozen lines) for stdout."""
    m = rep.metrics
    lines = [f"{rep.path}"]
    if not rep.usable:
        lines.append("  nothing to analyse")
        return "\n".join(lines)
    v = m.get("vehicle")
    veh = f"{v['autopilot']} {v['type']} (sys {v['sysid']} comp {v['compid']})" if v else "no autopilot heartbeat"
    fr = m["framing"]
    lines.append(f"  {m['duration_s']:.1f} s from {m['start_utc']}, {m['messages']['total']} messages of "
                 f"{m['messages']['types']} types, {len(m['components'])} components; vehicle: {veh}")
    pl = m["packet_loss"]
    vl = pl.get("vehicle_link")
    loss = (f"vehicle link {vl['loss_pct']:.2f} % ({vl['lost']} lost), all links {pl['loss_pct']:.2f} %"
            if vl else f"{pl['loss_pct']:.2f} % ({pl['lost']} lost)")
    lines.append(f"  packet loss: {loss}, "
                 f"CRC failures {fr['crc_failures']}, unknown ids {fr['unknown_id_packets']}, "
                 f"garbage {fr['garbage_bytes']} B")
    tl = m["modes"]["timeline"]
    if tl:
        lines.append("  modes: " + " → ".join(f"{e['mode']}@{e['t_s']:.1f}s" for e in tl[:12])
                     + (" …" if len(tl) > 12 else ""))
    if m["arm_events"]:
        lines.append("  arming: " + ", ".join(f"{e['event']}@{e['t_s']:.1f}s" for e in m["arm_events"]))
    off = m.get("offboard") or {}
    sp = off.get("setpoints") or {}
    if sp.get("count"):
        lines.append(f"  setpoints: {sp['count']} at {_f(sp.get('rate_hz'), '.1f')} Hz, longest gap "
                     f"{_f(sp.get('longest_gap_s'), '.3f')} s; offboard for {off['offboard_time_s']:.1f} s")
        lines.append(f"  tracking error (estimate vs setpoint): {_err_line(off.get('tracking_error'))}")
    else:
        lines.append("  no offboard setpoints (SET_POSITION_TARGET_LOCAL_NED)")
    tr = off.get("truth") or {}
    if tr.get("tracking_error") is not None or tr.get("estimate_error") is not None:
        lines.append(f"  truth ({tr['source']}): tracking {_err_line(tr.get('tracking_error'))}; "
                     f"estimate error {_err_line(tr.get('estimate_error'))}")
    if m["statustext"]:
        lines.append(f"  {len(m['statustext'])} STATUSTEXT, last: {m['statustext'][-1]['text']!r}")
    if m.get("signatures"):
        from tools.tlog.signatures import signatures_line

        lines.append("  " + signatures_line(m["signatures"]))
    if rep.notes:
        lines.append(f"  {len(rep.notes)} note(s), see metrics.json / report.md")
    return "\n".join(lines)


def _table(head: list[str], rows: list[list[Any]]) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(" --- " for _ in head) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]
    return out


def report_markdown(rep: Report, plots: dict[str, str]) -> str:
    m = rep.metrics
    md = [f"# Flight log report: `{Path(rep.path).name}`", ""]
    if rep.notes:
        md += ["## Notes", ""] + [f"- {n}" for n in rep.notes] + [""]
    if not rep.usable:
        md += ["Nothing could be analysed.", ""]
        return "\n".join(md)
    v = m.get("vehicle")
    flat_framing = json_safe({k: x for k, x in m["framing"].items() if not isinstance(x, dict)})
    md += ["## Summary", "",
           f"- file: `{rep.path}` ({m['file_bytes']} bytes)",
           f"- start: {m['start_utc']}, duration {m['duration_s']:.2f} s",
           "- vehicle: " + (f"{v['autopilot']} ({v['autopilot_enum']}), {v['type']} ({v['type_enum']}), "
                             f"sys {v['sysid']} comp {v['compid']}" if v else "no autopilot HEARTBEAT"),
           f"- messages: {m['messages']['total']} decoded of {m['messages']['types']} types; "
           f"packet loss {m['packet_loss']['loss_pct']:.2f} % ({m['packet_loss']['lost']} by sequence gaps)",
           f"- framing: {json.dumps(flat_framing)}",
           ""]
    md += ["## Components", ""]
    md += _table(["sys:comp", "component", "type", "autopilot", "packets", "lost", "loss %"],
                 [[k, c["component"], c.get("type", ""), c.get("autopilot", ""), c["packets"], c["lost"],
                   f"{c['loss_pct']:.2f}"] for k, c in m["components"].items()])
    md += ["", "Loss is inferred from sequence gaps per (sysid, compid); a sender that shares one sequence "
           "counter across several links (a GCS, a router) shows false loss for the packets it sent elsewhere.",
           "", "## Messages", ""]
    md += _table(["type", "id", "count", "rate [Hz]", "sources"],
                 [[k, e["id"], e["count"], _f(e["rate_hz"], ".2f"),
                   ", ".join(f"{s}×{n}" for s, n in e["sources"].items())]
                  for k, e in m["messages"]["by_type"].items()])
    md += ["", "## Modes and arming", ""]
    if m["modes"]["timeline"]:
        md += _table(["from [s]", "to [s]", "mode", "armed"],
                     [[f"{e['t_s']:.2f}", f"{e['until_s']:.2f}", e["mode"], e["armed"]]
                      for e in m["modes"]["timeline"]])
    else:
        md += ["No mode information."]
    md += [""] + ([f"- {e['event']} at {e['t_s']:.2f} s" for e in m["arm_events"]] or ["No arm/disarm events."])
    md += ["", "## STATUSTEXT", ""]
    md += _table(["t [s]", "source", "severity", "text"],
                 [[f"{e['t_s']:.2f}", e["source"], e["severity"], e["text"]] for e in m["statustext"]]) \
        if m["statustext"] else ["None."]
    off = m.get("offboard") or {}
    sp = off.get("setpoints") or {}
    md += ["", "## Offboard", ""]
    if sp.get("count"):
        md += [f"- setpoints (SET_POSITION_TARGET_LOCAL_NED): {sp['count']}, {_f(sp.get('rate_hz'), '.2f')} Hz "
               f"over {sp['span_s']:.2f} s; longest gap {_f(sp.get('longest_gap_s'), '.3f')} s at "
               f"{_f(sp.get('longest_gap_at_s'), '.2f')} s; {sp['gaps_over_px4_timeout']} gap(s) > 0.5 s (PX4 "
               f"offboard timeout)",
               f"- position-controlled setpoints: {sp['position_controlled']}; type masks {sp['type_masks']}; "
               f"frames {sp['frames']}"]
    else:
        md += ["- no SET_POSITION_TARGET_LOCAL_NED in the log"]
    md += [f"- time in offboard mode: {off.get('offboard_time_s', 0.0):.2f} s in {off.get('offboard_entries', 0)} "
           f"interval(s)",
           f"- estimate: {off.get('estimate_source')}",
           f"- tracking error, estimate vs latest position setpoint: {_err_line(off.get('tracking_error'))}",
           f"- same, offboard intervals only: {_err_line(off.get('tracking_error_offboard'))}"]
    tr = off.get("truth") or {}
    md += [f"- ground truth: {tr.get('source')}"]
    sc = m.get("scene")
    if sc:
        md += ["", f"## Scene `{sc['name']}`", "", f"- wall front face at x = {sc['wall_x']:.3f} m"]
        for key, label in (("estimate_wall_crossings", "estimate"), ("truth_wall_crossings", "truth")):
            for c in sc.get(key, []):
                md.append(f"- {label} crosses the wall plane {c['direction']} at {c['t_s']:.2f} s, "
                          f"(y, z) = ({c['y']:.3f}, {c['z']:.3f}) m, "
                          + ("inside an opening" if c["through_opening"] else "OUTSIDE every opening"))
    if "tracking_error" in tr:
        md += [f"  - truth vs setpoint: {_err_line(tr.get('tracking_error'))}",
               f"  - estimate vs truth: {_err_line(tr.get('estimate_error'))}"]
    if plots:
        md += ["", "## Plots", ""]
        md += [f"![{name}]({fn})\n" for name, fn in plots.items()]
    return "\n".join(md) + "\n"


def _csv_column(col: np.ndarray) -> list[list[str]] | list[Any]:
    if col.dtype.kind == "S":
        return [b.rstrip(b"\0").decode("utf-8", "replace") for b in col.tolist()]
    if col.dtype.kind == "f":
        return [format(x, ".9g") for x in col.tolist()]
    return col.tolist()


def write_csvs(rep: Report, out_dir: Path) -> list[str]:
    """One CSV per decoded message type: time_unix_s, t_s, sysid, compid, then its fields."""
    f = rep.frames
    if f is None or not len(f):
        return []
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    t0 = rep.series.get("t0_us", 0)
    for mid in np.unique(f.msgid[f.good]).tolist():
        cls = rep.mavlink.mavlink_map[mid]
        idx = np.flatnonzero((f.msgid == mid) & f.good)
        rows = decode_columns(f, rep.mavlink, mid, idx)
        head = ["time_unix_s", "t_s", "sysid", "compid"]
        cols: list[list[Any]] = [[f"{x / 1e6:.6f}" for x in f.ts[idx].tolist()],
                                 [f"{(x - t0) / 1e6:.6f}" for x in f.ts[idx].tolist()],
                                 f.sysid[idx].tolist(), f.compid[idx].tolist()]
        for name in cls.fieldnames:
            col = rows[name]
            if col.ndim == 2:
                for k in range(col.shape[1]):
                    head.append(f"{name}_{k}")
                    cols.append(_csv_column(col[:, k]))
            else:
                head.append(name)
                cols.append(_csv_column(col))
        path = out_dir / f"{cls.msgname}.csv"
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(head)
            w.writerows(zip(*cols, strict=True))
        written.append(path.name)
    return written


def _scene_metrics(rep: Report, name: str, geo: dict[str, Any]) -> None:
    from tools.tlog.plots import wall_crossings

    sc: dict[str, Any] = {"name": name, "wall_x": geo["wall_x"],
                          "openings_yz": [o.tolist() for o in geo["openings"]]}
    s = rep.series
    if s.get("est") is not None and len(s["est"]):
        sc["estimate_wall_crossings"] = wall_crossings(s["t_est"], s["est"], geo)
    if s.get("truth") is not None and len(s["truth"]):
        sc["truth_wall_crossings"] = wall_crossings(s["t_truth"], s["truth"], geo)
    rep.metrics["scene"] = sc


def write_outputs(rep: Report, out_dir: str | Path, *, plots: bool = True, csv_dir: bool = False,
                  scene: str | None = None) -> dict[str, Any]:
    """Write metrics.json and report.md (+ PNGs, + csv/) into ``out_dir``; returns what was written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Any] = {}
    pngs: dict[str, str] = {}
    geo = None
    if scene and rep.usable:
        from tools.tlog.plots import load_scene_geometry

        geo, note = load_scene_geometry(scene)
        if note:
            rep.note(note)
        else:
            _scene_metrics(rep, scene, geo)
    if plots and rep.usable:
        try:
            from tools.tlog.plots import make_plots

            pngs = make_plots(rep, out, geo)
        except Exception as exc:  # noqa: BLE001 - a plotting failure must not lose the report
            rep.note(f"plotting failed ({type(exc).__name__}: {exc}); report written without plots")
    written["plots"] = pngs
    if csv_dir and rep.usable:
        written["csv"] = write_csvs(rep, out / "csv")
    (out / "report.md").write_text(report_markdown(rep, pngs))
    (out / "metrics.json").write_text(json.dumps(json_safe(rep.to_json()), indent=2) + "\n")
    written["report"] = "report.md"
    written["metrics"] = "metrics.json"
    return written
