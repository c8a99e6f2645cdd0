"""A tlog's messages in a form two flights can be compared by: each message's source and every field, in order."""

from __future__ import annotations

from pathlib import Path

from pymavlink import mavutil


def tlog_messages(tlog: Path) -> list[str]:
    """Every message of ``tlog`` as the repr of (source system, component, fields), so that NaN fields compare
    equal; SYSTEM_TIME's Unix time, the one wall-clock field, is left out."""
    conn = mavutil.mavlink_connection(str(tlog))
    out = []
    while (msg := conn.recv_match()) is not None:
        fields = msg.to_dict()
        if msg.get_type() == "SYSTEM_TIME":
            fields.pop("time_unix_usec", None)
        out.append(repr((msg.get_srcSystem(), msg.get_srcComponent(), fields)))
    conn.close()
    return out
