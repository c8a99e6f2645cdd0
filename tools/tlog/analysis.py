"""Analyse one tlog: what the vehicle did, what it was told, how well it followed.

:func:`analyse_tlog` is the library entry point; it never raises on a bad log (missing, empty, not a
tlog, truncated, garbage, unknown ids): problems become one-line ``notes`` and the rest of the report is
filled in as far as the data allows.

Definitions used in the metrics (all times are tlog receive times, seconds from the first packet):

- *vehicle*: the (sysid, compid) sending the most HEARTBEATs with an autopilot other than
  MAV_AUTOPILOT_INVALID; its LOCAL_POSITION_NED is the *estimate*.
- *setpoint*: SET_POSITION_TARGET_LOCAL_NED. It is *position-controlled* when none of the x/y/z ignore
  bits (type_mask & 0b111) is set and its frame is MAV_FRAME_LOCAL_NED; only those enter tracking error.
- *tracking error* of a position sample at time t: the distance to the latest position-controlled setpoint
  logged before it (tlog time; within the same microsecond, file order decides; samples before the first
  such setpoint are skipped). ``tracking_error`` uses all
  such samples; ``tracking_error_offboard`` only those inside offboard-mode intervals.
- *offboard mode*: PX4 OFFBOARD, ArduPilot GUIDED / GUIDED_NOGPS, from the vehicle's HEARTBEATs; an
  interval lasts from the heartbeat that shows the mode to the next heartbeat that shows another mode
  (or the end of the log).
- *packet loss* per link (sysid, compid): from MAVLink sequence numbers, lost = sum((seq_i - seq_{i-1} - 1)
  mod 256) over consecutive packets, duplicates (same seq) not counted as loss. When that exceeds 5 % and
  the packets split into at most 4 interleaved counters (two channels of one component logged together)
  with less than half the loss, the per-counter loss is reported instead, with a note.
- *ground truth*: the first of TRUTH_SOURCES found (ATT_POS_MOCAP; ODOMETRY in a local frame marked
  MAV_ESTIMATOR_TYPE_MOCAP, as flowgap's simulator sends it, or from a component other than the estimate's;
  LOCAL_POSITION_NED_COV or LOCAL_POSITION_NED from another component).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from tools.tlog.framing import (
    Frames,
    decode_columns,
    decode_messages,
    load_dialect,
    looks_like_raw_mavlink,
    scan_tlog,
)
from tools.tlog.truth import TRUTH_AUTO_ORDER, TRUTH_SOURCES, error_stats, parse_truth_option, tracking_stats

log = logging.getLogger(__name__)

MAV_AUTOPILOT_INVALID = 8
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_FRAME_LOCAL_NED = 1
POSITION_IGNORE_BITS = 0b111
OFFBOARD_MODES = {"OFFBOARD", "GUIDED", "GUIDED_NOGPS"}
PX4_OFFBOARD_TIMEOUT_S = 0.5
EVENT_MESSAGES = ("HEARTBEAT", "STATUSTEXT", "COMMAND_LONG", "COMMAND_INT", "COMMAND_ACK")


# --- report -------------------------------------------------------------------------------------------

@dataclass
class Report:
    """Result of :func:`analyse_tlog`: JSON-ready ``metrics``, ``notes`` and numpy ``series`` for plots."""

    path: str
    metrics: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    series: dict[str, Any] = field(default_factory=dict)
    frames: Frames | None = None
    mavlink: Any = None
    usable: bool = False   # False: nothing could be analysed (missing, unreadable, no MAVLink packets)

    def note(self, text: str) -> None:
        self.notes.append(text)
        log.warning("%s", text)

    def to_json(self) -> dict[str, Any]:
        return {"file": self.path, "usable": self.usable, **self.metrics, "notes": list(self.notes)}


def _enum_name(mav: Any, enum: str, value: int, strip: str = "") -> str:
    entry = mav.enums.get(enum, {}).get(int(value))
    if entry is None:
        return f"{enum}({value})"
    return entry.name[len(strip):] if strip and entry.name.startswith(strip) else entry.name


def autopilot_label(value: int) -> str:
    return {3: "ArduPilot", 12: "PX4", 8: "none (not an autopilot)", 0: "generic"}.get(int(value), "")


def mode_name(msg: Any) -> str:
    """Flight mode of a HEARTBEAT, decoded with pymavlink's PX4 / ArduPilot mode tables."""
    from pymavlink import mavutil

    try:
        name = mavutil.mode_string_v10(msg)
    except Exception:  # noqa: BLE001 - unknown vehicle types etc.
        name = f"Mode({msg.custom_mode})"
    if name == "UNKNOWN" and msg.autopilot == 12:
        name = f"PX4({(msg.custom_mode >> 16) & 0xFF}.{(msg.custom_mode >> 24) & 0xFF})"
    return name


def _intervals_mask(t: np.ndarray, intervals: list[tuple[float, float]]) -> np.ndarray:
    m = np.zeros(t.size, dtype=bool)
    for a, b in intervals:
        m |= (t >= a) & (t < b)
    return m


def analyse_tlog(path: str | Path, *, truth: str = "auto", dialect: str = "ardupilotmega",
                 progress: bool = False, signing_secret: bytes | None = None) -> Report:
    """Analyse the tlog at ``path``; never raises for bad input (see ``Report.notes``/``usable``).

    ``signing_secret``: also check every packet's MAVLink 2 signature with this key (metrics ``signatures``)."""
    path = Path(path)
    rep = Report(path=str(path))
    try:
        truth_name, truth_src = parse_truth_option(truth)
    except ValueError as exc:
        rep.note(str(exc))
        truth_name, truth_src = "auto", None
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        rep.note(f"file not found: {path}")
        return rep
    except OSError as exc:
        rep.note(f"cannot read {path}: {exc.strerror or exc}")
        return rep
    try:
        mav_mod = load_dialect(dialect)
    except ImportError:
        rep.note(f"unknown pymavlink dialect {dialect!r}")
        return rep
    rep.mavlink = mav_mod
    rep.metrics["file_bytes"] = len(raw)
    if not raw:
        rep.note("empty file: no packets")
        _empty_metrics(rep)
        return rep
    frames = scan_tlog(raw, mav_mod, progress=progress)
    rep.frames = frames
    if len(frames) == 0:
        if looks_like_raw_mavlink(raw, mav_mod):
            rep.note(f"no tlog records in {len(raw)} bytes, but it holds raw MAVLink packets without the "
                     "8-byte timestamps of a tlog (a raw byte capture, not a tlog): record with a tlog writer")
        else:
            rep.note(f"no MAVLink packets found in {len(raw)} bytes: not a tlog "
                     "(8-byte big-endian µs timestamp before each MAVLink packet)?")
        _empty_metrics(rep)
        return rep
    rep.usable = True
    stages = (("framing", lambda: _framing_notes(rep, frames, mav_mod)),
              ("summary", lambda: _summary(rep, frames, mav_mod)),
              ("events", lambda: _events(rep, frames, mav_mod)),
              ("offboard", lambda: _offboard(rep, frames, mav_mod, truth_name, truth_src)))
    if signing_secret is not None:
        from tools.tlog.signatures import check_signatures

        stages += (("signatures", lambda: rep.metrics.__setitem__("signatures",
                                                                  check_signatures(frames, signing_secret))),)
    for name, stage in stages:
        try:
            stage()
        except Exception as exc:  # noqa: BLE001 - a log we did not foresee: keep what the other stages give
            log.debug("stage %s failed", name, exc_info=True)
            rep.note(f"the {name} analysis failed on this log ({type(exc).__name__}: {exc}); "
                     "its part of the report is missing")
    _empty_metrics(rep)
    return rep


def _empty_metrics(rep: Report) -> None:
    """Fill whatever a failed or skipped stage left out with empty values."""
    defaults: dict[str, Any] = {
        "duration_s": 0.0, "start_utc": None, "file_bytes": rep.metrics.get("file_bytes", 0),
        "framing": {"packets": 0, "mavlink1": 0, "mavlink2": 0, "signed": 0, "crc_failures": 0,
                    "unknown_id_packets": 0, "garbage_bytes": 0, "garbage_runs": 0, "truncated_tail_bytes": 0},
        "messages": {"total": 0, "types": 0, "by_type": {}}, "components": {}, "systems": [],
        "packet_loss": {"received": 0, "lost": 0, "loss_pct": 0.0}, "vehicle": None,
        "modes": {"timeline": [], "mode_changes": 0}, "arm_events": [], "statustext": [], "command_acks": [],
        "offboard": None}
    for k, v in defaults.items():
        rep.metrics.setdefault(k, v)


def _framing_notes(rep: Report, f: Frames, mav: Any) -> None:
    bad = ~f.crc_ok & f.known
    n_bad = int(bad.sum())
    unknown = ~f.known
    fr = {"packets": len(f), "mavlink1": int((~f.v2).sum()), "mavlink2": int(f.v2.sum()),
          "signed": int(f.signed.sum()), "crc_failures": n_bad, "unknown_id_packets": int(unknown.sum()),
          "garbage_bytes": f.garbage_bytes, "garbage_runs": f.garbage_runs,
          "truncated_tail_bytes": f.trailing_bytes}
    if n_bad:
        ids, cnt = np.unique(f.msgid[bad], return_counts=True)
        by = {mav.mavlink_map[int(i)].msgname: int(c) for i, c in zip(ids, cnt, strict=True)}
        fr["crc_failures_by_type"] = by
        listing = ", ".join(f"{k} x{v}" for k, v in by.items())
        rep.note(f"{n_bad} packet(s) failed the CRC check and were not decoded ({listing}): corrupt, or "
                 "sent with a different message definition")
    if unknown.any():
        ids, cnt = np.unique(f.msgid[unknown], return_counts=True)
        fr["unknown_ids"] = {str(int(i)): int(c) for i, c in zip(ids, cnt, strict=True)}
        rep.note(f"{int(unknown.sum())} packet(s) with message id(s) unknown to the "
                 f"{mav.__name__.rsplit('.', 1)[-1]} dialect: {sorted(fr['unknown_ids'])}; counted, not decoded")
    if f.garbage_bytes:
        rep.note(f"skipped {f.garbage_bytes} byte(s) of non-MAVLink data in {f.garbage_runs} place(s)")
    if f.trailing_bytes:
        rep.note(f"file ends with an incomplete packet ({f.trailing_bytes} byte(s)): truncated log")
    rep.metrics["framing"] = fr


def split_sequence_loss(seqs: list[int], max_gap: int = 64, max_counters: int = 4) -> tuple[int, int] | None:
    """Loss on a link whose packets come from several interleaved sequence counters.

    Greedily assigns each packet to the counter it continues with the smallest forward step (1..max_gap);
    returns (lost, counters), or None when more than ``max_counters`` would be needed.
    """
    streams: list[list[int]] = []  # [last seq, lost]
    for s in seqs:
        best, best_d = None, max_gap + 1
        for st in streams:
            d = (s - st[0]) & 0xFF
            if 0 < d < best_d:
                best, best_d = st, d
        if best is None:
            if len(streams) == max_counters:
                return None
            streams.append([s, 0])
        else:
            best[0] = s
            best[1] += best_d - 1
    return sum(st[1] for st in streams), len(streams)


def _utc_text(t_us: int) -> str | None:
    """ISO UTC time of a tlog time in µs, None when it is outside what a date can hold (a corrupt timestamp)."""
    try:
        return datetime.fromtimestamp(t_us / 1e6, tz=timezone.utc).isoformat()
    except (ValueError, OverflowError, OSError):
        return None


def _summary(rep: Report, f: Frames, mav: Any) -> None:
    good = f.good
    t0 = int(f.ts.min())
    t1 = int(f.ts.max())
    rep.series["t0_us"] = t0
    rep.metrics["start_utc"] = _utc_text(t0)
    if rep.metrics["start_utc"] is None:
        rep.note(f"the first packet's time ({t0} µs) is not a UNIX time (corrupt log?): start time unknown")
    rep.metrics["duration_s"] = (t1 - t0) / 1e6
    if np.any(np.diff(f.ts) < 0):
        n_back = int((np.diff(f.ts) < 0).sum())
        rep.metrics["timestamps_backwards"] = n_back
    # message counts and rates, by type
    ids = f.msgid[good]
    ts = f.ts[good]
    by_type: dict[str, Any] = {}
    order = np.argsort(ids, kind="stable")
    sid = ids[order]
    if sid.size:
        bounds = np.flatnonzero(np.diff(sid)) + 1
        starts = np.concatenate([[0], bounds])
        ends = np.concatenate([bounds, [sid.size]])
        srcs = (f.sysid[good] * 256 + f.compid[good])[order]
        for a, b in zip(starts, ends, strict=True):
            mid = int(sid[a])
            tt = ts[order[a:b]]
            n = int(b - a)
            span = (int(tt.max()) - int(tt.min())) / 1e6
            u, c = np.unique(srcs[a:b], return_counts=True)
            by_type[mav.mavlink_map[mid].msgname] = {
                "id": mid, "count": n, "rate_hz": (n - 1) / span if n > 1 and span > 0 else None,
                "sources": {f"{int(x) // 256}:{int(x) % 256}": int(k) for x, k in zip(u, c, strict=True)}}
    by_type = dict(sorted(by_type.items(), key=lambda kv: -kv[1]["count"]))
    rep.metrics["messages"] = {"total": int(good.sum()), "types": len(by_type), "by_type": by_type}
    # links: components seen and packet loss from sequence gaps (all framed packets with a sane header)
    # every framed packet counts here, CRC failures included: their headers arrived, so did their seq
    links = f.sysid * 256 + f.compid
    usable = np.ones(len(f), dtype=bool)
    comps: dict[str, Any] = {}
    lost_total = recv_total = 0
    for key in np.unique(links[usable]):
        sel = usable & (links == key)
        seq = f.seq[sel]
        d = (np.diff(seq) % 256) if seq.size > 1 else np.zeros(0, dtype=np.int64)
        lost = int(np.where(d > 0, d - 1, 0).sum())
        dup = int((d == 0).sum())
        n = int(sel.sum())
        s, c = int(key) // 256, int(key) % 256
        counters = 1
        if n >= 20 and lost > 0.05 * (n + lost):
            split = split_sequence_loss(seq.tolist())
            if split is not None and split[0] < lost / 2:
                lost, counters = split
                dup = 0
                rep.note(f"link {s}:{c} carries {counters} interleaved sequence counters (several channels "
                         "logged together, e.g. a separate truth stream): loss counted per counter")
        comps[f"{s}:{c}"] = {"sysid": s, "compid": c, "component": _enum_name(mav, "MAV_COMPONENT", c, "MAV_COMP_ID_"),
                             "packets": n, "lost": lost, "duplicates": dup, "sequence_counters": counters,
                             "loss_pct": 100.0 * lost / (n + lost) if n + lost else 0.0}
        lost_total += lost
        recv_total += n
    rep.metrics["components"] = comps
    rep.metrics["systems"] = sorted({v["sysid"] for v in comps.values()})
    rep.metrics["packet_loss"] = {"received": recv_total, "lost": lost_total,
                                  "loss_pct": 100.0 * lost_total / (recv_total + lost_total) if recv_total else 0.0}


def _events(rep: Report, f: Frames, mav_mod: Any) -> None:
    name_to_id = {cls.msgname: mid for mid, cls in mav_mod.mavlink_map.items()}
    mav = mav_mod.MAVLink(None)
    t0 = rep.series["t0_us"]
    hb_id = name_to_id["HEARTBEAT"]
    hb_sel = np.flatnonzero((f.msgid == hb_id) & f.good)
    hbs = decode_messages(f, mav, hb_sel)
    per_src: dict[tuple[int, int], list[tuple[float, Any]]] = {}
    for i, m in hbs:
        per_src.setdefault((int(f.sysid[i]), int(f.compid[i])), []).append(((int(f.ts[i]) - t0) / 1e6, m))
    comps = rep.metrics["components"]
    for (s, c), lst in per_src.items():
        m = lst[-1][1]
        comps[f"{s}:{c}"].update({
            "heartbeats": len(lst), "type": _enum_name(mav_mod, "MAV_TYPE", m.type, "MAV_TYPE_").lower(),
            "autopilot": _enum_name(mav_mod, "MAV_AUTOPILOT", m.autopilot, "MAV_AUTOPILOT_").lower()})
    autopilots = {k: v for k, v in per_src.items() if v[-1][1].autopilot != MAV_AUTOPILOT_INVALID}
    vehicle = max(autopilots, key=lambda k: len(autopilots[k])) if autopilots else None
    rep.series["vehicle"] = vehicle
    timeline: list[dict[str, Any]] = []
    arm_events: list[dict[str, Any]] = []
    if vehicle is None:
        rep.metrics["vehicle"] = None
        rep.note("no HEARTBEAT from an autopilot: vehicle type, modes and arming unknown")
    else:
        m = autopilots[vehicle][-1][1]
        rep.metrics["vehicle"] = {
            "sysid": vehicle[0], "compid": vehicle[1], "autopilot": autopilot_label(m.autopilot) or
            _enum_name(mav_mod, "MAV_AUTOPILOT", m.autopilot, "MAV_AUTOPILOT_").lower(),
            "autopilot_enum": _enum_name(mav_mod, "MAV_AUTOPILOT", m.autopilot),
            "type": _enum_name(mav_mod, "MAV_TYPE", m.type, "MAV_TYPE_").lower(),
            "type_enum": _enum_name(mav_mod, "MAV_TYPE", m.type)}
        if len(autopilots) > 1:
            rep.metrics["vehicle"]["other_autopilots"] = [f"{s}:{c}" for s, c in autopilots if (s, c) != vehicle]
        prev_mode = prev_armed = None
        for t, hb in autopilots[vehicle]:
            name = mode_name(hb)
            armed = bool(hb.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
            if name != prev_mode:
                timeline.append({"t_s": t, "mode": name, "armed": armed})
                prev_mode = name
            if prev_armed is not None and armed != prev_armed:
                arm_events.append({"t_s": t, "event": "arm" if armed else "disarm"})
            prev_armed = armed
        vc = comps[f"{vehicle[0]}:{vehicle[1]}"]
        rep.metrics["packet_loss"]["vehicle_link"] = {"link": f"{vehicle[0]}:{vehicle[1]}", "lost": vc["lost"],
                                                      "loss_pct": vc["loss_pct"]}
        rep.metrics["initially_armed"] = bool(autopilots[vehicle][0][1].base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
    t_end = rep.metrics["duration_s"]
    for k, e in enumerate(timeline):
        e["until_s"] = timeline[k + 1]["t_s"] if k + 1 < len(timeline) else t_end
    rep.metrics["modes"] = {"timeline": timeline, "mode_changes": max(len(timeline) - 1, 0)}
    rep.metrics["arm_events"] = arm_events
    # STATUSTEXT and commands
    texts: list[dict[str, Any]] = []
    open_chunks: dict[tuple[str, int], dict[str, Any]] = {}  # MAVLink 2 long texts: chunks share an id > 0
    st_sel = np.flatnonzero((f.msgid == name_to_id["STATUSTEXT"]) & f.good)
    for i, m in decode_messages(f, mav, st_sel):
        text = m.text.decode("utf-8", "replace") if isinstance(m.text, bytes | bytearray) else str(m.text)
        source = f"{int(f.sysid[i])}:{int(f.compid[i])}"
        t = (int(f.ts[i]) - t0) / 1e6
        chunk_id = int(getattr(m, "id", 0) or 0)
        prev = open_chunks.get((source, chunk_id)) if chunk_id else None
        if prev is not None and int(getattr(m, "chunk_seq", 0)) > 0 and t - prev["t_s"] < 2.0:
            prev["text"] += text
            continue
        entry = {"t_s": t, "source": source,
                 "severity": _enum_name(mav_mod, "MAV_SEVERITY", m.severity, "MAV_SEVERITY_"), "text": text}
        texts.append(entry)
        if chunk_id:
            open_chunks[(source, chunk_id)] = entry
    rep.metrics["statustext"] = texts
    acks = []
    ack_sel = np.flatnonzero((f.msgid == name_to_id["COMMAND_ACK"]) & f.good)
    for i, m in decode_messages(f, mav, ack_sel):
        acks.append({"t_s": (int(f.ts[i]) - t0) / 1e6, "command": _enum_name(mav_mod, "MAV_CMD", m.command),
                     "result": _enum_name(mav_mod, "MAV_RESULT", m.result, "MAV_RESULT_")})
    rep.metrics["command_acks"] = acks


def _stream(f: Frames, mav: Any, name: str, src: tuple[int, int] | None = None,
            exclude: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(packet indices, decoded rows) of one message type, optionally from / not from one source.

    Indices are ordered by tlog time (stable), so that time lookups work on logs whose clock steps back.
    """
    mid = next((k for k, c in mav.mavlink_map.items() if c.msgname == name), None)
    if mid is None:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    sel = (f.msgid == mid) & f.good
    if src is not None:
        sel &= (f.sysid == src[0]) & (f.compid == src[1])
    if exclude is not None:
        sel &= ~((f.sysid == exclude[0]) & (f.compid == exclude[1]))
    idx = np.flatnonzero(sel)
    idx = idx[np.argsort(f.ts[idx], kind="stable")]
    return idx, decode_columns(f, mav, mid, idx)


def _busiest_source(f: Frames, idx: np.ndarray) -> tuple[int, int] | None:
    if idx.size == 0:
        return None
    keys, counts = np.unique(f.sysid[idx] * 256 + f.compid[idx], return_counts=True)
    k = int(keys[np.argmax(counts)])
    return k // 256, k % 256


def _offboard(rep: Report, f: Frames, mav: Any, truth_name: str, truth_src: tuple[int, int] | None) -> None:
    t0 = rep.series["t0_us"]
    vehicle = rep.series.get("vehicle")
    off: dict[str, Any] = {}
    # vehicle estimate
    idx, lp = _stream(f, mav, "LOCAL_POSITION_NED")
    est_src = vehicle if vehicle is not None and np.any((f.sysid[idx] == vehicle[0]) & (f.compid[idx] == vehicle[1])) \
        else _busiest_source(f, idx)
    if est_src is not None:
        keep = (f.sysid[idx] == est_src[0]) & (f.compid[idx] == est_src[1])
        idx, lp = idx[keep], lp[keep]
    t_est = f.ts[idx]
    est = np.stack([lp["x"], lp["y"], lp["z"]], axis=1).astype(np.float64) if idx.size else np.zeros((0, 3))
    vel = np.stack([lp["vx"], lp["vy"], lp["vz"]], axis=1).astype(np.float64) if idx.size else np.zeros((0, 3))
    rep.series.update(t_est=(t_est - t0) / 1e6, est=est, vel=vel)
    off["estimate_source"] = f"LOCAL_POSITION_NED from {est_src[0]}:{est_src[1]}" if est_src else None
    if idx.size == 0:
        rep.note("no LOCAL_POSITION_NED in the log: no trajectory or tracking analysis")
    # setpoints
    sidx, sp = _stream(f, mav, "SET_POSITION_TARGET_LOCAL_NED")
    t_sp_all = f.ts[sidx]
    n_sp = int(sidx.size)
    spm: dict[str, Any] = {"count": n_sp}
    if n_sp:
        span = (int(t_sp_all.max()) - int(t_sp_all.min())) / 1e6
        gaps = np.diff(np.sort(t_sp_all)) / 1e6
        spm.update({"span_s": span, "rate_hz": (n_sp - 1) / span if span > 0 else None,
                    "longest_gap_s": float(gaps.max()) if gaps.size else None,
                    "longest_gap_at_s": float((np.sort(t_sp_all)[int(np.argmax(gaps))] - t0) / 1e6)
                    if gaps.size else None,
                    "gaps_over_px4_timeout": int((gaps > PX4_OFFBOARD_TIMEOUT_S).sum()),
                    "first_s": float((t_sp_all.min() - t0) / 1e6), "last_s": float((t_sp_all.max() - t0) / 1e6)})
        srcs, cnt = np.unique(f.sysid[sidx] * 256 + f.compid[sidx], return_counts=True)
        spm["sources"] = {f"{int(k) // 256}:{int(k) % 256}": int(c) for k, c in zip(srcs, cnt, strict=True)}
        masks, cnt = np.unique(sp["type_mask"], return_counts=True)
        spm["type_masks"] = {f"0x{int(k):04x}": int(c) for k, c in zip(masks, cnt, strict=True)}
        frames_u, cnt = np.unique(sp["coordinate_frame"], return_counts=True)
        spm["frames"] = {_enum_name(mav, "MAV_FRAME", int(k), "MAV_FRAME_"): int(c)
                         for k, c in zip(frames_u, cnt, strict=True)}
        pos_ok = ((sp["type_mask"] & POSITION_IGNORE_BITS) == 0) & (sp["coordinate_frame"] == MAV_FRAME_LOCAL_NED)
        spm["position_controlled"] = int(pos_ok.sum())
        n_other_frame = int((((sp["type_mask"] & POSITION_IGNORE_BITS) == 0)
                             & (sp["coordinate_frame"] != MAV_FRAME_LOCAL_NED)).sum())
        if n_other_frame:
            rep.note(f"{n_other_frame} position setpoint(s) not in MAV_FRAME_LOCAL_NED: left out of tracking error")
    else:
        pos_ok = np.zeros(0, dtype=bool)
    off["setpoints"] = spm
    t_sp = t_sp_all[pos_ok]
    i_sp = sidx[pos_ok]
    sp_xyz = np.stack([sp["x"], sp["y"], sp["z"]], axis=1)[pos_ok].astype(np.float64) if n_sp else np.zeros((0, 3))
    rep.series.update(t_sp=(t_sp - t0) / 1e6, sp=sp_xyz)
    # offboard time
    timeline = rep.metrics.get("modes", {}).get("timeline", [])
    intervals = [(e["t_s"], e["until_s"]) for e in timeline if e["mode"] in OFFBOARD_MODES]
    off["offboard_time_s"] = float(sum(b - a for a, b in intervals))
    off["offboard_entries"] = len(intervals)
    off["offboard_intervals_s"] = [[a, b] for a, b in intervals]
    # tracking error against setpoints
    if t_sp.size and t_est.size:
        stats, t_used, err = tracking_stats(t_est, est, t_sp, sp_xyz, None, idx, i_sp)
        off["tracking_error"] = stats
        rep.series.update(t_err=(t_used - t0) / 1e6, err=err)
        in_off = _intervals_mask((t_est - t0) / 1e6, intervals)
        off["tracking_error_offboard"] = tracking_stats(t_est, est, t_sp, sp_xyz, in_off, idx, i_sp)[0]
    else:
        off["tracking_error"] = None
        off["tracking_error_offboard"] = None
        if n_sp and not t_sp.size:
            rep.note("no position-controlled SET_POSITION_TARGET_LOCAL_NED (type_mask ignores x/y/z): "
                     "no tracking error")
    # ground truth
    off["truth"] = _truth(rep, f, mav, truth_name, truth_src, est_src, t_est, est, t_sp, sp_xyz, i_sp)
    rep.metrics["offboard"] = off


def _truth(rep: Report, f: Frames, mav: Any, name: str, src: tuple[int, int] | None,
           est_src: tuple[int, int] | None, t_est: np.ndarray, est: np.ndarray,
           t_sp: np.ndarray, sp_xyz: np.ndarray, i_sp: np.ndarray) -> dict[str, Any]:
    t0 = rep.series["t0_us"]
    if name == "none":
        return {"source": "disabled (--truth none)"}
    candidates = TRUTH_AUTO_ORDER if name == "auto" else (name,)
    for cand in candidates:
        ts_ = TRUTH_SOURCES[cand]
        idx, rows = _stream(f, mav, ts_.message, src=src)
        if idx.size and src is None:
            from_est = ((f.sysid[idx] == est_src[0]) & (f.compid[idx] == est_src[1]) if est_src is not None
                        else np.zeros(idx.size, dtype=bool))
            keep = ts_.accept(rows, from_est)
            idx, rows = idx[keep], rows[keep]
        if idx.size == 0:
            continue
        where = _busiest_source(f, idx)
        keep = (f.sysid[idx] == where[0]) & (f.compid[idx] == where[1])
        idx, rows = idx[keep], rows[keep]
        t_tr = f.ts[idx]
        tr = ts_.positions(rows)
        rep.series.update(t_truth=(t_tr - t0) / 1e6, truth=tr)
        out: dict[str, Any] = {"source": f"{ts_.message} from {where[0]}:{where[1]}", "samples": int(idx.size)}
        out["tracking_error"] = None
        if t_sp.size:
            out["tracking_error"], t_used, err = tracking_stats(t_tr, tr, t_sp, sp_xyz, None, idx, i_sp)
            rep.series.update(t_err_truth=(t_used - t0) / 1e6, err_truth=err)
        if t_est.size > 1 and t_tr.size:
            # estimate error: truth vs the estimate interpolated at truth times (within the estimate's span)
            inside = (t_tr >= t_est[0]) & (t_tr <= t_est[-1])
            if inside.any():
                te = (t_est - t_est[0]).astype(np.float64)
                tt = (t_tr[inside] - t_est[0]).astype(np.float64)
                interp = np.stack([np.interp(tt, te, est[:, j]) for j in range(3)], axis=1)
                out["estimate_error"] = error_stats(np.linalg.norm(interp - tr[inside], axis=1))
        return out
    if name != "auto":
        rep.note(f"truth source {name!r} not found in the log")
    return {"source": "none found", "looked_for": [TRUTH_SOURCES[c].message for c in candidates]}
