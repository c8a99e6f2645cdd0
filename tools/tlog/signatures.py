"""Checking a tlog's MAVLink 2 signatures against a key (``flowgap-tlog --signing-key FILE``).

Every packet is classed as the vehicle would class it on arrival (``sitl_vehicle.signing``): *good* (a valid
signature and a timestamp above the last one of its (system, component, link id) stream), *replayed* (a valid
signature but a timestamp that did not rise on its stream), *bad* (signed, but not with this key, or cut
short) or *unsigned*.  Counts are given in all and per source system/component, so that a log shows at once
who signed and who did not.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from sitl_vehicle.signing import SIGNATURE_LENGTH, frame_link_and_timestamp, signature_of
from tools.tlog.framing import Frames

CLASSES = ("good", "replayed", "bad", "unsigned")


def check_signatures(frames: Frames, secret: bytes) -> dict[str, Any]:
    """Counts of :data:`CLASSES` over the well-formed packets of ``frames``, in all and per ``"SYS/COMP"``."""
    total: Counter = Counter()
    by_source: dict[str, Counter] = {}
    last: dict[tuple[int, int, int], int] = {}
    good = frames.good
    for i in range(len(frames)):
        if not good[i]:
            continue
        source = (int(frames.sysid[i]), int(frames.compid[i]))
        kind = "unsigned"
        if frames.signed[i]:
            packet = bytes(frames.packet_bytes(i))
            if len(packet) < SIGNATURE_LENGTH + 12 or signature_of(secret, packet) != packet[-6:]:
                kind = "bad"
            else:
                link_id, stamp = frame_link_and_timestamp(packet)
                stream = (*source, link_id)
                kind = "good" if stamp > last.get(stream, -1) else "replayed"
                last[stream] = max(stamp, last.get(stream, -1))
        total[kind] += 1
        by_source.setdefault(f"{source[0]}/{source[1]}", Counter())[kind] += 1
    return {**{k: int(total[k]) for k in CLASSES},
            "by_source": {src: {k: int(c[k]) for k in CLASSES} for src, c in sorted(by_source.items())}}


def signatures_line(result: dict[str, Any]) -> str:
    """'signatures: 812 good, 0 replayed, 0 bad, 3 unsigned (HEARTBEAT from 255/190 ...)' for the summary."""
    unsigned_sources = [src for src, c in result["by_source"].items() if c["unsigned"]]
    line = (f"signatures: {result['good']} good, {result['replayed']} replayed, {result['bad']} bad, "
            f"{result['unsigned']} unsigned")
    if unsigned_sources:
        line += f" (unsigned from {', '.join(unsigned_sources[:4])}{' …' if len(unsigned_sources) > 4 else ''})"
    return line
