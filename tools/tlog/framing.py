"""Fast tlog framing: find every MAVLink packet in a .tlog without decoding payloads.

A tlog is a sequence of records ``[8-byte big-endian UNIX time in µs][one MAVLink 1 or 2 packet]``.
:func:`scan_tlog` walks the records with a tight byte loop (resynchronising over garbage), then reads
every header field, checks every CRC (vectorised X.25 / CRC-16/MCRF4XX with the dialect's CRC_EXTRA) and
returns column arrays. :func:`decode_columns` decodes the payloads of one message id straight into numpy
columns using pymavlink's own struct layout; :func:`decode_messages` hands single packets to pymavlink's
decoder (for the few low-rate messages that need objects: HEARTBEAT, STATUSTEXT, ...).

Packet layouts (offsets from the STX byte):

- MAVLink 1: ``FE len seq sys comp msgid payload[len] crc16`` (6-byte header)
- MAVLink 2: ``FD len incompat compat seq sys comp msgid[3] payload[len] crc16 [signature 13 bytes if
  incompat & 0x01]`` (10-byte header; trailing zero bytes of the payload may be truncated on the wire)
"""

from __future__ import annotations

import logging
import re
import struct
from array import array
from dataclasses import dataclass, field
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

STX_V1 = 0xFE
STX_V2 = 0xFD
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
# Records whose tlog timestamp jumps by more than this from the previous record are only accepted when
# they also pass the stricter resynchronisation test (CRC good and the following record consistent).
TS_WINDOW_US = 3600 * 1_000_000

_TS = struct.Struct(">Q")


def _crc_table() -> np.ndarray:
    i = np.arange(256, dtype=np.uint32)
    tmp = (i ^ (i << 4)) & 0xFF
    return ((tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)).astype(np.uint32) & 0xFFFF


_CRC_TABLE = _crc_table()


_CRC_LIST = [int(x) for x in _CRC_TABLE]


def crc_x25(buf: bytes | bytearray, crc: int = 0xFFFF) -> int:
    """Scalar CRC-16/MCRF4XX (MAVLink's X.25 checksum), for single packets."""
    table = _CRC_LIST
    for b in buf:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc


def load_dialect(name: str = "ardupilotmega"):
    """Import ``pymavlink.dialects.v20.<name>`` (v20 modules decode MAVLink 1 and 2 packets alike)."""
    import importlib

    return importlib.import_module(f"pymavlink.dialects.v20.{name}")


@dataclass
class Frames:
    """Column arrays, one entry per MAVLink packet found in the file (in file order)."""

    data: np.ndarray                 # the whole file as uint8
    rec: np.ndarray                  # offset of each record (its 8-byte timestamp)
    ts: np.ndarray                   # tlog time, µs since the UNIX epoch (int64)
    v2: np.ndarray                   # bool: MAVLink 2 packet
    plen: np.ndarray                 # payload length on the wire
    seq: np.ndarray
    sysid: np.ndarray
    compid: np.ndarray
    msgid: np.ndarray                # int64
    signed: np.ndarray               # bool
    size: np.ndarray                 # record size (timestamp + packet)
    known: np.ndarray                # bool: msgid is in the dialect
    crc_ok: np.ndarray               # bool: CRC matches (False for unknown ids: cannot be checked)
    garbage_bytes: int = 0           # bytes skipped while resynchronising
    garbage_runs: int = 0
    trailing_bytes: int = 0          # bytes of an incomplete record at the end of the file
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.rec.size)

    @property
    def hdr(self) -> np.ndarray:
        """Offset of each packet's STX byte."""
        return self.rec + 8

    @property
    def payload_start(self) -> np.ndarray:
        return self.hdr + np.where(self.v2, 10, 6)

    @property
    def good(self) -> np.ndarray:
        """Packets that decode: known id and CRC good."""
        return self.known & self.crc_ok

    def packet_bytes(self, i: int) -> bytearray:
        h = int(self.rec[i]) + 8
        return bytearray(self.data[h:int(self.rec[i]) + int(self.size[i])].tobytes())


def _header(data: bytes, p: int, n: int) -> tuple[int, int] | None:
    """(record size, msgid) of a record starting at ``p`` if its header is sane, else None.

    The record may extend past the end of the file (the caller decides whether that is a truncation).
    """
    if p + 8 >= n:
        return None
    stx = data[p + 8]
    if stx == STX_V2:
        if p + 18 > n:
            return None
        flags = data[p + 10]
        if flags & ~IFLAG_SIGNED & 0xFF:
            return None
        size = 20 + data[p + 9] + (SIGNATURE_LEN if flags & IFLAG_SIGNED else 0)
        return size, data[p + 15] | (data[p + 16] << 8) | (data[p + 17] << 16)
    if stx == STX_V1:
        if p + 14 > n:
            return None
        return 16 + data[p + 9], data[p + 13]
    return None


def _packet_crc_ok(data: bytes, p: int, size: int, msgid: int, extras: dict[int, int]) -> bool | None:
    """CRC check of one record (None when the id is unknown to the dialect)."""
    extra = extras.get(msgid)
    if extra is None:
        return None
    h = p + 8
    v2 = data[h] == STX_V2
    body_end = h + (10 if v2 else 6) + data[h + 1]
    crc = crc_x25(data[h + 1:body_end])
    crc = crc_x25(bytes([extra]), crc)
    return crc == (data[body_end] | (data[body_end + 1] << 8))


def _time_disagrees_with_a_consistent_pair(data: bytes, p: int, size: int, n: int) -> bool:
    """Whether the record at ``p`` is followed by two sane records whose times agree with each other but not
    with its own: then its timestamp is the corrupt one (a first record with a flipped time byte would
    otherwise become the log's start time, hundreds of years away from the rest)."""
    q = p + size
    nxt = _header(data, q, n)
    if nxt is None or q + nxt[0] > n:
        return False
    after = _header(data, q + nxt[0], n)
    if after is None:
        return False
    t_own, t_next = _TS.unpack_from(data, p)[0], _TS.unpack_from(data, q)[0]
    t_after = _TS.unpack_from(data, q + nxt[0])[0]
    return abs(t_next - t_own) > TS_WINDOW_US and abs(t_after - t_next) <= TS_WINDOW_US


def _resync(data: bytes, start: int, n: int, last_ts: int | None, extras: dict[int, int]) -> int | None:
    """Offset of the next plausible record at or after ``start`` (None: nothing more in the file).

    A candidate needs a sane header and either a good CRC or a sane record right after it; its timestamp
    must lie within TS_WINDOW_US of the last good record, unless both of those hold (a genuine jump).
    """
    s = start + 8
    while True:
        a = data.find(b"\xfd", s)
        b = data.find(b"\xfe", s)
        if a < 0 and b < 0:
            return None
        c = a if b < 0 else b if a < 0 else min(a, b)
        s = c + 1
        p = c - 8
        hd = _header(data, p, n)
        if hd is None:
            if p + 8 < n and p + 18 > n:  # an incomplete header at the very end
                return p
            continue
        size, msgid = hd
        ts = _TS.unpack_from(data, p)[0]
        in_window = last_ts is not None and abs(ts - last_ts) <= TS_WINDOW_US
        if p + size > n:  # runs past the end: a truncated last record if its time fits
            if in_window:
                return p
            continue
        at_end = p + size == n
        nxt = None if at_end else _header(data, p + size, n)
        chain = at_end or (nxt is not None and abs(_TS.unpack_from(data, p + size)[0] - ts) <= TS_WINDOW_US)
        # cheap tests first; the CRC only where it decides
        if last_ts is None:  # no reference time yet (start of file): demand a consistent pair
            if at_end:
                if p == 0 and _packet_crc_ok(data, p, size, msgid, extras):
                    return p  # the whole file is one record
            elif chain and _packet_crc_ok(data, p, size, msgid, extras) is not False:
                return p
            elif p == 0 and not _time_disagrees_with_a_consistent_pair(data, p, size, n) and \
                    _packet_crc_ok(data, p, size, msgid, extras):
                return p  # the file starts with a good packet, damage right after it
        elif in_window:
            if chain or _packet_crc_ok(data, p, size, msgid, extras):
                return p
        elif chain and not at_end and _packet_crc_ok(data, p, size, msgid, extras):
            return p  # a genuine jump in time


def _cut_in_timestamp(data: bytes, pos: int, n: int, last_ts: int | None) -> bool:
    """Whether the file ends inside a record's 8-byte timestamp: at most 8 bytes left, and they start as the
    last record's time does (the top 4 bytes of a µs time change once in 71 minutes). Such a tail is a
    truncated record, not non-MAVLink data."""
    left = n - pos
    if last_ts is None or not 0 < left <= 8:
        return False
    k = min(left, 4)
    return data[pos:pos + k] == _TS.pack(last_ts)[:k]


def _scan_offsets(data: bytes, extras: dict[int, int], progress: bool) -> tuple[array, int, int, int]:
    """Record offsets, garbage bytes, garbage runs, trailing (incomplete) bytes."""
    n = len(data)
    recs = array("q")  # 8 bytes per record, not a Python int object
    append = recs.append
    unpack_ts = _TS.unpack_from
    garbage = runs = trailing = 0
    last_ts: int | None = None
    bar = None
    if progress and n > 20_000_000:
        from tqdm import tqdm

        bar = tqdm(total=n, unit="B", unit_scale=True, desc="scan", leave=False)
    tick = step = max(n // 100, 1 << 20)
    pos = 0
    # first record: be strict (the file might not be a tlog at all)
    first = _resync(data, 0, n, None, extras) if n else None
    if first is None:
        return recs, n, (1 if n else 0), 0
    if first > 0:
        garbage, runs = first, 1
    pos = first
    while pos < n:
        if pos >= tick and bar is not None:
            bar.update(pos - bar.n)
            tick += step
        # inline fast path of _header + timestamp window
        if pos + 18 <= n:
            stx = data[pos + 8]
            if stx == STX_V2:
                flags = data[pos + 10]
                if flags == 0:
                    size = 20 + data[pos + 9]
                elif flags == IFLAG_SIGNED:
                    size = 33 + data[pos + 9]
                else:
                    size = 0
            elif stx == STX_V1:
                size = 16 + data[pos + 9]
            else:
                size = 0
            if size:
                ts = unpack_ts(data, pos)[0]
                if last_ts is None or -TS_WINDOW_US <= ts - last_ts <= TS_WINDOW_US:
                    if pos + size <= n:
                        append(pos)
                        pos += size
                        last_ts = ts
                        continue
                    trailing = n - pos
                    break
        elif pos + 14 <= n and data[pos + 8] == STX_V1 and pos + 16 + data[pos + 9] <= n:
            ts = unpack_ts(data, pos)[0]
            if last_ts is None or abs(ts - last_ts) <= TS_WINDOW_US:
                append(pos)
                pos += 16 + data[pos + 9]
                last_ts = ts
                continue
        # slow path: something is wrong here; find the next plausible record
        nxt = _resync(data, pos, n, last_ts, extras)
        if nxt is None:
            if (n - pos < 20 + 255 + SIGNATURE_LEN and _header(data, pos, n) is not None) or \
                    _cut_in_timestamp(data, pos, n, last_ts):
                trailing = n - pos
            else:
                garbage += n - pos
                runs += 1
            break
        hd = _header(data, nxt, n)
        if hd is None or nxt + hd[0] > n:  # an incomplete record at the end of the file
            garbage += nxt - pos
            runs += 1 if nxt > pos else 0
            trailing = n - nxt
            break
        if nxt > pos:
            garbage += nxt - pos
            runs += 1
        # _resync vetted this record (possibly a genuine jump in time): take it, and its time as reference
        append(nxt)
        last_ts = _TS.unpack_from(data, nxt)[0]
        pos = nxt + hd[0]
    if bar is not None:
        bar.update(n - bar.n)
        bar.close()
    return recs, garbage, runs, trailing


def looks_like_raw_mavlink(raw: bytes, mavlink_module: Any, need: int = 3) -> bool:
    """True when ``raw`` holds back-to-back MAVLink packets with good CRCs but no tlog timestamps."""
    extras = {mid: cls.crc_extra for mid, cls in mavlink_module.mavlink_map.items()}
    n = len(raw)
    start = 0
    for _ in range(64):  # try a few starting points
        a, b = raw.find(b"\xfd", start), raw.find(b"\xfe", start)
        c = a if b < 0 else b if a < 0 else min(a, b)
        if c < 0:
            return False
        p, good = c, 0
        while good < need:
            hd = _header(raw, p - 8, n)  # _header expects a record offset (8 bytes before STX)
            if hd is None or p - 8 + hd[0] > n or not _packet_crc_ok(raw, p - 8, hd[0], hd[1], extras):
                break
            good += 1
            p += hd[0] - 8
        if good >= need:
            return True
        start = c + 1
    return False


GATHER_CHUNK = 1 << 18  # rows per fancy-indexing step: bounds the int64 index temporaries on huge logs


def _gather(buf: np.ndarray, start: np.ndarray, width: int) -> np.ndarray:
    """(len(start), width) uint8 rows of bytes starting at each offset (clipped to the buffer; callers mask)."""
    out = np.empty((start.size, width), dtype=np.uint8)
    cols = np.arange(width, dtype=np.int64)[None, :]
    for a in range(0, start.size, GATHER_CHUNK):
        idx = start[a:a + GATHER_CHUNK, None] + cols
        np.minimum(idx, buf.size - 1, out=idx)
        out[a:a + GATHER_CHUNK] = buf[idx]
    return out


def _check_crcs(buf: np.ndarray, hdr: np.ndarray, hlen: np.ndarray, plen: np.ndarray,
                extra: np.ndarray) -> np.ndarray:
    """Vectorised MAVLink CRC check; ``extra`` < 0 marks unknown ids (result False)."""
    ok = np.zeros(hdr.size, dtype=bool)
    known = extra >= 0
    body = hlen + plen - 1  # bytes covered after STX, before CRC_EXTRA
    for blen in np.unique(body[known]):
        sel = np.flatnonzero(known & (body == blen))
        cols = np.ascontiguousarray(_gather(buf, hdr[sel] + 1, int(blen)).T)  # one contiguous row per byte
        crc = np.full(sel.size, 0xFFFF, dtype=np.uint32)
        for j in range(int(blen)):
            crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ cols[j]) & 0xFF]
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ extra[sel].astype(np.uint32)) & 0xFF]
        cpos = hdr[sel] + 1 + blen
        wire = buf[cpos].astype(np.uint32) | (buf[cpos + 1].astype(np.uint32) << 8)
        ok[sel] = crc == wire
    return ok


def scan_tlog(raw: bytes, mavlink_module: Any, progress: bool = False) -> Frames:
    """Find every MAVLink packet in the tlog bytes ``raw`` and read its header fields and CRC."""
    extras = {mid: cls.crc_extra for mid, cls in mavlink_module.mavlink_map.items()}
    recs, garbage, runs, trailing = _scan_offsets(raw, extras, progress)
    buf = np.frombuffer(raw, dtype=np.uint8)
    rec = np.frombuffer(recs, dtype=np.int64) if len(recs) else np.zeros(0, dtype=np.int64)
    hdr = rec + 8
    if rec.size:
        ts = np.ascontiguousarray(_gather(buf, rec, 8)).view(">u8").ravel().astype(np.int64)
        head = np.ascontiguousarray(_gather(buf, hdr, 10).T)  # uint8, one row per header byte
    else:
        ts = np.zeros(0, dtype=np.int64)
        head = np.zeros((10, 0), dtype=np.uint8)
    v2 = head[0] == STX_V2

    def col(j: int) -> np.ndarray:
        return head[j].astype(np.int64)

    plen = col(1)
    seq = np.where(v2, head[4], head[2]).astype(np.int64)
    sysid = np.where(v2, head[5], head[3]).astype(np.int64)
    compid = np.where(v2, head[6], head[4]).astype(np.int64)
    msgid = np.where(v2, col(7) | (col(8) << 8) | (col(9) << 16), col(5))
    signed = v2 & ((head[2] & IFLAG_SIGNED) != 0)
    hlen = np.where(v2, 10, 6)
    size = 8 + hlen + plen + 2 + np.where(signed, SIGNATURE_LEN, 0)
    uids, inv = np.unique(msgid, return_inverse=True)
    extra_u = np.array([extras.get(int(u), -1) for u in uids], dtype=np.int64)
    extra = extra_u[inv] if msgid.size else np.zeros(0, dtype=np.int64)
    crc_ok = _check_crcs(buf, hdr, hlen, plen, extra)
    return Frames(data=buf, rec=rec, ts=ts, v2=v2, plen=plen, seq=seq, sysid=sysid, compid=compid,
                  msgid=msgid, signed=signed, size=size, known=extra >= 0, crc_ok=crc_ok,
                  garbage_bytes=garbage, garbage_runs=runs, trailing_bytes=trailing)


# --- payload decoding --------------------------------------------------------------------------------

_NP_TYPES = {"B": "u1", "b": "i1", "H": "<u2", "h": "<i2", "I": "<u4", "i": "<i4", "Q": "<u8", "q": "<i8",
             "f": "<f4", "d": "<f8", "c": "S1", "?": "u1"}
_DTYPES: dict[int, np.dtype] = {}


def message_dtype(cls: Any) -> np.dtype:
    """Packed numpy dtype of a pymavlink message class's wire payload (extensions included)."""
    key = id(cls)
    dt = _DTYPES.get(key)
    if dt is None:
        toks = re.findall(r"(\d*)([a-zA-Z?])", cls.unpacker.format.lstrip("<"))
        fields = []
        for name, (count, code) in zip(cls.ordered_fieldnames, toks, strict=True):
            n = int(count) if count else 1
            if code == "s":
                fields.append((name, f"S{n}"))
            elif n > 1:
                fields.append((name, _NP_TYPES[code], (n,)))
            else:
                fields.append((name, _NP_TYPES[code]))
        dt = np.dtype(fields)
        if dt.itemsize != cls.unpacker.size:
            raise ValueError(f"{cls.msgname}: dtype size {dt.itemsize} != struct size {cls.unpacker.size}")
        _DTYPES[key] = dt
    return dt


def decode_columns(frames: Frames, mavlink_module: Any, msgid: int,
                   sel: np.ndarray | None = None) -> np.ndarray:
    """Decode all good packets of ``msgid`` (or the packet indices ``sel``) into a structured array.

    MAVLink 2 payloads truncated on the wire are zero-padded; longer ones (newer definitions) are cut,
    exactly as pymavlink does.
    """
    cls = mavlink_module.mavlink_map[msgid]
    dt = message_dtype(cls)
    if sel is None:
        sel = np.flatnonzero((frames.msgid == msgid) & frames.good)
    if sel.size == 0:
        return np.zeros(0, dtype=dt)
    width = dt.itemsize
    start = frames.payload_start[sel]
    rows = _gather(frames.data, start, width)
    rows[np.arange(width)[None, :] >= frames.plen[sel][:, None]] = 0
    return np.ascontiguousarray(rows).view(dt).ravel()


def decode_messages(frames: Frames, mav: Any, sel: np.ndarray) -> list[tuple[int, Any]]:
    """pymavlink-decoded message objects for the packet indices ``sel``: [(index, msg)]."""
    out = []
    for i in sel.tolist():
        try:
            out.append((i, mav.decode(frames.packet_bytes(i))))
        except Exception as exc:  # noqa: BLE001 - a corrupt packet must not stop the report
            log.debug("packet %d does not decode: %s", i, exc)
    return out
